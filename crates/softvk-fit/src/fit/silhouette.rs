//! Image losses on the renderer's output: SoftRas's silhouette loss `neg_iou_loss` on the alpha
//! channel, and the image MSE over RGBA. Both write dL/d(image) in the layout the renderer's
//! backward takes as `d_image` (RGBA per pixel, view-major).
//!
//! - [`SilhouetteLoss`]: `I_n = Σ P T`, `U_n = Σ (P + T − P T) + 1e-6` per view n over its
//!   pixels (P the predicted alpha, T the target silhouette), `L = 1 − (1/N) Σ_n I_n / U_n`,
//!   `dL/dP = −(1/N) (T U_n − I_n (1 − T)) / U_n²` (RGB gradients 0).
//!   Kernels: `iou_views.comp` (one workgroup per view), `fit_sum.comp` (the loss),
//!   `iou_grad.comp` (per pixel).
//! - [`ImageMse`]: `L = mean((P − T)²)` over the M = N·W·H·4 RGBA values, `dL/dP = 2 (P − T) / M`.
//!   Kernels: `mse_views.comp`, `fit_sum.comp`, `mse_grad.comp`.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{GradOut, check_binding, check_floats, groups};
use crate::primitives::sum::{Sum, SumPush};
use crate::specs;

/// SoftRas's union epsilon.
pub const IOU_EPS: f64 = 1e-6;

/// Push constants of `iou_views.comp` and `mse_views.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ViewsPush {
    pixels: u32,
    views: u32,
}

/// Push constants of `iou_grad.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct IouGradPush {
    pixels: u32,
    views: u32,
    coef: f32,
    accumulate: u32,
}

/// Push constants of `mse_grad.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct MseGradPush {
    count: u32,
    coef: f32,
    accumulate: u32,
    pad: u32,
}

/// Image dimensions shared by both losses, checked once.
#[derive(Clone, Copy, Debug)]
struct Shape {
    views: u32,
    pixels: u32,
}

impl Shape {
    fn new(ctx: &Context, what: &str, views: u32, width: u32, height: u32) -> Result<Self> {
        if views == 0 || width == 0 || height == 0 {
            return Err(Error::Input(format!(
                "{what}: {views} views of {width}×{height} pixels; every count must be positive"
            )));
        }
        let pixels = u64::from(width) * u64::from(height);
        // RGBA images are the largest binding.
        check_binding(
            ctx,
            &format!("{what}: {views} RGBA images of {width}×{height}"),
            16 * pixels * u64::from(views),
        )?;
        Ok(Self {
            views,
            pixels: pixels as u32, // < maxStorageBufferRange / 16
        })
    }

    fn total(&self) -> u64 {
        u64::from(self.pixels) * u64::from(self.views)
    }
}

/// SoftRas's `neg_iou_loss` on the GPU for N views of W×H (see the [module docs](self)).
pub struct SilhouetteLoss {
    views_kernel: Arc<Kernel>,
    grad_kernel: Arc<Kernel>,
    sum: Sum,
    shape: Shape,
    stats: Buffer,
    loss: Buffer,
}

impl SilhouetteLoss {
    /// Pipelines and output buffers for `views` images of `width`×`height`.
    pub fn new(ctx: &Context, views: u32, width: u32, height: u32) -> Result<Self> {
        let shape = Shape::new(ctx, "silhouette loss", views, width, height)?;
        Ok(Self {
            views_kernel: ctx.kernel(&specs::IOU_VIEWS, &[])?,
            grad_kernel: ctx.kernel(&specs::IOU_GRAD, &[])?,
            sum: Sum::new(ctx)?,
            shape,
            stats: ctx.create_buffer(
                "silhouette loss per-view stats",
                16 * u64::from(views),
                MemoryKind::Device,
            )?,
            loss: ctx.create_buffer("silhouette loss", 4, MemoryKind::Device)?,
        })
    }

