//! [`FragmentRasterizer`]'s host-slice entry points: the upload of faces, meshes and
//! neighbours, the checks of a host call's arrays, `rasterize_to`, `rasterize_into`,
//! `rasterize` and `rasterize_grad_into`, and the layouts of their host-visible buffers.

use super::super::{check_finite, check_pix_to_face};
use super::{FragmentGrads, FragmentInputs, FragmentOutputs, FragmentPlan, FragmentRasterizer};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, MemoryKind};

fn host_buffer(
    ctx: &Context,
    slot: &mut Option<Buffer>,
    name: &str,
    bytes: u64,
    kind: MemoryKind,
) -> Result<()> {
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = None; // free the old one first
        *slot = Some(ctx.create_buffer(name, bytes.max(16), kind)?);
    }
    Ok(())
}

impl FragmentRasterizer {
    /// Uploads the faces and mesh table (and neighbours) into the host-visible input buffer:
    /// face vertices at 0, the mesh table, the neighbours, then `extra` bytes for the caller.
    fn upload_inputs(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
        extra: u64,
    ) -> Result<InputLayout> {
        let faces = u64::from(plan.face_count);
        let layout = InputLayout::new(faces, plan.meshes.len() as u64, extra);
        host_buffer(
            ctx,
            &mut self.host.inputs,
            "fragment inputs",
            layout.total,
            MemoryKind::Upload,
        )?;
        let buffer = self.host.inputs.as_mut().expect("made above");
        let bytes = buffer
            .mapped_mut()
            .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
        let put = |bytes: &mut [u8], at: u64, data: &[u8]| {
            bytes[at as usize..at as usize + data.len()].copy_from_slice(data);
        };
        put(bytes, 0, bytemuck::cast_slice(face_verts));
        put(bytes, layout.meshes, bytemuck::cast_slice(&plan.meshes));
        let nb = &mut bytes[layout.neighbors as usize..(layout.neighbors + 4 * faces) as usize];
        match neighbors {
            Some(list) => {
                for (dst, &n) in nb.chunks_exact_mut(4).zip(list) {
                    let n = if (0..i64::from(plan.face_count)).contains(&n) {
                        n as i32
                    } else {
                        -1
                    };
                    dst.copy_from_slice(&n.to_ne_bytes());
                }
            }
            None => nb.fill(0xFF),
        }
        Ok(layout)
    }

    fn check_host_inputs(
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
    ) -> Result<()> {
        let faces = plan.face_count as usize;
        if face_verts.len() != 9 * faces {
            return Err(Error::Input(format!(
                "fragment rasterizer: {} face-vertex floats for {faces} faces (9 each)",
                face_verts.len()
            )));
        }
        if let Some(nb) = neighbors {
            if nb.len() != faces {
                return Err(Error::Input(format!(
                    "fragment rasterizer: {} neighbours for {faces} faces",
                    nb.len()
                )));
            }
        }
        check_finite(face_verts)
    }

    /// The forward on host slices: `face_verts` (nine f32 per face), written into `out`, a
    /// host-visible buffer of at least `SlotParts::new(plan.slots()).total` bytes, at that
    /// layout's offsets. Waits for the device.
    pub fn rasterize_to(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
        out: &Buffer,
    ) -> Result<()> {
        Self::check_host_inputs(plan, face_verts, neighbors)?;
        let slots = plan.slots();
        let parts = SlotParts::new(slots);
        out.whole().require(parts.total, "fragment outputs")?;
        let layout = self.upload_inputs(ctx, plan, face_verts, neighbors, 0)?;
        let inputs_buffer = self.host.inputs.take().expect("uploaded");
        let result = (|| {
            let inputs = layout.inputs(&inputs_buffer);
            self.submit(ctx, |s, rec| s.record_setup(rec, plan, inputs))?;
            self.bin(ctx)?;
            let bound = self.longest_run_bound(plan)?;
            // Crowded tiles: the lists first, then the real longest run decides.
            let sorted_first = Self::forward_passes(plan, bound) > 1;
            let mut passes = 1;
            if sorted_first {
                self.submit(ctx, |s, rec| s.record_sort(rec, plan))?;
                passes = Self::forward_passes(plan, self.longest_run(ctx, plan)?);
            }
            let [p, z, d, b] = parts.at;
            let outputs = FragmentOutputs {
                pix_to_face: out.range(p, 8 * slots),
                zbuf: out.range(z, 4 * slots),
                dists: out.range(d, 4 * slots),
                bary_coords: out.range(b, 12 * slots),
            };
            let neighbors =
                inputs_buffer.range(layout.neighbors, 4 * u64::from(plan.face_count).max(1));
            self.submit(ctx, |s, rec| {
                if !sorted_first {
                    s.record_sort(rec, plan)?;
                }
                s.record_forward(rec, plan, inputs, neighbors, &outputs, passes)
            })
        })();
        self.host.inputs = Some(inputs_buffer);
        result
    }

