//! SoftRas's soft rasterizer (`softvk.torch`, `softvk.soft_renderer`):
//!
//! - [`settings`]: `Settings`, SoftRas's rasterizer arguments, parsed.
//! - [`raster`]: `Raster`, a render's scene kept on the device for its backward, and the render
//!   both entry points run.
//! - [`faces`]: `rasterize`, SoftRas's `soft_rasterize` on faces already in screen space, and
//!   its f64 CPU twin `reference_rasterize` / `reference_rasterize_grad`.
//! - [`mesh`]: `render_mesh`, with the camera, the lighting and the face set-up on the device.

pub(crate) mod faces;
pub(crate) mod mesh;
pub(crate) mod raster;
pub(crate) mod settings;
