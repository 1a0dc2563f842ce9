//! softvk: differentiable rendering as Vulkan compute kernels.
//!
//! The modules, bottom up (none imports from one below it in this list):
//!
//! - [`error`] (the one error enum) and [`atomic_file`] (files written whole or not at all).
//! - [`gpu`]: the Vulkan compute core — a [`gpu::Context`] (owned headless, or adopted from a host
//!   engine with [`gpu::Context::from_raw`]), buffers, kernels compiled at build time, and a
//!   [`gpu::Recorder`] that records dispatches into a command buffer the caller owns.
//! - [`fmath`]: softvk's own `exp`, `log`, division, `sqrt`, `sin`, `cos`, ... built from
//!   correctly rounded operations, which every kernel uses (`kernels/include/fmath.glsl`), so a
//!   kernel's bits are the same on every conformant device; the CPU twin is bit-exact.
//! - [`primitives`]: exclusive scan, stable radix sort, sums and tiled binning (which items each
//!   screen tile must visit, exactly), with their CPU twins.
//! - Inputs: [`mesh`] (OBJ and MTL, per-face textures, generated shapes), [`assets`] (the meshes
//!   built in or found through `SOFTVK_ASSETS`), [`io`] (silhouettes, cameras CSV), [`exr_io`].
//! - The soft rasterizer: [`camera`] (look-at, projection, pixel centres) → [`lighting`] →
//!   [`raster`]: the settings; the f64 CPU twins of the forward ([`raster::reference`], the
//!   oracle of the GPU kernels) and of the backward ([`raster::reference_grad`], checked by
//!   finite differences); the GPU face setup, the tiled and brute-force fine passes and the
//!   backward, driven by [`raster::gpu::Renderer`], with what a forward leaves for its backward
//!   as types ([`raster::binned`]: an exact run, guarded bins), the f32 bit twins of the fine
//!   pass and the backward ([`raster::bits`]); and PyTorch3D's rasterizer
//!   ([`raster::fragments`]: the K nearest faces of every pixel, forward and backward, with its
//!   f64 twin).
//! - [`fit`]: the fitting building blocks as kernels — silhouette losses, Laplacian and flatten
//!   regularizers, deformation, Adam, blur — the loop driver that every fit runs on
//!   ([`fit::driver`]) and the session around it ([`fit::session`]: log, hooks, checkpoints,
//!   resume, stopping rule), the fits (mesh, field, rigid pose, articulated pose), their
//!   checkpoint format and reports.
//! - [`probe`]: implicit-field sphere probing — sampling (rays, anchors, surface candidates),
//!   probing anchors binned to screen tiles, the silhouette loss and the geometric regularizer,
//!   with their gradients with respect to φ.
//! - [`field`]: implicit fields φ = sigmoid(f) in a bounding cube (dense grid, MLP with positional
//!   encoding, analytic shapes) with a deterministic GPU backward, marching cubes, occupancy /
//!   visual hull / IoU tools and a ray-marched preview.
//! - [`nn`]: neural-network layers (Conv2d, Linear, fused activations) as kernels with a
//!   deterministic backward and f64 twins, chained by [`nn::Sequential`].
//! - [`recon`]: single-view reconstruction learned from silhouettes (SoftRas's unsupervised 3D
//!   learning): the NMR dataset format and a procedural dataset in it, the mesh network and the
//!   conditioned implicit field trained on the GPU, evaluation by 3D IoU beside retrieval and
//!   mean-shape baselines.
//! - [`mod@bench`] (feature `bench`): the scene benchmarks behind `softvk bench` — forward and
//!   backward per scene and method, and one iteration of each fit and of reconstruction
//!   training (JSON records).
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
pub mod fmath;
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