    /// Records the loss of the alpha channel of `images` (RGBA, N·W·H·4 floats) against
    /// `targets` (N·W·H floats), and, with `d_image`, its gradient (RGBA, N·W·H·4 floats; RGB 0).
    /// The loss lands in [`Self::loss_buffer`], the per-view values in [`Self::stats_buffer`].
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        images: BufferRange<'_>,
        targets: BufferRange<'_>,
        d_image: Option<GradOut<'_>>,
    ) -> Result<()> {
        let n = self.shape.total();
        check_floats("silhouette loss: images", &images, 4 * n)?;
        check_floats("silhouette loss: targets", &targets, n)?;
        if let Some(d) = &d_image {
            check_floats("silhouette loss: d_image", &d.range, 4 * n)?;
        }
        let views = ViewsPush {
            pixels: self.shape.pixels,
            views: self.shape.views,
        };
        rec.dispatch(
            &self.views_kernel,
            &specs::IouViewsBindings {
                images: images.sub(0, 16 * n),
                targets: targets.sub(0, 4 * n),
                stats: self.stats.whole(),
            }
            .for_kernel(&self.views_kernel)?,
            &views,
            self.shape.views,
        )?;
        let count = f64::from(self.shape.views);
        self.sum.record(
            rec,
            self.stats.whole(),
            self.loss.whole(),
            SumPush {
                n: self.shape.views,
                stride: 4,
                offset: 2,
                out_index: 0,
                scale: (-1.0 / count) as f32,
                bias: 1.0,
            },
            1,
        )?;
        if let Some(d) = d_image {
            let push = IouGradPush {
                pixels: self.shape.pixels,
                views: self.shape.views,
                coef: (-f64::from(d.weight) / count) as f32,
                accumulate: u32::from(d.accumulate),
            };
            rec.dispatch(
                &self.grad_kernel,
                &specs::IouGradBindings {
                    targets: targets.sub(0, 4 * n),
                    stats: self.stats.whole(),
                    d_image: d.range.sub(0, 16 * n),
                }
                .for_kernel(&self.grad_kernel)?,
                &push,
                groups(n, 64)?,
            )?;
        }
        Ok(())
    }

    /// One `f32`: the loss of the last recorded run.
    pub fn loss_buffer(&self) -> &Buffer {
        &self.loss
    }

    /// Four `f32` per view: `(I_n, U_n, I_n / U_n, 0)` (U with its epsilon).
    pub fn stats_buffer(&self) -> &Buffer {
        &self.stats
    }

    /// Reads the loss back (waits).
    pub fn read_loss(&self, ctx: &Context) -> Result<f32> {
        Ok(ctx.read_buffer::<f32>(&self.loss, 0, 1)?[0])
    }

    /// Reads the per-view IoUs `I_n / U_n` back (waits).
    pub fn read_ious(&self, ctx: &Context) -> Result<Vec<f32>> {
        let stats: Vec<[f32; 4]> = ctx.read_buffer(&self.stats, 0, self.shape.views as usize)?;
        Ok(stats.iter().map(|s| s[2]).collect())
    }
}

/// The mean squared error of RGBA images on the GPU (see the [module docs](self)).
pub struct ImageMse {
    views_kernel: Arc<Kernel>,
    grad_kernel: Arc<Kernel>,
    sum: Sum,
    shape: Shape,
    partials: Buffer,
    loss: Buffer,
}

impl ImageMse {
    /// Pipelines and output buffers for `views` RGBA images of `width`×`height`.
    pub fn new(ctx: &Context, views: u32, width: u32, height: u32) -> Result<Self> {
        let shape = Shape::new(ctx, "image MSE", views, width, height)?;
        Ok(Self {
            views_kernel: ctx.kernel(&specs::MSE_VIEWS, &[])?,
            grad_kernel: ctx.kernel(&specs::MSE_GRAD, &[])?,
            sum: Sum::new(ctx)?,
            shape,
            partials: ctx.create_buffer(
                "image MSE per-view sums",
                4 * u64::from(views),
                MemoryKind::Device,
            )?,
            loss: ctx.create_buffer("image MSE", 4, MemoryKind::Device)?,
        })
    }

