//! Fitting on the GPU: the losses, regularizers, parameterization and optimizer of SoftRas's
//! mesh deformation (`demo_deform.py`) as compute kernels, each with an f64 CPU twin whose
//! gradient is checked by central finite differences, so that a whole fitting iteration can be
//! recorded into one command buffer with no host round trip:
//!
//! ```text
//! params ─[Deform::record_forward]→ positions ─(render)→ RGBA images
//!   images ─[SilhouetteLoss / ImageMse]→ loss, d_image ─(render backward)→ d_positions
//!   positions ─[Regularizers::record_laplacian / record_flatten]→ += λ d_positions
//!   d_positions ─[Deform::record_backward]→ d_params ─[Adam::record_step]→ params
//! ```
//!
//! [`mesh_fit`] wires the renderer into that chain for silhouettes (unlit: the lighting's share
//! of the position gradient, which the renderer's backward adds on the host, is zero there), and
//! runs whole iterations on the GPU with no host round trip ([`crate::gpu::gate`]).
//!
//! - [`driver`] and [`session`]: the loop every fit runs on ([`driver::Fitter`]: iterations
//!   per submission behind the binning's gate) and the session around it (log, hooks,
//!   checkpoints in the one format of [`checkpoint`], resume, stopping rule). A fit is its
//!   [`driver::Fit`] and its [`session::Trainee`]; see [`session`] for what a new one needs.
//! - [`silhouette`]: SoftRas's `neg_iou_loss` on the alpha channel ([`SilhouetteLoss`]) and the
//!   image MSE ([`ImageMse`]), with their dL/d(image) in the renderer's `d_image` layout.
//! - [`laplacian`] and [`flatten`]: SoftRas's `LaplacianLoss` and `FlattenLoss`, driven on the
//!   GPU by [`Regularizers`].
//! - [`deform`]: SoftRas's sigmoid/tanh parameterization of vertex positions ([`Deform`]).
//! - [`adam`]: Adam with PyTorch's semantics ([`Adam`]).
//! - [`blur`]: a Gaussian blur of RGBA images and the MSE of blurred images ([`blur::BlurredMse`]).
//! - [`pose`], [`rig`] and [`articulated`]: rigid pose, and the joint angles of a skinned
//!   articulated mesh (forward kinematics, linear blend skinning and the chain to the angles on
//!   the GPU), each fitted to one image.
//! - [`crate::gpu::gate`]: the check that lets whole fitting iterations run on the GPU without the host
//!   reading the binning's entry count ([`mesh_fit`] uses it).
//! - [`crate::io`]: the fitting commands' files (CPU): target silhouettes, the cameras CSV, the fitted
//!   OBJ, all checked on load and written atomically.
//! - The field fit runs on the same driver and session; it is softvk-field's (`field_fit`), as
//!   it needs the fields and sphere probing.
//! - [`report`]: what a fit shows a person (CPU): a contact sheet of predicted against target
//!   silhouettes, a loss plot, an animated GIF of the progress, PNG writing.
//!
//! **Conventions shared by every kernel here.**
//! - Buffers hold `f32`. Vertex positions and their gradients are packed triples, `3 * vertex`
//!   floats (the renderer's positions buffer). Images are RGBA, view-major, row-major (the
//!   renderer's output and its backward's `d_image`); silhouettes are one float per pixel in the
//!   same order.
//! - Gradients are written through a [`GradOut`]: `out = weight · g`, or, accumulating,
//!   `out += weight · g`. Every output element has exactly one writer, so several terms can be
//!   accumulated into one buffer, one pass after another, deterministically.
//! - **Deterministic**: no float atomics; every reduction has a fixed order (sequential sums per
//!   invocation over a fixed stride, then a fixed shared-memory tree: `fit_reduce.glsl`).
//!   Repeated runs on one device are bit-identical.
//! - Loss values land in small device buffers the structs own, read back only when asked
//!   (`read_*`).
//! - A range that holds fewer values than the problem needs is [`Error::Input`](crate::error::Error::Input); a problem too
//!   large for one storage-buffer binding is [`Error::Limit`](crate::error::Error::Limit). Larger ranges are fine (only the
//!   leading values are used), so whole, alignment-rounded buffers can be passed.

pub mod adam;
pub mod articulated;
pub mod blur;
pub mod checkpoint;
pub mod deform;
pub mod driver;
pub mod flatten;
pub mod laplacian;
pub mod log;
pub mod mesh_fit;
pub mod pose;
mod posed;
mod regularizers;
#[cfg(feature = "plots")]
pub mod report;
pub mod rig;
pub mod session;
pub mod silhouette;

pub use crate::gpu::GradOut;
pub use adam::{Adam, AdamOptions};
pub use deform::Deform;
pub use driver::{max_entry_capacity, reserve_guarded, with_headroom};
pub use posed::PosedFit;
pub use regularizers::{RegularizerLosses, Regularizers};
pub use silhouette::{ImageMse, SilhouetteLoss};

/// Test data and the finite-difference check shared by the twins' tests (softvk-testing).
#[cfg(test)]
pub(crate) use softvk_testing as test_support;
