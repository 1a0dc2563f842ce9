//! The batches: the schedule computed from the seed and the iteration alone, its rows staged
//! per submission, and each iteration's gather of inputs, targets and rotations on the GPU.

use std::ops::Range;

use super::{COPIES, TrainImages, VIEWS, view_azimuth};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::recon::batch::{BatchBuffers, BatchGather, BatchShape};
use crate::recon::decode::view_rotation;
use crate::rng::SplitMix64;

/// SplitMix64's output for one counter value: the schedule is a stateless function of the
/// seed and the position, so a resumed run needs no generator state.
fn mix(z: u64) -> u64 {
    SplitMix64(z).next_u64()
}

/// Uniform in `0..n` from a 64-bit word (Lemire's multiply-shift; the bias is below 2^-32).
fn below(word: u64, n: u32) -> u32 {
    (((word >> 32) * u64::from(n)) >> 32) as u32
}

/// Batch slot `slot` of iteration `iteration`: `(object, view a, view b, 0)`, SoftRas's
/// sampler (a class uniformly, an object of it uniformly, two views uniformly), from the seed
/// and the position alone.
pub fn schedule_entry(
    seed: u64,
    iteration: u32,
    slot: u32,
    classes: &[(String, Range<u32>)],
) -> [u32; 4] {
    let key = mix(seed ^ mix((u64::from(iteration) << 32) | u64::from(slot)));
    let class = &classes[below(mix(key ^ 1), classes.len() as u32) as usize].1;
    let object = class.start + below(mix(key ^ 2), class.end - class.start);
    [
        object,
        below(mix(key ^ 3), VIEWS),
        below(mix(key ^ 4), VIEWS),
        0,
    ]
}

/// Host bytes staged for one submission: written to host-visible memory and copied to a device
/// buffer at the submission's start (no submission of their own); both grow as submissions
/// need. The trainers stage their schedule rows and the views those rows name through it.
pub(crate) struct Staged {
    name: &'static str,
    device: Buffer,
    upload: Buffer,
    /// Bytes staged for the next copy.
    staged: u64,
}

impl Staged {
    /// Room for `bytes` to start with.
    pub(crate) fn new(ctx: &Context, name: &'static str, bytes: u64) -> Result<Self> {
        let bytes = bytes.max(4);
        Ok(Self {
            name,
            device: ctx.create_buffer(name, bytes, MemoryKind::Device)?,
            upload: ctx.create_buffer(name, bytes, MemoryKind::Upload)?,
            staged: 0,
        })
    }

    /// Stages `bytes` for the next [`Staged::record_copy`].
    pub(crate) fn stage(&mut self, ctx: &Context, bytes: &[u8]) -> Result<()> {
        let size = bytes.len() as u64;
        if size > self.device.size() {
            self.device = ctx.create_buffer(self.name, size, MemoryKind::Device)?;
            self.upload = ctx.create_buffer(self.name, size, MemoryKind::Upload)?;
        }
        self.upload
            .mapped_mut()
            .ok_or_else(|| Error::Limit("upload memory is not host-mapped".into()))?[..bytes.len()]
            .copy_from_slice(bytes);
        self.staged = size;
        Ok(())
    }

    /// Records the copy of the staged bytes to the device buffer.
    pub(crate) fn record_copy(&self, rec: &mut Recorder<'_>) {
        rec.copy(&self.upload, 0, &self.device, 0, self.staged);
    }

    /// The device buffer (what the batch gather reads).
    pub(crate) fn buffer(&self) -> &Buffer {
        &self.device
    }
}

/// The schedule's rows of `iterations` (`objects` per iteration, iteration-major); with
/// `both_views`, each object's row is followed by its views swapped (the second view as an
/// input too).
fn schedule_rows(
    seed: u64,
    classes: &[(String, Range<u32>)],
    objects: u32,
    both_views: bool,
    iterations: std::ops::RangeInclusive<u32>,
) -> Vec<[u32; 4]> {
    iterations
        .flat_map(|it| (0..objects).map(move |s| (it, s)))
        .map(|(it, s)| schedule_entry(seed, it, s, classes))
        .flat_map(|[o, a, b, _]| {
            let swapped = both_views.then_some([o, b, a, 0]);
            std::iter::once([o, a, b, 0]).chain(swapped)
        })
        .collect()
}

