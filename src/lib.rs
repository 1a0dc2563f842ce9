//! softvk: differentiable rendering as Vulkan compute kernels.
//!
//! This crate is the top of softvk's workspace: the command line and `softvk bench`, and
//! single-view reconstruction (networks, datasets, trainers) on the fits below it. It re-exports the crates below it, so one
//! dependency gives everything under the paths the project itself uses:
//!
//! - softvk-gpu: [`error`] (the one error enum), [`atomic_file`], [`gpu`] (the Vulkan compute
//!   core: contexts owned or adopted with [`gpu::Context::from_raw`], buffers, kernels,
//!   recording into a caller's command buffer), [`fmath`] (correctly rounded maths, the same
//!   bits on every device) and [`primitives`] (scan, sort, sums, tiled binning);
//! - softvk-raster: [`mesh`], [`camera`], [`lighting`] and [`raster`] (the soft rasterizer,
//!   PyTorch3D's fragments, the hard rasterizer, with their twins);
//! - softvk-fit: [`io`] (silhouettes, cameras CSV, OBJ out), [`rng`] and [`fit`] (the losses,
//!   regularizers, deformation and Adam as kernels, the driver and session every fit runs on,
//!   the mesh, rigid-pose and articulated fits, their checkpoints and reports);
//! - softvk-field: [`field`] (implicit fields, marching cubes, voxel tools, preview) and
//!   [`probe`] (sphere probing), and the field fit, which [`fit`] holds here as
//!   [`fit::field_fit`] beside the other fits.
//!
//! An engine that only renders depends on softvk-raster alone. The modules of this crate, bottom
//! up (none imports from one below it in this list):
//!
//! - [`assets`] (the meshes found through `SOFTVK_ASSETS` or the checkout), [`exr_io`].
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

pub use softvk_field::{field, probe};
pub use softvk_fit::{io, rng};
pub use softvk_gpu::{Error, LimitKind, Result, atomic_file, error, fmath, gpu, primitives};
pub use softvk_raster::{camera, lighting, mesh, raster};

/// Fitting: softvk-fit's [`fit`](softvk_fit::fit) (losses, regularizers, Adam, the driver and
/// session, the mesh and pose fits), with softvk-field's field fit beside them as
/// [`field_fit`](softvk_field::field_fit).
pub mod fit {
    pub use softvk_field::field_fit;
    pub use softvk_fit::fit::*;
}

pub mod assets;
#[cfg(feature = "bench")]
pub mod bench;
pub mod exr_io;
pub mod nn;
pub mod recon;

/// This crate's kernels (`kernels/softvk/`: networks and reconstruction), as `softvk-build`
/// compiled them. The crates below list theirs in [`gpu::specs`], [`raster::specs`],
/// [`softvk_fit::specs`] and [`softvk_field::specs`].
#[allow(missing_docs)]
pub mod specs {
    use softvk_gpu::gpu::{BindingKind, BindingSpec, BufferRange, KernelSpec};
    include!(concat!(env!("OUT_DIR"), "/kernels.rs"));
}
