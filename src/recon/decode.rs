//! The reconstruction network's heads: SoftRas's `Decoder` turns each object's network
//! outputs into vertex positions of the sphere template, and the renderer sees each object
//! through several *copies*, each turned about y so that one camera shows every view.
//!
//! With the template t (SoftRas's `sphere_642.obj` scaled by `obj_scale` = 0.5, so every
//! coordinate is in (−1, 1) and nonzero), per object the network outputs
//! `r = [r_d (3 V), r_c (3)]` and (`kernels/softvk/recon/recon_decode.comp`):
//!
//! ```text
//! base = log(|t| / (1 − |t|));   c = tanh(0.1 · r_c)
//! v = sigmoid(base + r_d) · sign(t);   v = relu(v) (1 − c) − relu(−v) (c + 1) + c
//! p = 0.5 v                                                  (the object's mesh)
//! p'_k = R_y(φ_k) p                                          (its copy k, for the renderer)
//! ```
//!
//! SoftRas's `Decoder.forward` writes `centroid = fc_centroid(x) · centroid_scale` (0.1), then
//! `centroid = tanh(centroid)` inside the deformation, and halves the result: the same chain,
//! one `tanh` (the centroid moves up to ±0.5 after the halving). Views of the NMR dataset share their
//! elevation and distance and differ only in azimuth, so view j of an object is the view of
//! the scene's single camera of the object turned by `φ_j` about y (see
//! [`view_rotation`]): a batch renders its copies as a batch of meshes with one camera, and the
//! views change per iteration on the GPU (a rotation per copy) with no new scene.
//!
//! The backward (`recon_decode_backward.comp`, then `recon_centroid_grad.comp` for r_c, a sum
//! over the vertices in a fixed order) takes dL/d(copy positions) and dL/d(object mesh) (the
//! regularizers' gradient) and writes dL/dr. Deterministic; each output has one writer.
//!
//! **The colour head** is [`ColorGenerator`]: after the mesh head's `3 V + 3`, each object's
//! outputs hold the generator's sampling and selection logits, and its vertex colours are
//! sampled from the object's input image (see [`super::colors`]). An object's outputs are thus
//! `[r_d (3 V), r_c (3), colour generator]` ([`MeshDecoder::outputs_per_object`]).

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::colors::{ColorGenerator, HeadLayout};
use crate::error::{Error, LimitKind, Result};
use crate::fit::deform::cpu::template_terms;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::specs;

/// Push constants of the three decode kernels.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DecodePush {
    vertex_count: u32,
    objects: u32,
    copies: u32,
    stride: u32,
}

/// The turn about y, as `(cos φ, sin φ)`, that brings the camera at azimuth `azimuth_deg`
/// (SoftRas's `get_points_from_angles`, any elevation and distance) to the camera at azimuth
/// 0: with `R_y(φ) (x, y, z) = (cos φ x + sin φ z, y, −sin φ x + cos φ z)`,
/// `R_y(φ) eye(θ) = eye(θ − φ)`, so `φ = θ`. The object turned by it, seen from azimuth 0, is
/// the object seen from azimuth θ.
pub fn view_rotation(azimuth_deg: f64) -> [f32; 2] {
    let phi = azimuth_deg.to_radians();
    [phi.cos() as f32, phi.sin() as f32]
}

/// The decoder's mesh head on the GPU for one template: kernels and the template's terms.
pub struct MeshDecoder {
    forward: Arc<Kernel>,
    backward: Arc<Kernel>,
    centroid: Arc<Kernel>,
    colors: ColorGenerator,
    vertex_count: u32,
    base: Buffer,
    signs: Buffer,
}

