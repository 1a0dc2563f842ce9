//! A training batch gathered on the GPU (`recon_batch.comp`): a *schedule* of batch entries
//! `(object, view a, view b, slot)` per iteration says what each iteration sees, and the two
//! views of every entry of a submission are staged beside it as uint8 RGBA (four bytes per
//! word, at the entry's slot: [`stage_views`]). So a command buffer of many iterations needs
//! nothing from the host between them, and the dataset itself stays on the host: it may be
//! larger than one storage buffer (lavapipe's is 128 MiB; 500 objects per class of the NMR
//! layout are 1.2 GB).
//!
//! Per batch slot b: the encoder's input is view a's RGBA / 255 (`4 × H × W`, NCHW); the
//! silhouette targets are the alphas of views a and b (copies `2b` and `2b + 1`); the copies'
//! rotations are the views' [`super::view_rotation`]s, from a table of one per view.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::{BufferRange, Context, Kernel, Recorder, check_binding};
use crate::specs;

/// Push constants of `recon_batch.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct BatchPush {
    batch: u32,
    pixels: u32,
    views: u32,
    iteration: u32,
}

/// The shape of a gather: batch slots, pixels per view, views per object.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchShape {
    /// Objects per batch.
    pub batch: u32,
    /// `H × W` of every view.
    pub pixels: u32,
    /// Views per object in the images (24 in the NMR data).
    pub views: u32,
}

/// The gather kernel.
pub struct BatchGather {
    kernel: Arc<Kernel>,
}

/// The buffers of one gather.
#[derive(Clone, Copy)]
pub struct BatchBuffers<'a> {
    /// The staged views ([`stage_views`]): uint8 RGBA, `[slot][view a, view b][channel][pixel]`,
    /// packed four per u32 (little-endian).
    pub views: BufferRange<'a>,
    /// `(object, view a, view b, slot of the staged views)` per batch slot, iteration-major.
    pub schedule: BufferRange<'a>,
    /// `(cos φ, sin φ)` per view.
    pub view_rotations: BufferRange<'a>,
    /// Out: `batch × 4 × pixels` floats.
    pub input: BufferRange<'a>,
    /// Out: `2 batch × pixels` floats.
    pub targets: BufferRange<'a>,
    /// Out: `2 batch` `(cos φ, sin φ)`.
    pub rotations: BufferRange<'a>,
    /// Out: `2 batch × pixels` RGBA (4 floats per pixel).
    pub target_images: BufferRange<'a>,
}

impl BatchGather {
    /// The pipeline.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            kernel: ctx.kernel(&specs::RECON_BATCH, &[])?,
        })
    }

    /// Records the gather of schedule row `iteration`. The schedule's object and view indices
    /// are not checked on the GPU: the host checks them when it builds the schedule
    /// ([`cpu::check_schedule`]).
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        shape: BatchShape,
        iteration: u32,
        b: BatchBuffers<'_>,
    ) -> Result<()> {
        let (n, px) = (u64::from(shape.batch), u64::from(shape.pixels));
        if n == 0 || px == 0 || shape.views == 0 {
            return Err(Error::Input(format!("an empty batch shape {shape:?}")));
        }
        let check = crate::gpu::check_floats;
        check(
            "batch: schedule",
            &b.schedule,
            4 * n * (u64::from(iteration) + 1),
        )?;
        check(
            "batch: view rotations",
            &b.view_rotations,
            2 * u64::from(shape.views),
        )?;
        check("batch: input", &b.input, 4 * n * px)?;
        check("batch: targets", &b.targets, 2 * n * px)?;
        check("batch: rotations", &b.rotations, 4 * n)?;
        check("batch: target images", &b.target_images, 8 * n * px)?;
        if b.views.size < 2 * 4 * px {
            return Err(Error::Input(format!(
                "batch: the staged views `{}` hold less than one pair",
                b.views.buffer.name()
            )));
        }
        rec.dispatch(
            &self.kernel,
            &specs::ReconBatchBindings {
                views: b.views,
                schedule: b.schedule,
                view_rotations: b.view_rotations,
                input: b.input,
                targets: b.targets,
                rotations: b.rotations,
                target_images: b.target_images,
            }
            .for_kernel(&self.kernel)?,
            &BatchPush {
                batch: shape.batch,
                pixels: shape.pixels,
                views: shape.views,
                iteration,
            },
            crate::gpu::groups(n * px, 64)?,
        )
    }
}

