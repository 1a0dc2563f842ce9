//! A Gaussian blur of RGBA images on the GPU, and the image MSE of blurred images: the loss a
//! fit uses to see mismatches farther than a thin part's width (the articulated fits).
//!
//! `L = mean((G * render − G * target)²)` with G a Gaussian of `std` pixels, zero outside the
//! image. Each separable pass is then a symmetric matrix, so `dL/d(render) = G * dL/d(G *
//! render)`: the gradient is the same two passes over the blurred MSE's gradient. A fit lowers
//! `std` to 0 stage by stage ([`BlurredMse`] with std 0 is the plain [`ImageMse`]). Unlike a
//! render softened by σ, the blur treats the render and the target alike, so a sharp target (a
//! photograph) is compared fairly at every width.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::ImageMse;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{GradOut, check_floats, groups};
use crate::specs;

/// The widest blur, in pixels (its taps reach 3 std).
pub const MAX_BLUR_STD: f64 = 32.0;

/// The taps' half-width for `std` pixels: ⌈3 std⌉ (0 for no blur).
pub fn blur_radius(std: f64) -> u32 {
    (3.0 * std).ceil().max(0.0) as u32
}

/// Push constants of `image_blur.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct BlurPush {
    width: u32,
    height: u32,
    pixels: u32,
    radius: u32,
    std_px: f32,
    axis: u32,
    pad: [u32; 2],
}

/// The separable Gaussian blur of `views` RGBA images of `width`×`height` (see the [module
/// docs](self)), with its scratch image.
pub struct ImageBlur {
    kernel: Arc<Kernel>,
    width: u32,
    height: u32,
    pixels: u32,
    scratch: Buffer,
}

impl ImageBlur {
    /// The pipeline and scratch for `views` images of `width`×`height`.
    pub fn new(ctx: &Context, views: u32, width: u32, height: u32) -> Result<Self> {
        let pixels = u64::from(views) * u64::from(width) * u64::from(height);
        let bytes = crate::gpu::check_binding(ctx, "a blurred image", 16 * pixels)?;
        Ok(Self {
            kernel: ctx.kernel(&specs::IMAGE_BLUR, &[])?,
            width,
            height,
            pixels: pixels as u32, // < maxStorageBufferRange / 16
            scratch: ctx.create_buffer("blur scratch", bytes, MemoryKind::Device)?,
        })
    }

    /// Records `dst = G * src` for a Gaussian of `std` pixels (0: a copy), both RGBA.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        src: BufferRange<'_>,
        dst: BufferRange<'_>,
        std: f64,
    ) -> Result<()> {
        if !(std.is_finite() && (0.0..=MAX_BLUR_STD).contains(&std)) {
            return Err(Error::Input(format!(
                "a blur of {std} pixels: it must be in [0, {MAX_BLUR_STD}]"
            )));
        }
        let n = 4 * u64::from(self.pixels);
        check_floats("blur: source", &src, n)?;
        check_floats("blur: destination", &dst, n)?;
        let push = |axis| BlurPush {
            width: self.width,
            height: self.height,
            pixels: self.pixels,
            radius: blur_radius(std),
            std_px: std.max(1e-3) as f32,
            axis,
            pad: [0; 2],
        };
        let g = groups(u64::from(self.pixels), 64)?;
        let scratch = self.scratch.whole();
        rec.dispatch(
            &self.kernel,
            &specs::ImageBlurBindings { src, dst: scratch }.for_kernel(&self.kernel)?,
            &push(0),
            g,
        )?;
        rec.dispatch(
            &self.kernel,
            &specs::ImageBlurBindings { src: scratch, dst }.for_kernel(&self.kernel)?,
            &push(1),
            g,
        )
    }
}

/// The image MSE of blurred images (see the [module docs](self)): the blurs, [`ImageMse`] and
/// the blurred gradient, with their scratch images.
pub struct BlurredMse {
    blur: ImageBlur,
    mse: ImageMse,
    render: Buffer,
    target: Buffer,
    grad: Buffer,
}

impl BlurredMse {
    /// Pipelines and scratch for `views` RGBA images of `width`×`height`.
    pub fn new(ctx: &Context, views: u32, width: u32, height: u32) -> Result<Self> {
        let bytes = 16 * u64::from(views) * u64::from(width) * u64::from(height);
        let image = |name| ctx.create_buffer(name, bytes.max(16), MemoryKind::Device);
        Ok(Self {
            blur: ImageBlur::new(ctx, views, width, height)?,
            mse: ImageMse::new(ctx, views, width, height)?,
            render: image("blurred render")?,
            target: image("blurred target")?,
            grad: image("blurred loss gradient")?,
        })
    }