impl MeshDecoder {
    /// Pipelines and the template's `base`/`sign` buffers, for inputs of `image`² pixels (the
    /// colour generator samples them). `template` is already scaled (SoftRas scales its sphere
    /// by 0.5); every coordinate must be finite, nonzero and inside (−1, 1), else
    /// [`Error::Input`]. The centroid's gradient sums over the vertices in one loop, so a
    /// template over the device's shader loop limit is [`Error::DeviceLimit`].
    pub fn new(ctx: &Context, template: &[[f32; 3]], image: u32) -> Result<Self> {
        let (base, signs) = template_terms(template)?;
        let vertex_count = u32::try_from(template.len())
            .map_err(|_| Error::Input("the template has more than 2^32 vertices".into()))?;
        if let Some(max) = ctx.info().shader_loop_limit()
            && u64::from(vertex_count) > max
        {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: "the decoder's centroid gradient (a loop over the template's vertices)"
                    .into(),
                need: u64::from(vertex_count),
                max,
                device: ctx.info().name.clone(),
                hint: "use a template with fewer vertices",
            });
        }
        let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        Ok(Self {
            forward: ctx.kernel(&specs::RECON_DECODE, &[])?,
            backward: ctx.kernel(&specs::RECON_DECODE_BACKWARD, &[])?,
            centroid: ctx.kernel(&specs::RECON_CENTROID_GRAD, &[])?,
            colors: ColorGenerator::new(ctx, vertex_count, image)?,
            vertex_count,
            base: ctx.upload_buffer("decoder template base", &to_f32(&base))?,
            signs: ctx.upload_buffer("decoder template signs", &to_f32(&signs))?,
        })
    }

    /// Template vertices V.
    pub fn vertex_count(&self) -> u32 {
        self.vertex_count
    }

    /// Network outputs per object: `3 V` displacements, the centroid's 3, then the colour
    /// generator's ([`ColorGenerator::outputs_per_object`]).
    pub fn outputs_per_object(&self) -> u64 {
        3 * u64::from(self.vertex_count) + 3 + self.colors.outputs_per_object()
    }

    /// The colour generator (its scratch sizes: [`ColorGenerator::pooled_floats`],
    /// [`ColorGenerator::palette_floats`]).
    pub fn color_generator(&self) -> &ColorGenerator {
        &self.colors
    }

    /// Where the colour generator's outputs sit in an object's.
    pub fn color_head(&self) -> HeadLayout {
        HeadLayout {
            stride: self.outputs_per_object() as u32,
            offset: 3 * self.vertex_count + 3,
        }
    }

    /// Bytes of the scratch [`Self::record_backward`] needs for `objects` objects.
    pub fn partials_bytes(&self, objects: u32) -> u64 {
        12 * u64::from(self.vertex_count) * u64::from(objects)
    }

    /// Scratch for the backward of up to `objects` objects.
    pub fn create_partials(&self, ctx: &Context, objects: u32) -> Result<Buffer> {
        ctx.create_buffer(
            "decoder centroid partials",
            self.partials_bytes(objects).max(4),
            MemoryKind::Device,
        )
    }

    fn push(&self, objects: u32, copies: u32) -> DecodePush {
        DecodePush {
            vertex_count: self.vertex_count,
            objects,
            copies,
            stride: self.outputs_per_object() as u32,
        }
    }

    fn check(
        &self,
        objects: u32,
        copies: u32,
        outputs: &BufferRange<'_>,
        rotations: &BufferRange<'_>,
        canonical: &BufferRange<'_>,
        positions: &BufferRange<'_>,
    ) -> Result<()> {
        let (b, v, c) = (
            u64::from(objects),
            u64::from(self.vertex_count),
            u64::from(copies),
        );
        if objects == 0 {
            return Err(Error::Input("the decoder needs at least one object".into()));
        }
        crate::gpu::check_floats("decoder: outputs", outputs, b * self.outputs_per_object())?;
        crate::gpu::check_floats("decoder: rotations", rotations, 2 * b * c)?;
        crate::gpu::check_floats("decoder: meshes", canonical, 3 * b * v)?;
        crate::gpu::check_floats("decoder: copy positions", positions, 3 * b * c * v)
    }

    /// Records the forward for `objects` objects of `copies` copies each: `outputs`
    /// ([`Self::outputs_per_object`] floats per object; the mesh head reads its first `3 V + 3`) and `rotations` (`(cos φ, sin φ)` per copy, object-major)
    /// → `canonical` (`objects × V` packed positions) and `positions` (`objects × copies × V`,
    /// copy `k` of object `b` as mesh `b · copies + k`).
    #[allow(clippy::too_many_arguments)]
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        objects: u32,
        copies: u32,
        outputs: BufferRange<'_>,
        rotations: BufferRange<'_>,
        canonical: BufferRange<'_>,
        positions: BufferRange<'_>,
    ) -> Result<()> {
        self.check(
            objects, copies, &outputs, &rotations, &canonical, &positions,
        )?;
        rec.dispatch(
            &self.forward,
            &specs::ReconDecodeBindings {
                outputs,
                base: self.base.whole(),
                signs: self.signs.whole(),
                rotations,
                canonical,
                positions,
            }
            .for_kernel(&self.forward)?,
            &self.push(objects, copies),
            crate::gpu::groups(u64::from(self.vertex_count) * u64::from(objects), 64)?,
        )
    }

    /// Records the backward at `outputs`: dL/d(`canonical`) and dL/d(`positions`) (laid out as
    /// the forward writes them) → dL/d(`outputs`) (overwritten). `partials` is scratch of
    /// [`Self::partials_bytes`] ([`Self::create_partials`]).
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        objects: u32,
        copies: u32,
        outputs: BufferRange<'_>,
        rotations: BufferRange<'_>,
        d_canonical: BufferRange<'_>,
        d_positions: BufferRange<'_>,
        d_outputs: BufferRange<'_>,
        partials: BufferRange<'_>,
    ) -> Result<()> {
        self.check(
            objects,
            copies,
            &outputs,
            &rotations,
            &d_canonical,
            &d_positions,
        )?;
        crate::gpu::check_floats(
            "decoder: d_outputs",
            &d_outputs,
            u64::from(objects) * self.outputs_per_object(),
        )?;
        if partials.size < self.partials_bytes(objects) {
            return Err(Error::Input(format!(
                "decoder: the partials buffer `{}` holds {} bytes, {} needed",
                partials.buffer.name(),
                partials.size,
                self.partials_bytes(objects)
            )));
        }
        let push = self.push(objects, copies);
        rec.dispatch(
            &self.backward,
            &specs::ReconDecodeBackwardBindings {
                outputs,
                base: self.base.whole(),
                signs: self.signs.whole(),
                rotations,
                d_canonical,
                d_positions,
                d_outputs,
                partials,
            }
            .for_kernel(&self.backward)?,
            &push,
            crate::gpu::groups(u64::from(self.vertex_count) * u64::from(objects), 64)?,
        )?;
        rec.dispatch(
            &self.centroid,
            &specs::ReconCentroidGradBindings {
                outputs,
                partials,
                d_outputs,
            }
            .for_kernel(&self.centroid)?,
            &push,
            crate::gpu::groups(3 * u64::from(objects), 64)?,
        )
    }
}