/// The views `entries` name, staged for the gather: entry i's views a and b of its object,
/// from `images` (uint8 RGBA, the NMR layout `[object][view][channel][pixel]` of `shape`'s views
/// and pixels), at slot i (written to the entry's fourth field), packed four bytes per word.
/// [`Error::Input`] for an entry outside the images; [`Error::DeviceLimit`] when the staged
/// views exceed a storage buffer (fewer iterations per submission, or a smaller batch, fit).
pub fn stage_views(
    ctx: &Context,
    images: &[u8],
    shape: BatchShape,
    entries: &mut [[u32; 4]],
) -> Result<Vec<u32>> {
    let view_bytes = 4 * shape.pixels as usize;
    let objects = images.len() / (view_bytes * shape.views as usize).max(1);
    cpu::check_schedule(entries, objects as u32, shape.views)?;
    check_binding(
        ctx,
        "a submission's staged training views (fewer iterations per submission or a smaller \
         batch fit)",
        2 * view_bytes as u64 * entries.len() as u64,
    )?;
    let mut staged = Vec::with_capacity(2 * entries.len() * view_bytes / 4);
    for (i, e) in entries.iter_mut().enumerate() {
        for v in [e[1], e[2]] {
            let at = (e[0] as usize * shape.views as usize + v as usize) * view_bytes;
            staged.extend(cpu::pack_bytes(&images[at..at + view_bytes]));
        }
        e[3] = i as u32;
    }
    Ok(staged)
}

/// CPU twin.
pub mod cpu {
    use super::BatchShape;
    use crate::error::{Error, Result};

    /// What [`gather`] gives: the kernel's outputs.
    pub struct Gathered {
        /// The encoder's input, `batch × 4 × pixels`.
        pub input: Vec<f32>,
        /// The copies' alphas, `2 batch × pixels`.
        pub targets: Vec<f32>,
        /// The copies' rotations.
        pub rotations: Vec<[f32; 2]>,
        /// The copies' RGBA per pixel.
        pub target_images: Vec<[f32; 4]>,
    }

    /// The batch of schedule row `iteration`, as the kernel computes it from the views
    /// [`super::stage_views`] staged (`views`, unpacked: `[slot][view a, view b][channel]
    /// [pixel]`; bytes as `f32` times the `f32` nearest 1/255).
    pub fn gather(
        views: &[u8],
        schedule: &[[u32; 4]],
        view_rotations: &[[f32; 2]],
        shape: BatchShape,
        iteration: u32,
    ) -> Gathered {
        let (n, px) = (shape.batch as usize, shape.pixels as usize);
        let scale = 1.0f32 / 255.0;
        let mut input = vec![0.0; 4 * n * px];
        let mut targets = vec![0.0; 2 * n * px];
        let mut rotations = vec![[0.0; 2]; 2 * n];
        let mut target_images = vec![[0.0; 4]; 2 * n * px];
        for b in 0..n {
            let [_, va, vb, slot] = schedule[iteration as usize * n + b].map(|x| x as usize);
            let view = |j: usize| &views[(2 * slot + j) * 4 * px..(2 * slot + j + 1) * 4 * px];
            for (dst, &src) in input[4 * b * px..4 * (b + 1) * px].iter_mut().zip(view(0)) {
                *dst = f32::from(src) * scale;
            }
            for (j, v) in [va, vb].into_iter().enumerate() {
                for (dst, &src) in targets[(2 * b + j) * px..(2 * b + j + 1) * px]
                    .iter_mut()
                    .zip(&view(j)[3 * px..])
                {
                    *dst = f32::from(src) * scale;
                }
                rotations[2 * b + j] = view_rotations[v];
                for p in 0..px {
                    target_images[(2 * b + j) * px + p] =
                        [0, 1, 2, 3].map(|c| f32::from(view(j)[c * px + p]) * scale);
                }
            }
        }
        Gathered {
            input,
            targets,
            rotations,
            target_images,
        }
    }

    /// [`Error::Input`] unless every entry names an object below `objects` and views below
    /// `views`.
    pub fn check_schedule(schedule: &[[u32; 4]], objects: u32, views: u32) -> Result<()> {
        for (i, e) in schedule.iter().enumerate() {
            if e[0] >= objects || e[1] >= views || e[2] >= views {
                return Err(Error::Input(format!(
                    "schedule entry {i} {e:?}: {objects} objects of {views} views"
                )));
            }
        }
        Ok(())
    }

    /// Packs bytes four to a little-endian u32 word, zero-padded: the images' GPU layout.
    pub fn pack_bytes(bytes: &[u8]) -> Vec<u32> {
        bytes
            .chunks(4)
            .map(|c| {
                let mut w = [0u8; 4];
                w[..c.len()].copy_from_slice(c);
                u32::from_le_bytes(w)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<BatchPush>() as u32,
            specs::RECON_BATCH.push_constant_size
        );
    }

    #[test]
    fn schedule_out_of_range_is_an_input_error() {
        assert!(cpu::check_schedule(&[[1, 23, 0, 0]], 2, 24).is_ok());
        for bad in [[2, 0, 0, 0], [0, 24, 0, 0], [0, 0, 24, 0]] {
            assert!(matches!(
                cpu::check_schedule(&[[0, 0, 0, 0], bad], 2, 24),
                Err(Error::Input(m)) if m.contains("entry 1")
            ));
        }
    }
}
