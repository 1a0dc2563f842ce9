//! The render settings (SPEC §2, §6): what SoftRas calls its rasterizer's options, checked
//! once ([`RasterSettings::validate`]) and read alike by the GPU path and the f64 twins, which
//! both sit above this module.

pub use crate::error::RenderError;

/// ε_d of the SPEC by default: the coverage below which a face is ignored (`dist_eps` in
/// SoftRas; [`RasterSettings::dist_eps`] sets it).
pub const DIST_EPS: f64 = 1e-4;

/// Distance function for the coverage `D`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Dist {
    /// `sigmoid(δ d² / σ)`, d the distance to the triangle's edges.
    #[default]
    Euclidean,
    /// `sigmoid(m |m| / σ)`, m the smallest barycentric.
    Barycentric,
    /// 1 inside, ignored outside.
    Hard,
}

/// Colour aggregation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Rgb {
    /// Depth softmax weighted by coverage, with a background term.
    #[default]
    Softmax,
    /// The nearest face whose pixel is inside.
    Hard,
}

/// Alpha aggregation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Alpha {
    /// `1 - Π(1 - D_j)`.
    #[default]
    Prod,
    /// `Σ D_j / F`.
    Sum,
    /// 1 if any `D_j > 0.5`.
    Hard,
}

/// Where face colours come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ColorMode {
    /// Per-face R×R textures, lit with face normals.
    #[default]
    Surface,
    /// Per-vertex colours interpolated with the clipped barycentrics, lit with vertex normals.
    Vertex,
}

/// Everything the forward pass needs besides mesh, camera and lights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RasterSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Sharpness σ of the coverage sigmoid.
    pub sigma: f64,
    /// Temperature γ of the depth softmax.
    pub gamma: f64,
    /// Near plane: faces closer than this at a pixel are dropped from colour.
    pub near: f64,
    /// Far plane: faces farther than this at a pixel are dropped from colour.
    pub far: f64,
    /// Background depth offset ε of the softmax (`eps` in SoftRas, 1e-3).
    pub eps: f64,
    /// ε_d: a face whose coverage of a pixel outside it would be below this is ignored there
    /// (`dist_eps` in SoftRas: 1e-4 by default, 1e-10 in its reconstruction). It sets the
    /// squared-distance cut-off [`RasterSettings::cutoff`], so how far faces reach.
    pub dist_eps: f64,
    /// Distance function.
    pub dist: Dist,
    /// Colour aggregation.
    pub rgb: Rgb,
    /// Alpha aggregation.
    pub alpha: Alpha,
    /// Background colour `C_b`.
    pub background: [f64; 3],
    /// SoftRas `fill_back`: back faces contribute colour too.
    pub double_sided: bool,
    /// Render at 2× and average 2×2.
    pub antialias: bool,
    /// Where colours come from.
    pub color_mode: ColorMode,
}

impl Default for RasterSettings {
    /// SoftRas `SoftRenderer` defaults at 256×256.
    fn default() -> Self {
        RasterSettings {
            width: 256,
            height: 256,
            sigma: 1e-5,
            gamma: 1e-4,
            near: 1.0,
            far: 100.0,
            eps: 1e-3,
            dist_eps: DIST_EPS,
            dist: Dist::Euclidean,
            rgb: Rgb::Softmax,
            alpha: Alpha::Prod,
            background: [0.0; 3],
            double_sided: true,
            antialias: false,
            color_mode: ColorMode::Surface,
        }
    }
}

/// Largest image side accepted (×2 with anti-aliasing stays far below any overflow).
pub const MAX_IMAGE_SIDE: u32 = 16384;

impl RasterSettings {
    /// Checks every setting's domain, so a bad value is an error, never a NaN image.
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::Settings(m));
        if self.width == 0 || self.height == 0 {
            return bad(format!(
                "image size {}x{} is empty",
                self.width, self.height
            ));
        }
        if self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return bad(format!(
                "image size {}x{} exceeds {MAX_IMAGE_SIDE}",
                self.width, self.height
            ));
        }
        if self.dist != Dist::Hard && !(self.sigma.is_finite() && self.sigma > 0.0) {
            return bad(format!("sigma must be finite and > 0, got {}", self.sigma));
        }
        if self.rgb == Rgb::Softmax && !(self.gamma.is_finite() && self.gamma > 0.0) {
            return bad(format!("gamma must be finite and > 0, got {}", self.gamma));
        }
        if !(self.near.is_finite() && self.far.is_finite() && self.near < self.far) {
            return bad(format!(
                "need finite near < far, got near {} far {}",
                self.near, self.far
            ));
        }
        if !self.eps.is_finite() {
            return bad(format!("eps must be finite, got {}", self.eps));
        }
        if !(self.dist_eps > 0.0 && self.dist_eps < 0.5) {
            return bad(format!(
                "dist_eps must be in (0, 0.5), got {}",
                self.dist_eps
            ));
        }
        if !self.background.iter().all(|c| c.is_finite()) {
            return bad(format!("background {:?} is not finite", self.background));
        }
        Ok(())
    }
}

/// Squared-distance cut-off `T = σ ln(1/ε_d − 1)` (≈ 9.21 σ at the default ε_d = 1e-4): beyond
/// it, outside, a face's coverage is below ε_d and the face is ignored.
pub fn cutoff(sigma: f64, dist_eps: f64) -> f64 {
    sigma * (1.0 / dist_eps - 1.0).ln()
}

impl RasterSettings {
    /// These settings' squared-distance [`cutoff`] `T` (from σ and ε_d).
    pub fn cutoff(&self) -> f64 {
        cutoff(self.sigma, self.dist_eps)
    }
}
