//! softvk: differentiable rendering as Vulkan compute kernels.
//!
//! - [`gpu`]: the Vulkan compute core — a [`gpu::Context`] (owned headless, or adopted from a host
//!   engine with [`gpu::Context::from_raw`]), buffers, kernels compiled at build time, and a
//!   [`gpu::Recorder`] that records dispatches into a command buffer the caller owns.
//! - [`primitives`]: exclusive scan and stable radix sort, the building blocks of binning.
//! - The soft rasterizer's stages: [`mesh`] (OBJ, per-face textures) → [`camera`] (look-at,
//!   projection, pixel centres) → [`lighting`] → [`raster`]: the f64 CPU twin
//!   ([`raster::reference`], the oracle the GPU kernels are tested against), the GPU face setup
//!   ([`raster::setup`]) and the brute-force fine pass ([`raster::brute`]), driven by
//!   [`raster::gpu::Renderer`].
//!
//! - [`mod@bench`]: the forward benchmark behind `softvk bench` (scenes, timing, JSON records).
//!
//! Every kernel has a CPU twin that tests compare it with.

#![warn(missing_docs)]

pub mod assets;
pub mod bench;
pub mod camera;
pub mod error;
pub mod gpu;
pub mod lighting;
pub mod mesh;
pub mod primitives;
pub mod raster;

pub use error::{Error, Result};