    /// Records the MSE of `images` against `targets` (both RGBA, N·W·H·4 floats) and, with
    /// `d_image`, its gradient (RGBA). The loss lands in [`Self::loss_buffer`].
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        images: BufferRange<'_>,
        targets: BufferRange<'_>,
        d_image: Option<GradOut<'_>>,
    ) -> Result<()> {
        let n = self.shape.total();
        check_floats("image MSE: images", &images, 4 * n)?;
        check_floats("image MSE: targets", &targets, 4 * n)?;
        if let Some(d) = &d_image {
            check_floats("image MSE: d_image", &d.range, 4 * n)?;
        }
        let (images, targets) = (images.sub(0, 16 * n), targets.sub(0, 16 * n));
        let views = ViewsPush {
            pixels: self.shape.pixels,
            views: self.shape.views,
        };
        rec.dispatch(
            &self.views_kernel,
            &specs::MseViewsBindings {
                images,
                targets,
                partials: self.partials.whole(),
            }
            .for_kernel(&self.views_kernel)?,
            &views,
            self.shape.views,
        )?;
        let values = 4.0 * n as f64;
        self.sum.record(
            rec,
            self.partials.whole(),
            self.loss.whole(),
            SumPush {
                n: self.shape.views,
                stride: 1,
                offset: 0,
                out_index: 0,
                scale: (1.0 / values) as f32,
                bias: 0.0,
            },
            1,
        )?;
        if let Some(d) = d_image {
            let push = MseGradPush {
                count: n as u32,
                coef: (2.0 * f64::from(d.weight) / values) as f32,
                accumulate: u32::from(d.accumulate),
                pad: 0,
            };
            rec.dispatch(
                &self.grad_kernel,
                &specs::MseGradBindings {
                    images,
                    targets,
                    d_image: d.range.sub(0, 16 * n),
                }
                .for_kernel(&self.grad_kernel)?,
                &push,
                groups(n, 64)?,
            )?;
        }
        Ok(())
    }

    /// One `f32`: the loss of the last recorded run.
    pub fn loss_buffer(&self) -> &Buffer {
        &self.loss
    }

    /// Reads the loss back (waits).
    pub fn read_loss(&self, ctx: &Context) -> Result<f32> {
        Ok(ctx.read_buffer::<f32>(&self.loss, 0, 1)?[0])
    }
}

/// Per view, the IoU of two sets of hard silhouettes (`pixels` values a view, view after view,
/// inside where > 0.5): `|a ∩ b| / |a ∪ b|`, 0 for two empty masks. What a fit's report calls
/// its final IoU.
pub fn hard_ious(predicted: &[f32], targets: &[f32], pixels: usize) -> Vec<f32> {
    predicted
        .chunks(pixels.max(1))
        .zip(targets.chunks(pixels.max(1)))
        .map(|(p, t)| {
            let (mut both, mut any) = (0usize, 0usize);
            for (a, b) in p.iter().zip(t) {
                both += usize::from(*a > 0.5 && *b > 0.5);
                any += usize::from(*a > 0.5 || *b > 0.5);
            }
            both as f32 / any.max(1) as f32
        })
        .collect()
}

/// CPU twins, in f64.
pub mod cpu {
    use super::IOU_EPS;

    /// The silhouette loss and its gradient.
    #[derive(Clone, Debug, PartialEq)]
    pub struct NegIou {
        /// `1 − mean IoU`.
        pub loss: f64,
        /// `I_n / U_n` per view.
        pub ious: Vec<f64>,
        /// dL/d(image), RGBA per pixel (RGB 0).
        pub d_image: Vec<[f64; 4]>,
    }

    /// SoftRas's `neg_iou_loss` of the alpha channel of `images` (RGBA per pixel, view-major)
    /// against `targets` (one value per pixel), over `views` equal views.
    pub fn neg_iou(images: &[[f64; 4]], targets: &[f64], views: usize) -> NegIou {
        assert_eq!(images.len(), targets.len(), "one target per pixel");
        assert!(views > 0 && targets.len() % views == 0, "equal views");
        let pixels = targets.len() / views;
        let mut stats = Vec::with_capacity(views);
        for v in 0..views {
            let (mut i, mut u) = (0.0, 0.0);
            for p in v * pixels..(v + 1) * pixels {
                let (a, t) = (images[p][3], targets[p]);
                i += a * t;
                u += a + t - a * t;
            }
            stats.push((i, u + IOU_EPS));
        }
        let ious: Vec<f64> = stats.iter().map(|&(i, u)| i / u).collect();
        let n = views as f64;
        let loss = 1.0 - ious.iter().sum::<f64>() / n;
        let d_image = targets
            .iter()
            .enumerate()
            .map(|(p, &t)| {
                let (i, u) = stats[p / pixels];
                [0.0, 0.0, 0.0, -(t * u - i * (1.0 - t)) / (u * u) / n]
            })
            .collect();
        NegIou {
            loss,
            ious,
            d_image,
        }
    }

