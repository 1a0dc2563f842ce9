//! The voxel grids scored: visual hulls of the test objects, predicted meshes voxelized by a
//! [`Voxelizer`], fields' occupancies, and another program's predictions read from files.

use super::voxel_iou;
use crate::error::{Error, Result};

/// Object `n`'s visual hull in NMR order: the 32³ voxels whose centres fall inside its
/// silhouette (alpha ≥ 128) in all [`crate::recon::dataset::VIEWS`] views, as their cameras
/// ([`crate::recon::dataset::view_camera`]) project them.
pub fn visual_hull_voxels(class: &crate::recon::dataset::ClassData, n: usize) -> Result<Vec<bool>> {
    use crate::recon::dataset::{
        IMAGE_SIZE, VIEWS, VOXEL_RES, occupancy_to_nmr, view_camera, voxel_cube,
    };
    let px = IMAGE_SIZE * IMAGE_SIZE;
    let masks = (0..VIEWS)
        .flat_map(|v| class.image(n, v)[3 * px..].iter())
        .map(|&a| if a >= 128 { 1.0 } else { 0.0 })
        .collect();
    let silhouettes = crate::io::Silhouettes {
        width: IMAGE_SIZE as u32,
        height: IMAGE_SIZE as u32,
        names: (0..VIEWS).map(|v| format!("view {v}")).collect(),
        masks,
    };
    let cameras: Vec<_> = (0..VIEWS).map(view_camera).collect();
    let hull =
        crate::field::voxel::visual_hull(&silhouettes, &cameras, &voxel_cube(), VOXEL_RES as u32)?;
    occupancy_to_nmr(&hull)
}

/// The 3D IoU of object `n`'s visual hull ([`visual_hull_voxels`]) against its voxels.
///
/// Training sees only these silhouettes, so what they cannot carve (the space under a table's
/// top or a car's body, which every view at 30° elevation looks down on) is out of its reach:
/// the hull is about the best a silhouette-supervised reconstruction can expect, where
/// retrieval returns a training object's true voxels, hollows included.
pub fn visual_hull_iou(class: &crate::recon::dataset::ClassData, n: usize) -> Result<f64> {
    voxel_iou(&visual_hull_voxels(class, n)?, class.voxels_of(n))
}

/// How a predicted mesh becomes 32³ voxels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Voxelizer {
    /// SoftRas's evaluation (`srf.voxelization`): the voxels the surface passes through and
    /// everything they enclose ([`crate::field::voxel::voxelize_mesh_conservative`]). Robust to
    /// the self-overlapping folds a deformed sphere makes; the protocol of SoftRas's table,
    /// whose ground truth (ShapeNet's binvox grids) marks surface voxels too. Against this
    /// dataset's ground truth (voxel centres inside) it counts every surface voxel the truth
    /// does not: a perfect mesh scores below 1.
    SoftRas,
    /// The voxels whose centres are inside by parity ([`crate::field::voxel::voxelize_mesh`]):
    /// the convention of the dataset's ground truth ([`crate::recon::dataset::voxelize_shapes`]), so a
    /// perfect mesh scores 1. A fold that overlaps the surface empties the region it doubles.
    #[default]
    Parity,
    /// The voxels whose centres have a winding number of magnitude ≥ 0.5
    /// ([`crate::field::voxel::voxelize_mesh_winding`]): the same as parity for a mesh that
    /// does not overlap itself, but a region a fold encloses twice stays inside, and an
    /// inside-out mesh is inside. It needs a closed, consistently oriented mesh, which the
    /// decoder's deformed sphere always is (its faces are the template's); others are refused.
    Winding,
}

impl Voxelizer {
    /// `positions`/`faces` voxelized at 32³ on the dataset's lattice, in NMR order
    /// ([`crate::recon::dataset::voxel_cube`], [`crate::recon::dataset::occupancy_to_nmr`]).
    pub fn voxelize(&self, positions: &[[f32; 3]], faces: &[[u32; 3]]) -> Result<Vec<bool>> {
        use crate::field::voxel;
        use crate::recon::dataset::{VOXEL_RES, occupancy_to_nmr, voxel_cube};
        let (cube, res) = (voxel_cube(), VOXEL_RES as u32);
        let occ = match self {
            Voxelizer::SoftRas => voxel::voxelize_mesh_conservative(positions, faces, &cube, res)?,
            Voxelizer::Parity => voxel::voxelize_mesh(positions, faces, &cube, res)?.occupancy,
            Voxelizer::Winding => voxel::voxelize_mesh_winding(positions, faces, &cube, res)?,
        };
        occupancy_to_nmr(&occ)
    }

    /// `parity`, `winding` or `softras`, as the table names it.
    pub fn name(&self) -> &'static str {
        match self {
            Voxelizer::SoftRas => "softras",
            Voxelizer::Parity => "parity",
            Voxelizer::Winding => "winding",
        }
    }
}