    /// The forward on host slices: `face_verts` (nine f32 per face), written into `out`'s
    /// slices (each `plan.slots()` long; three f32 a slot for the barycentrics).
    pub fn rasterize_into(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
        out: HostFragments<'_>,
    ) -> Result<()> {
        let slots = plan.slots();
        let n = slots as usize;
        if out.pix_to_face.len() != n
            || out.zbuf.len() != n
            || out.dists.len() != n
            || out.bary_coords.len() != 3 * n
        {
            return Err(Error::Input(
                "fragment rasterizer: output slices of the wrong length".into(),
            ));
        }
        let parts = SlotParts::new(slots);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "fragments",
            parts.total,
            MemoryKind::Readback,
        )?;
        let outputs_buffer = self.host.outputs.take().expect("made above");
        let result = self.rasterize_to(ctx, plan, face_verts, neighbors, &outputs_buffer);
        if result.is_ok() {
            let bytes = outputs_buffer
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let [p, z, d, b] = parts.at;
            let part = |at: u64, len: u64| &bytes[at as usize..(at + len) as usize];
            bytemuck::cast_slice_mut::<i64, u8>(out.pix_to_face)
                .copy_from_slice(part(p, 8 * slots));
            bytemuck::cast_slice_mut::<f32, u8>(out.zbuf).copy_from_slice(part(z, 4 * slots));
            bytemuck::cast_slice_mut::<f32, u8>(out.dists).copy_from_slice(part(d, 4 * slots));
            bytemuck::cast_slice_mut::<f32, u8>(out.bary_coords)
                .copy_from_slice(part(b, 12 * slots));
        }
        self.host.outputs = Some(outputs_buffer);
        result
    }

    /// The forward on host slices, into new vectors.
    pub fn rasterize(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
    ) -> Result<GpuFragments> {
        let n = plan.slots() as usize;
        let mut f = GpuFragments {
            pix_to_face: vec![0; n],
            zbuf: vec![0.0; n],
            dists: vec![0.0; n],
            bary_coords: vec![0.0; 3 * n],
        };
        self.rasterize_into(
            ctx,
            plan,
            face_verts,
            neighbors,
            HostFragments {
                pix_to_face: &mut f.pix_to_face,
                zbuf: &mut f.zbuf,
                dists: &mut f.dists,
                bary_coords: &mut f.bary_coords,
            },
        )?;
        Ok(f)
    }

    /// The backward on host slices: the gradient of
    /// `Σ grad_zbuf·zbuf + grad_bary·bary_coords + grad_dists·dists` to `face_verts`, given
    /// the forward's `pix_to_face`, into `grad_face_verts` (nine f32 per face).
    #[allow(clippy::too_many_arguments)]
    pub fn rasterize_grad_into(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        pix_to_face: &[i64],
        grad_zbuf: &[f32],
        grad_bary: &[f32],
        grad_dists: &[f32],
        grad_face_verts: &mut [f32],
    ) -> Result<()> {
        Self::check_host_inputs(plan, face_verts, None)?;
        let slots = plan.slots();
        let n = slots as usize;
        if pix_to_face.len() != n
            || grad_zbuf.len() != n
            || grad_dists.len() != n
            || grad_bary.len() != 3 * n
            || grad_face_verts.len() != face_verts.len()
        {
            return Err(Error::Input(
                "fragment rasterizer backward: slices of the wrong length".into(),
            ));
        }
        check_pix_to_face(pix_to_face, plan.face_count as usize)?;
        let parts = SlotParts::new(slots);
        let layout = self.upload_inputs(ctx, plan, face_verts, None, parts.total)?;
        {
            let buffer = self.host.inputs.as_mut().expect("uploaded");
            let bytes = buffer.mapped_mut().expect("host-mapped");
            for (at, part) in parts.at.iter().zip([
                bytemuck::cast_slice::<i64, u8>(pix_to_face),
                bytemuck::cast_slice(grad_zbuf),
                bytemuck::cast_slice(grad_dists),
                bytemuck::cast_slice(grad_bary),
            ]) {
                let at = (layout.extra + at) as usize;
                bytes[at..at + part.len()].copy_from_slice(part);
            }
        }
        let faces = u64::from(plan.face_count);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "fragments",
            (36 * faces).max(36),
            MemoryKind::Readback,
        )?;
        let inputs_buffer = self.host.inputs.take().expect("uploaded");
        let outputs_buffer = self.host.outputs.take().expect("made above");
        let result = (|| {
            let inputs = layout.inputs(&inputs_buffer);
            self.submit(ctx, |s, rec| s.record_setup(rec, plan, inputs))?;
            self.bin(ctx)?;
            let e = layout.extra;
            let [p, z, d, b] = parts.at.map(|at| e + at);
            let grads = FragmentGrads {
                pix_to_face: inputs_buffer.range(p, 8 * slots),
                grad_zbuf: inputs_buffer.range(z, 4 * slots),
                grad_dists: inputs_buffer.range(d, 4 * slots),
                grad_bary: inputs_buffer.range(b, 12 * slots),
            };
            let out = outputs_buffer.range(0, (36 * faces).max(4));
            self.submit(ctx, |s, rec| {
                // Faces of no mesh get 0.
                rec.fill(out, 0);
                s.record_backward(rec, plan, inputs, &grads, out)
            })?;
            let bytes = outputs_buffer.mapped().expect("host-mapped");
            bytemuck::cast_slice_mut::<f32, u8>(grad_face_verts)
                .copy_from_slice(&bytes[..36 * faces as usize]);
            Ok(())
        })();
        self.host.inputs = Some(inputs_buffer);
        self.host.outputs = Some(outputs_buffer);
        result
    }
}