impl MeshDecoder {
    /// Records the colour generator for `objects` objects of `copies` copies each, from
    /// `outputs` and the input `images` (`4 × H × W` floats per object) → `colors`, the
    /// renderer's vertex colours; `pooled` and `palette` are the generator's scratch
    /// ([`ColorGenerator::record_forward`]).
    #[allow(clippy::too_many_arguments)]
    pub fn record_colors(
        &self,
        rec: &mut Recorder<'_>,
        objects: u32,
        copies: u32,
        outputs: BufferRange<'_>,
        images: BufferRange<'_>,
        pooled: BufferRange<'_>,
        palette: BufferRange<'_>,
        colors: BufferRange<'_>,
    ) -> Result<()> {
        self.colors.record_forward(
            rec,
            objects,
            copies,
            self.color_head(),
            outputs,
            images,
            pooled,
            palette,
            colors,
        )
    }

    /// Records the colour generator's backward: dL/d(colours) (3 floats per copy vertex; zeros
    /// for a loss without colour) → the generator's slots of dL/d(`outputs`) (overwritten; the
    /// mesh head's slots are left alone) ([`ColorGenerator::record_backward`]).
    #[allow(clippy::too_many_arguments)]
    pub fn record_colors_backward(
        &self,
        rec: &mut Recorder<'_>,
        objects: u32,
        copies: u32,
        outputs: BufferRange<'_>,
        pooled: BufferRange<'_>,
        palette: BufferRange<'_>,
        d_colors: BufferRange<'_>,
        d_outputs: BufferRange<'_>,
    ) -> Result<()> {
        self.colors.record_backward(
            rec,
            objects,
            copies,
            self.color_head(),
            outputs,
            pooled,
            palette,
            d_colors,
            d_outputs,
        )
    }
}