/// The 3D IoU of the reconstruction from each input `(object, view)` of `class` against the
/// object's voxels, once per voxelizer (`[voxelizer][input]`): batches of the reconstructor's
/// capacity, each predicted mesh reconstructed once and voxelized by each of `voxelizers`.
pub fn reconstruction_ious(
    ctx: &crate::gpu::Context,
    recon: &crate::recon::model::Reconstructor,
    class: &crate::recon::dataset::ClassData,
    inputs: &[(usize, usize)],
    voxelizers: &[Voxelizer],
) -> Result<Vec<Vec<f64>>> {
    let faces = crate::recon::train::template().faces;
    let mut ious = vec![Vec::with_capacity(inputs.len()); voxelizers.len()];
    for chunk in inputs.chunks(recon.capacity() as usize) {
        let images = input_images(class, chunk);
        let meshes = recon.reconstruct(ctx, &images)?;
        for (mesh, &(n, _)) in meshes.iter().zip(chunk) {
            for (out, voxelizer) in ious.iter_mut().zip(voxelizers) {
                out.push(voxel_iou(
                    &voxelizer.voxelize(&mesh.positions, &faces)?,
                    class.voxels_of(n),
                )?);
            }
        }
    }
    Ok(ious)
}

/// The images of `(object, view)` inputs of `class`, one after another.
fn input_images(class: &crate::recon::dataset::ClassData, inputs: &[(usize, usize)]) -> Vec<u8> {
    inputs
        .iter()
        .flat_map(|&(n, v)| class.image(n, v).iter().copied())
        .collect()
}

/// As [`reconstruction_ious`] for a conditioned field: each input's field occupied at the voxel
/// centres ([`crate::recon::field::FieldReconstructor::occupancy`]) against the object's voxels.
pub fn field_reconstruction_ious(
    ctx: &crate::gpu::Context,
    recon: &crate::recon::field::FieldReconstructor,
    class: &crate::recon::dataset::ClassData,
    inputs: &[(usize, usize)],
) -> Result<Vec<f64>> {
    let mut ious = Vec::with_capacity(inputs.len());
    for chunk in inputs.chunks(recon.capacity() as usize) {
        let images = input_images(class, chunk);
        for (occ, &(n, _)) in recon.occupancy(ctx, &images)?.iter().zip(chunk) {
            ious.push(voxel_iou(occ, class.voxels_of(n))?);
        }
    }
    Ok(ious)
}

/// The file of `class_id`'s external predictions in `dir`:
/// `<class>_test_predicted_voxels.npz`.
pub fn predictions_path(dir: &std::path::Path, class_id: &str) -> std::path::PathBuf {
    dir.join(format!("{class_id}_test_predicted_voxels.npz"))
}

/// Another program's reconstructions of `class`'s test split, scored beside softvk's models:
/// `arr_0` of [`predictions_path`], uint8 0/1 of shape (N, 24, 32, 32, 32), the voxels
/// predicted from view v of test object n in the order of the dataset's voxels (as
/// `<class>_test_voxels.npz`). Returned flat, one `bool` per voxel. [`Error::Input`] (naming
/// the file) for a missing file or array, another shape or dtype, or a value other than 0
/// and 1.
pub fn read_predictions(
    dir: &std::path::Path,
    class: &crate::recon::dataset::ClassData,
) -> Result<Vec<bool>> {
    use crate::recon::dataset::{VIEWS, VOXEL_RES};
    use crate::recon::npz::{NpyData, read_npz_array};
    let path = predictions_path(dir, &class.class_id);
    if !path.is_file() {
        return Err(Error::Input(format!(
            "{}: no predictions for class {} (expected `arr_0`, uint8, shape ({}, {VIEWS}, \
             {VOXEL_RES}, {VOXEL_RES}, {VOXEL_RES}))",
            path.display(),
            class.class_id,
            class.count
        )));
    }
    let array = read_npz_array(&path, "arr_0")?;
    let want = [class.count, VIEWS, VOXEL_RES, VOXEL_RES, VOXEL_RES];
    let NpyData::U8(data) = &array.data else {
        return Err(Error::Input(format!(
            "{}: `arr_0` is {}, expected uint8 0/1",
            path.display(),
            array.data.dtype_name()
        )));
    };
    if array.shape != want {
        return Err(Error::Input(format!(
            "{}: `arr_0` has shape {:?}, expected {want:?} (test objects of class {}, views, \
             voxels)",
            path.display(),
            array.shape,
            class.class_id
        )));
    }
    if let Some(bad) = data.iter().find(|&&x| x > 1) {
        return Err(Error::Input(format!(
            "{}: `arr_0` holds {bad}, expected only 0 and 1",
            path.display()
        )));
    }
    Ok(data.iter().map(|&x| x == 1).collect())
}

/// The 3D IoU of each input `(object, view)` of `class` whose prediction `predicted` holds
/// ([`read_predictions`]'s grid of the class) against the object's voxels.
pub fn predicted_ious(
    predicted: &[bool],
    class: &crate::recon::dataset::ClassData,
    inputs: &[(usize, usize)],
) -> Result<Vec<f64>> {
    use crate::recon::dataset::{VIEWS, VOXEL_RES};
    let size = VOXEL_RES.pow(3);
    inputs
        .iter()
        .map(|&(n, v)| {
            let start = (n * VIEWS + v) * size;
            let grid = predicted
                .get(start..start + size)
                .ok_or_else(|| Error::Input(format!("no prediction for object {n}, view {v}")))?;
            voxel_iou(grid, class.voxels_of(n))
        })
        .collect()
}
