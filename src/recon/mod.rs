//! Single-view mesh reconstruction learned from silhouettes (SoftRas §4.2, "3D unsupervised
//! learning"): the NMR/SoftRas dataset format and a procedural dataset in it, and (to come) the
//! encoder–decoder trained through the soft rasterizer.
//!
//! - [`npz`]: NumPy `.npy` / `.npz` arrays, read and written.
//! - [`shapes`]: procedural ShapeNet-like objects (chairs, tables, airplanes, …) built from
//!   closed parts with per-part colours, in the unit cube.
//! - [`dataset`]: the NMR/SoftRas dataset layout (`<class>_<split>_images.npz`,
//!   `<class>_<split>_voxels.npz`, 24 views per object), written from [`shapes`] and read back.

pub mod dataset;
pub mod npz;
pub mod shapes;

pub use dataset::{
    ClassData, Dataset, DatasetOptions, IMAGE_SIZE, Split, VIEWS, VOXEL_RES, view_camera,
    voxel_center, write_dataset,
};
pub use npz::{NpyArray, NpyData, Npz};
pub use shapes::{Category, Shape, generate};