    /// `mean((P − T)²)` over every RGBA value, and its gradient `2 (P − T) / M`.
    pub fn mse(images: &[[f64; 4]], targets: &[[f64; 4]]) -> (f64, Vec<[f64; 4]>) {
        assert_eq!(images.len(), targets.len(), "one target per pixel");
        let m = 4.0 * images.len() as f64;
        let mut sum = 0.0;
        let grad = images
            .iter()
            .zip(targets)
            .map(|(p, t)| {
                let mut g = [0.0; 4];
                for c in 0..4 {
                    let d = p[c] - t[c];
                    sum += d * d;
                    g[c] = 2.0 * d / m;
                }
                g
            })
            .collect();
        (sum / m, grad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::{Lcg, assert_grad_matches_fd};

    #[test]
    fn push_constant_structs_match_the_kernels_layout() {
        let views = std::mem::size_of::<ViewsPush>() as u32;
        assert_eq!(views, specs::IOU_VIEWS.push_constant_size);
        assert_eq!(views, specs::MSE_VIEWS.push_constant_size);
        assert_eq!(
            std::mem::size_of::<IouGradPush>() as u32,
            specs::IOU_GRAD.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<MseGradPush>() as u32,
            specs::MSE_GRAD.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<SumPush>() as u32,
            crate::gpu::specs::FIT_SUM.push_constant_size
        );
        // The shared-memory tree assumes 256 invocations.
        for spec in [
            &specs::IOU_VIEWS,
            &specs::MSE_VIEWS,
            &crate::gpu::specs::FIT_SUM,
        ] {
            assert_eq!(spec.workgroup_size, [256, 1, 1], "{}", spec.name);
        }
        assert_eq!(specs::IOU_VIEWS.bindings.len(), 3);
        assert_eq!(specs::IOU_GRAD.bindings.len(), 3);
        assert_eq!(specs::MSE_GRAD.bindings.len(), 3);
    }

    fn random_images(rng: &mut Lcg, n: usize) -> Vec<[f64; 4]> {
        (0..n)
            .map(|_| [rng.unit(), rng.unit(), rng.unit(), rng.unit()])
            .collect()
    }

    #[test]
    fn neg_iou_twin_gradient_matches_central_differences() {
        let mut rng = Lcg(7);
        let (views, pixels) = (3, 5 * 4);
        let images = random_images(&mut rng, views * pixels);
        // Binary silhouettes, as SoftRas's targets, plus some soft values.
        let targets: Vec<f64> = (0..views * pixels)
            .map(|i| {
                if i % 7 == 3 {
                    rng.unit()
                } else {
                    f64::from(rng.unit() > 0.5)
                }
            })
            .collect();
        let out = cpu::neg_iou(&images, &targets, views);
        let flat: Vec<f64> = images.iter().flatten().copied().collect();
        let analytic: Vec<f64> = out.d_image.iter().flatten().copied().collect();
        assert_grad_matches_fd(&flat, &analytic, 1e-6, |x| {
            let img: Vec<[f64; 4]> = x.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            cpu::neg_iou(&img, &targets, views).loss
        });
        // A perfect prediction of binary silhouettes has IoU 1 (up to the epsilon).
        let hard: Vec<f64> = targets.iter().map(|&t| t.round()).collect();
        let p: Vec<[f64; 4]> = hard.iter().map(|&t| [0.0, 0.0, 0.0, t]).collect();
        assert!(cpu::neg_iou(&p, &hard, views).loss < 1e-6);
    }

    #[test]
    fn mse_twin_gradient_matches_central_differences() {
        let mut rng = Lcg(11);
        let images = random_images(&mut rng, 2 * 6);
        let targets = random_images(&mut rng, 2 * 6);
        let (_, grad) = cpu::mse(&images, &targets);
        let flat: Vec<f64> = images.iter().flatten().copied().collect();
        let analytic: Vec<f64> = grad.iter().flatten().copied().collect();
        assert_grad_matches_fd(&flat, &analytic, 1e-6, |x| {
            let img: Vec<[f64; 4]> = x.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            cpu::mse(&img, &targets).0
        });
    }
}
