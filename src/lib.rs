//! softvk: differentiable rendering as Vulkan compute kernels.
//!
//! - [`gpu`]: the Vulkan compute core — a [`gpu::Context`] (owned headless, or adopted from a host
//!   engine with [`gpu::Context::from_raw`]), buffers, kernels compiled at build time, and a
//!   [`gpu::Recorder`] that records dispatches into a command buffer the caller owns.
//! - [`primitives`]: exclusive scan and stable radix sort, the building blocks of binning.
//! - The soft rasterizer's stages: [`mesh`] (OBJ, per-face textures) → [`camera`] (look-at,
//!   projection, pixel centres) → [`lighting`] → [`raster`]: the f64 CPU twins of the forward
//!   ([`raster::reference`], the oracle the GPU kernels are tested against) and of the backward
//!   ([`raster::reference_grad`], analytic gradients checked by finite differences), the GPU
//!   face setup ([`raster::setup`]) and the brute-force fine pass ([`raster::brute`]), driven by
//!   [`raster::gpu::Renderer`].
//! - [`fit`]: the fitting building blocks as kernels — SoftRas's silhouette (neg-IoU) loss and an
//!   image MSE, its Laplacian and flatten regularizers, its sigmoid/tanh deformation, and Adam —
//!   recordable into one command buffer per iteration.
//!
//! - [`probe`]: implicit-field sphere probing — sampling (rays, anchors, surface candidates),
//!   probing anchors binned to screen tiles, the silhouette loss and the geometric regularizer,
//!   with their gradients with respect to φ.
//! - [`field`]: implicit fields φ = sigmoid(f) in a bounding cube (dense grid, MLP with positional
//!   encoding, analytic shapes) with a deterministic GPU backward, marching cubes, occupancy / visual
//!   hull / IoU tools and a ray-marched preview: the field side of implicit-field sphere probing.
//!
//! - [`nn`]: neural-network layers (Conv2d, Linear, fused activations) as kernels with a
//!   deterministic backward and f64 twins, chained by [`nn::Sequential`]: what the
//!   reconstruction network is built from.
//! - [`recon`]: single-view mesh reconstruction learned from silhouettes (SoftRas's
//!   unsupervised 3D learning): the NMR dataset format and a procedural dataset in it, the
//!   encoder–decoder trained on the GPU through the soft rasterizer, evaluation by 3D IoU
//!   beside retrieval and mean-shape baselines.
//!
//! - [`mod@bench`]: the forward benchmark behind `softvk bench` (scenes, timing, JSON records).
//!
//! Every kernel has a CPU twin that tests compare it with.

#![warn(missing_docs)]

pub mod assets;
pub mod atomic_file;
#[cfg(feature = "bench")]
pub mod bench;
pub mod camera;
pub mod error;
pub mod exr_io;
pub mod field;
pub mod fit;
pub mod gpu;
pub mod io;
pub mod lighting;
pub mod mesh;
pub mod nn;
pub mod primitives;
pub mod probe;
pub mod raster;
pub mod recon;
mod rng;
mod text;

pub use error::{Error, LimitKind, Result};