    /// Records the MSE of `G * images` against `G * targets` for a Gaussian of `std` pixels and,
    /// with `d_image`, its gradient with respect to `images` (written, not accumulated). With
    /// `std` 0 it is [`ImageMse::record`] itself.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        images: BufferRange<'_>,
        targets: BufferRange<'_>,
        d_image: Option<BufferRange<'_>>,
        std: f64,
    ) -> Result<()> {
        if std == 0.0 {
            return self
                .mse
                .record(rec, images, targets, d_image.map(GradOut::write));
        }
        self.blur.record(rec, images, self.render.whole(), std)?;
        self.blur.record(rec, targets, self.target.whole(), std)?;
        let grad = d_image.map(|_| GradOut::write(self.grad.whole()));
        self.mse
            .record(rec, self.render.whole(), self.target.whole(), grad)?;
        if let Some(d) = d_image {
            self.blur.record(rec, self.grad.whole(), d, std)?;
        }
        Ok(())
    }

    /// The device buffer holding the loss (one float) after [`BlurredMse::record`].
    pub fn loss_buffer(&self) -> &Buffer {
        self.mse.loss_buffer()
    }

    /// Reads the loss back.
    pub fn read_loss(&self, ctx: &Context) -> Result<f32> {
        self.mse.read_loss(ctx)
    }
}

/// The f64 twins.
pub mod cpu {
    use super::blur_radius;

    /// `G * image` for `views` RGBA images of `width`×`height` (see the [module
    /// docs](super)).
    pub fn blur(image: &[[f64; 4]], width: u32, height: u32, std: f64) -> Vec<[f64; 4]> {
        let r = blur_radius(std) as i64;
        let s = std.max(1e-3);
        let taps: Vec<f64> = (-r..=r)
            .map(|t| (-(t * t) as f64 / (2.0 * s * s)).exp())
            .collect();
        let norm: f64 = taps.iter().sum();
        let (w, h) = (i64::from(width), i64::from(height));
        let pass = |src: &[[f64; 4]], axis: usize| -> Vec<[f64; 4]> {
            (0..src.len() as i64)
                .map(|i| {
                    let (x, y) = (i % w, (i / w) % h);
                    let (here, size, stride) = if axis == 0 { (x, w, 1) } else { (y, h, w) };
                    let mut acc = [0.0; 4];
                    for (t, wt) in (-r..=r).zip(&taps) {
                        if (0..size).contains(&(here + t)) {
                            let p = src[(i + t * stride) as usize];
                            for c in 0..4 {
                                acc[c] += wt * p[c];
                            }
                        }
                    }
                    acc.map(|a| a / norm)
                })
                .collect()
        };
        pass(&pass(image, 0), 1)
    }

    /// The MSE of `G * image` against `G * target`, and its gradient with respect to `image`.
    pub fn blurred_mse(
        image: &[[f64; 4]],
        target: &[[f64; 4]],
        width: u32,
        height: u32,
        std: f64,
    ) -> (f64, Vec<[f64; 4]>) {
        let (gi, gt) = (
            blur(image, width, height, std),
            blur(target, width, height, std),
        );
        let (loss, d) = crate::fit::silhouette::cpu::mse(&gi, &gt);
        (loss, blur(&d, width, height, std))
    }
}

#[cfg(test)]
mod tests {
    use super::cpu::{blur, blurred_mse};
    use crate::fit::test_support::{Lcg, assert_grad_matches_fd};

    fn random(rng: &mut Lcg, n: usize) -> Vec<[f64; 4]> {
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.range(-1.0, 1.0)))
            .collect()
    }

    #[test]
    fn the_blur_is_its_own_adjoint_and_keeps_constants_inside() {
        // ⟨G x, y⟩ = ⟨x, G y⟩ with zero outside the image (what the gradient relies on).
        let mut rng = Lcg(4);
        let (w, h) = (9, 6);
        let (x, y) = (random(&mut rng, 2 * w * h), random(&mut rng, 2 * w * h));
        let dot = |a: &[[f64; 4]], b: &[[f64; 4]]| -> f64 {
            a.iter()
                .zip(b)
                .map(|(p, q)| (0..4).map(|c| p[c] * q[c]).sum::<f64>())
                .sum()
        };
        for std in [0.0, 0.8, 2.5] {
            let (gx, gy) = (
                blur(&x, w as u32, h as u32, std),
                blur(&y, w as u32, h as u32, std),
            );
            assert!((dot(&gx, &y) - dot(&x, &gy)).abs() < 1e-12, "std {std}");
        }
        // A constant image stays constant where the taps stay inside (the weights sum to 1).
        let ones = vec![[1.0; 4]; 40 * 40];
        let g = blur(&ones, 40, 40, 2.0);
        assert!((g[20 * 40 + 20][0] - 1.0).abs() < 1e-12);
        assert!(g[0][0] < 0.75, "the corner loses the taps outside");
    }

    #[test]
    fn the_blurred_mse_gradient_matches_central_differences() {
        let mut rng = Lcg(6);
        let (w, h) = (7, 5);
        let (image, target) = (random(&mut rng, w * h), random(&mut rng, w * h));
        let (_, grad) = blurred_mse(&image, &target, w as u32, h as u32, 1.3);
        let flat: Vec<f64> = image.iter().flatten().copied().collect();
        let analytic: Vec<f64> = grad.iter().flatten().copied().collect();
        assert_grad_matches_fd(&flat, &analytic, 1e-7, |x| {
            let img: Vec<[f64; 4]> = x.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            blurred_mse(&img, &target, w as u32, h as u32, 1.3).0
        });
    }
}