/// CPU twin, in f64.
pub mod cpu {
    fn sigmoid(x: f64) -> f64 {
        1.0 / (1.0 + (-x).exp())
    }

    /// `(object meshes, copy positions)` from the outputs (`objects × stride`, the mesh head
    /// the first `3 V + 3` of each), the template's terms
    /// ([`crate::fit::deform::cpu::template_terms`]) and the rotations (`(cos φ, sin φ)` per
    /// copy, object-major).
    pub fn forward(
        base: &[f64],
        signs: &[f64],
        outputs: &[f64],
        stride: usize,
        rotations: &[[f64; 2]],
        copies: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let n = base.len();
        let objects = outputs.len() / stride;
        let mut canonical = vec![0.0; objects * n];
        let mut positions = vec![0.0; objects * copies * n];
        for b in 0..objects {
            let r = &outputs[b * stride..(b + 1) * stride];
            for o in 0..n {
                let c = (0.1 * r[n + o % 3]).tanh();
                let v = sigmoid(base[o] + r[o]) * signs[o];
                canonical[b * n + o] =
                    0.5 * ((v.max(0.0) * (1.0 - c) - (-v).max(0.0) * (c + 1.0)) + c);
            }
            for k in 0..copies {
                let [cs, sn] = rotations[b * copies + k];
                for i in 0..n / 3 {
                    let p = &canonical[b * n + 3 * i..b * n + 3 * i + 3];
                    let q = (b * copies + k) * n + 3 * i;
                    positions[q] = cs * p[0] + sn * p[2];
                    positions[q + 1] = p[1];
                    positions[q + 2] = cs * p[2] - sn * p[0];
                }
            }
        }
        (canonical, positions)
    }

