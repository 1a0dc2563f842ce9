//! Single-view mesh reconstruction learned from silhouettes (SoftRas §4.2, "3D unsupervised
//! learning"): an encoder–decoder that predicts a deformed sphere from one image, trained with
//! nothing but multi-view silhouettes through the soft rasterizer.
//!
//! - [`npz`]: NumPy `.npy` / `.npz` arrays, read and written.
//! - [`shapes`]: procedural ShapeNet-like objects (chairs, tables, airplanes, …) built from
//!   closed parts with per-part colours, in the unit cube.
//! - [`dataset`]: the NMR/SoftRas dataset layout (`<class>_<split>_images.npz`,
//!   `<class>_<split>_voxels.npz`, 24 views per object), written from [`shapes`] and read back.
//! - [`batch`]: a training batch gathered on the GPU from the images and a schedule.
//! - [`decode`]: the decoder's heads: SoftRas's sphere deformation (per view copies) and the
//!   per-vertex colours from [`colors`], the colour generator (sampled from the input image).
//! - [`train`]: the network, SoftRas's losses and the training loop on the GPU.
//! - [`field`]: the same encoder conditioning a shared occupancy MLP instead,
//!   trained by sphere probing against each object's silhouettes, and reconstruction with it.
//! - [`session`]: both trainers in a fit session (their log row, their checkpointed state,
//!   what a resumed run must match).
//! - [`model`]: the model file (mesh or field) and reconstruction with it.
//! - [`reconstruct`]: reconstruction with a model of either kind, the validation score, and
//!   what training, evaluation and `softvk recon` share.
//! - [`eval`]: 3D IoU against the voxels, and the retrieval and mean-shape baselines.

pub mod batch;
pub mod colors;
pub mod dataset;
pub mod decode;
pub mod eval;
pub mod field;
pub mod model;
pub mod npz;
pub mod reconstruct;
pub mod session;
pub mod shapes;
pub mod train;

pub use dataset::{
    ClassData, Dataset, DatasetOptions, IMAGE_SIZE, Split, VIEWS, VOXEL_RES, view_camera,
    voxel_center, write_dataset,
};
pub use decode::{MeshDecoder, view_rotation};
pub use model::{ReconModel, Reconstructor};
pub use npz::{NpyArray, NpyData, Npz};
pub use shapes::{Category, Shape, generate};
pub use train::{NetShape, ReconTrainer, TrainOptions};