/// Every part of a host-visible buffer starts 256-byte aligned: a storage binding's offset
/// alignment on any device.
fn align(x: u64) -> u64 {
    x.next_multiple_of(256)
}

/// Where the per-slot arrays lie in one buffer ([`FragmentRasterizer::rasterize_to`]):
/// `pix_to_face` (or its i64 upstream twin), `zbuf`, `dists`, `bary_coords`, in that order, each
/// at a byte offset 256-byte aligned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlotParts {
    /// Byte offsets of `pix_to_face`, `zbuf`, `dists` and `bary_coords`.
    pub at: [u64; 4],
    /// Bytes in all.
    pub total: u64,
}

impl SlotParts {
    /// The layout of `slots` slots.
    pub fn new(slots: u64) -> Self {
        let z = align(8 * slots);
        let d = z + align(4 * slots);
        let b = d + align(4 * slots);
        Self {
            at: [0, z, d, b],
            total: b + 12 * slots,
        }
    }
}

/// Where [`FragmentRasterizer`]'s host-visible input buffer holds each part.
struct InputLayout {
    meshes: u64,
    neighbors: u64,
    extra: u64,
    total: u64,
}

impl InputLayout {
    fn new(faces: u64, meshes: u64, extra: u64) -> Self {
        let m = align(36 * faces.max(1));
        let nb = m + align(8 * meshes);
        let e = nb + align(4 * faces.max(1));
        Self {
            meshes: m,
            neighbors: nb,
            extra: e,
            total: e + extra,
        }
    }

    fn inputs<'a>(&self, buffer: &'a Buffer) -> FragmentInputs<'a> {
        FragmentInputs {
            face_verts: buffer.range(0, self.meshes),
            meshes: buffer.range(self.meshes, self.neighbors - self.meshes),
        }
    }
}

/// The forward's outputs on the host, `[meshes, H, W, K]` slot-major (PyTorch3D's layout).
pub struct HostFragments<'a> {
    /// The packed face of each slot, −1 where empty.
    pub pix_to_face: &'a mut [i64],
    /// Depth per slot (−1 where empty).
    pub zbuf: &'a mut [f32],
    /// Signed squared distance per slot (−1 where empty).
    pub dists: &'a mut [f32],
    /// Three barycentrics per slot (−1 where empty).
    pub bary_coords: &'a mut [f32],
}

/// The forward's outputs in vectors ([`FragmentRasterizer::rasterize`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GpuFragments {
    /// The packed face of each slot, −1 where empty.
    pub pix_to_face: Vec<i64>,
    /// Depth per slot.
    pub zbuf: Vec<f32>,
    /// Signed squared distance per slot.
    pub dists: Vec<f32>,
    /// Three barycentrics per slot.
    pub bary_coords: Vec<f32>,
}