/// A trainer's batches on the GPU: the training images (borrowed, on the host), the schedule's
/// rows staged per submission, and each iteration's gathered input, targets, view rotations and
/// target images. Both trainers use it.
pub(crate) struct Batches<'d> {
    classes: Vec<(String, Range<u32>)>,
    seed: u64,
    /// Objects per batch.
    objects: u32,
    both_views: bool,
    shape: BatchShape,
    gather: BatchGather,
    /// The training images (the NMR layout, on the host, borrowed: the views a submission's
    /// rows name are staged for it, so the dataset may be larger than a storage buffer).
    images: &'d [u8],
    views: Staged,
    view_table: Buffer,
    schedule: Staged,
    pub(crate) input: Buffer,
    pub(crate) targets: Buffer,
    pub(crate) target_images: Buffer,
    pub(crate) rotations: Buffer,
}

impl<'d> Batches<'d> {
    /// `data` uploaded, for batches of `objects` objects drawn from `seed`, each seen from its
    /// view a or, with `both_views`, from a and from b (two inputs).
    pub(crate) fn new(
        ctx: &Context,
        data: &'d TrainImages,
        objects: u32,
        both_views: bool,
        seed: u64,
    ) -> Result<Self> {
        let batch = objects.saturating_mul(1 + u32::from(both_views));
        let b = u64::from(batch);
        let px = u64::from(data.size) * u64::from(data.size);
        let device = |name: &str, floats: u64| {
            ctx.create_buffer(name, 4 * floats.max(1), MemoryKind::Device)
        };
        let table: Vec<[f32; 2]> = (0..VIEWS).map(|v| view_rotation(view_azimuth(v))).collect();
        Ok(Self {
            classes: data.classes.clone(),
            seed,
            objects,
            both_views,
            shape: BatchShape {
                batch,
                pixels: data.size * data.size,
                views: VIEWS,
            },
            gather: BatchGather::new(ctx)?,
            images: &data.images,
            views: Staged::new(ctx, "recon staged views", 2 * 4 * b * px)?,
            view_table: ctx.upload_buffer("recon view rotations", &table)?,
            schedule: Staged::new(ctx, "recon schedule", 16 * b)?,
            input: device("recon input", 4 * b * px)?,
            targets: device("recon targets", u64::from(COPIES) * b * px)?,
            target_images: device("recon target images", 4 * u64::from(COPIES) * b * px)?,
            rotations: device("recon rotations", 2 * u64::from(COPIES) * b)?,
        })
    }

    /// Stages the rows of iterations `first ..= last` and returns them (one per input, in the
    /// iteration's batch order).
    /// The rows' two views each are staged beside them ([`crate::recon::batch::stage_views`]); a
    /// submission whose views exceed a storage buffer is [`Error::DeviceLimit`].
    pub(crate) fn stage(&mut self, ctx: &Context, first: u32, last: u32) -> Result<Vec<[u32; 4]>> {
        let mut entries = schedule_rows(
            self.seed,
            &self.classes,
            self.objects,
            self.both_views,
            first..=last,
        );
        let views = crate::recon::batch::stage_views(ctx, self.images, self.shape, &mut entries)?;
        self.views.stage(ctx, bytemuck::cast_slice(&views))?;
        self.schedule.stage(ctx, bytemuck::cast_slice(&entries))?;
        Ok(entries)
    }

    /// Records the gather of schedule row `row` (the staged rows copied in before row 0's).
    pub(crate) fn record(&self, rec: &mut Recorder<'_>, row: u32) -> Result<()> {
        if row == 0 {
            self.schedule.record_copy(rec);
            self.views.record_copy(rec);
        }
        rec.pass("recon batch", |rec| {
            self.gather.record(
                rec,
                self.shape,
                row,
                BatchBuffers {
                    views: self.views.buffer().whole(),
                    schedule: self.schedule.buffer().whole(),
                    view_rotations: self.view_table.whole(),
                    input: self.input.whole(),
                    targets: self.targets.whole(),
                    rotations: self.rotations.whole(),
                    target_images: self.target_images.whole(),
                },
            )
        })
    }
}
