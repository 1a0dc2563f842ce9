//! softvk-raster: meshes, cameras, lighting and the rasterizers of softvk, on softvk-gpu.
//!
//! An engine that renders (and differentiates) meshes needs this crate alone: it builds no
//! fitting, field, reconstruction, npz or zip code. The modules, bottom up:
//!
//! - [`mesh`]: OBJ and MTL, per-face textures, generated shapes (its errors are softvk-gpu's
//!   `error::mesh`, re-exported).
//! - [`camera`] (look-at, projection, pixel centres) → [`lighting`] → [`raster`]: the settings;
//!   the f64 CPU twins of the forward ([`raster::reference`], the oracle of the GPU kernels) and
//!   of the backward ([`raster::reference_grad`], checked by finite differences); the GPU face
//!   setup, the tiled and brute-force fine passes and the backward, driven by
//!   [`raster::gpu::Renderer`], with what a forward leaves for its backward as types
//!   ([`raster::binned`]: an exact run, guarded bins), the f32 bit twins of the fine pass and the
//!   backward ([`raster::bits`]); PyTorch3D's rasterizer ([`raster::fragments`]: the K nearest
//!   faces of every pixel, forward and backward, with its f64 twin); and nvdiffrast's hard
//!   rasterizer, interpolation, textures and antialiasing ([`raster::hard`]).
//!
//! The kernels are `kernels/raster/raster/` of the repository, listed in [`raster::specs`].

#![warn(missing_docs)]

// softvk-gpu's modules, by the paths the code of this crate names them with (`crate::gpu::…`).
use softvk_gpu::{error, fmath, gpu, primitives};

pub mod camera;
pub mod lighting;
pub mod mesh;
pub mod raster;