    /// dL/d(outputs) from dL/d(object meshes) and dL/d(copy positions) (the colour
    /// generator's slots 0: see [`crate::recon::colors::cpu::backward`]).
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        base: &[f64],
        signs: &[f64],
        outputs: &[f64],
        stride: usize,
        rotations: &[[f64; 2]],
        copies: usize,
        d_canonical: &[f64],
        d_positions: &[f64],
    ) -> Vec<f64> {
        let n = base.len();
        let objects = outputs.len() / stride;
        let mut d = vec![0.0; outputs.len()];
        for b in 0..objects {
            let r = &outputs[b * stride..(b + 1) * stride];
            let mut d_c = [0.0; 3];
            for i in 0..n / 3 {
                let mut g = [0.0; 3];
                g.copy_from_slice(&d_canonical[b * n + 3 * i..b * n + 3 * i + 3]);
                for k in 0..copies {
                    let [cs, sn] = rotations[b * copies + k];
                    let q = (b * copies + k) * n + 3 * i;
                    let dp = &d_positions[q..q + 3];
                    g[0] += cs * dp[0] - sn * dp[2];
                    g[1] += dp[1];
                    g[2] += sn * dp[0] + cs * dp[2];
                }
                for (k, gk) in g.iter().enumerate() {
                    let o = 3 * i + k;
                    let c = (0.1 * r[n + k]).tanh();
                    let s = sigmoid(base[o] + r[o]);
                    let v = s * signs[o];
                    let gk = 0.5 * gk;
                    let dv = if v > 0.0 { 1.0 - c } else { c + 1.0 };
                    d[b * stride + o] = gk * dv * (s * (1.0 - s)) * signs[o];
                    d_c[k] += gk * (1.0 - v.abs());
                }
            }
            for (k, dc) in d_c.iter().enumerate() {
                let c = (0.1 * r[n + k]).tanh();
                d[b * stride + n + k] = dc * ((1.0 - c * c) * 0.1);
            }
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        let size = std::mem::size_of::<DecodePush>() as u32;
        for spec in [
            &specs::RECON_DECODE,
            &specs::RECON_DECODE_BACKWARD,
            &specs::RECON_CENTROID_GRAD,
        ] {
            assert_eq!(size, spec.push_constant_size, "{}", spec.name);
        }
    }

    #[test]
    fn decode_twin_gradient_matches_central_differences() {
        use softvk_testing::{Lcg, assert_grad_matches_fd, jittered_icosphere};
        let (x, _) = jittered_icosphere(0, 0.05, 3);
        let template: Vec<[f32; 3]> = x
            .chunks(3)
            .map(|p| {
                [
                    0.5 * p[0] as f32 + 1e-3,
                    0.5 * p[1] as f32 + 1e-3,
                    0.5 * p[2] as f32,
                ]
            })
            .collect();
        let (base, signs) = template_terms(&template).unwrap();
        let (objects, copies) = (2, 2);
        let mut rng = Lcg(11);
        let stride = base.len() + 5;
        let outputs: Vec<f64> = (0..objects * stride)
            .map(|_| rng.range(-1.5, 1.5))
            .collect();
        let rotations: Vec<[f64; 2]> = (0..objects * copies)
            .map(|_| {
                let a = rng.range(-3.0, 3.0);
                [a.cos(), a.sin()]
            })
            .collect();
        let w_canon: Vec<f64> = (0..objects * base.len())
            .map(|_| rng.range(-1.0, 1.0))
            .collect();
        let w_pos: Vec<f64> = (0..objects * copies * base.len())
            .map(|_| rng.range(-1.0, 1.0))
            .collect();
        // L = w_canon · meshes + w_pos · copies.
        let grad = cpu::backward(
            &base, &signs, &outputs, stride, &rotations, copies, &w_canon, &w_pos,
        );
        assert_grad_matches_fd(&outputs, &grad, 1e-6, |r| {
            let (c, p) = cpu::forward(&base, &signs, r, stride, &rotations, copies);
            let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
            dot(&c, &w_canon) + dot(&p, &w_pos)
        });
        // Zero outputs give the template, halved (SoftRas's final 0.5), centred.
        let zero = vec![0.0; stride];
        let (c, _) = cpu::forward(&base, &signs, &zero, stride, &[[1.0, 0.0]], 1);
        for (a, t) in c.iter().zip(template.iter().flatten()) {
            assert!((a - 0.5 * f64::from(*t)).abs() < 1e-12);
        }
        // SoftRas's centroid: with the displacements far negative every vertex collapses onto
        // it, 0.5 tanh(0.1 r_c) (a second tanh would cap it at 0.5 tanh(0.1) ≈ 0.05).
        let mut collapsed = vec![-40.0; stride];
        collapsed[base.len()..base.len() + 3].copy_from_slice(&[10.0, -10.0, 3.0]);
        let (c, _) = cpu::forward(&base, &signs, &collapsed, stride, &[[1.0, 0.0]], 1);
        let want = [1.0f64, -1.0, 0.3].map(|x| 0.5 * x.tanh());
        for p in c.chunks(3) {
            for k in 0..3 {
                assert!((p[k] - want[k]).abs() < 1e-9, "{p:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn view_rotation_brings_each_azimuth_to_the_azimuth_zero_camera() {
        for az in [-345.0, -90.0, -15.0, 0.0, 45.0, 180.0] {
            let [c, s] = view_rotation(az).map(f64::from);
            let e = crate::camera::eye_from_angles(2.732, 30.0, az);
            let turned = [c * e.x + s * e.z, e.y, c * e.z - s * e.x];
            let zero = crate::camera::eye_from_angles(2.732, 30.0, 0.0);
            for (a, b) in turned.iter().zip(zero.to_array()) {
                assert!((a - b).abs() < 1e-6, "azimuth {az}: {turned:?} vs {zero:?}");
            }
        }
    }
}
