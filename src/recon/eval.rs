//! Scoring reconstructions as SoftRas's table does (3D IoU of 32³ voxel grids on the test
//! split, every view of every object as an input; the prediction voxelized by a [`Voxelizer`]:
//! by voxel centres as the ground truth is, or as SoftRas's evaluation does), the two baselines
//! computed beside it, and the visual hull ([`visual_hull_iou`]), the bound of what silhouettes
//! can decide:
//!
//! - **retrieval**: the training object whose silhouette, seen from the input's view, best
//!   matches the input's silhouette (2D IoU of the alpha masks at 0.5), its voxels as the
//!   answer. It searches every training object of every class: it knows no more than the
//!   network (one image).
//!   Beside it, the same retrieval answering with the retrieved object's visual hull (what its
//!   silhouettes show), which is all a silhouette-trained network could have learned of it.
//! - **mean shape**: the class's mean training occupancy, thresholded at 0.5 (it knows the
//!   class, which the network does not: an upper-ish bar for "no image needed").

use crate::error::{Error, Result};

/// A binary silhouette packed 64 pixels to a word, for fast 2D IoU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Mask(Vec<u64>);

impl Mask {
    /// The pixels of `alpha` (one byte per pixel) at or above 128.
    pub fn from_alpha(alpha: &[u8]) -> Mask {
        Mask(
            alpha
                .chunks(64)
                .map(|c| {
                    c.iter()
                        .enumerate()
                        .fold(0u64, |w, (i, &a)| w | (u64::from(a >= 128) << i))
                })
                .collect(),
        )
    }

    /// `|a ∩ b| / |a ∪ b|`, 1 for two empty masks.
    pub fn iou(&self, other: &Mask) -> f64 {
        let (mut i, mut u) = (0u32, 0u32);
        for (a, b) in self.0.iter().zip(&other.0) {
            i += (a & b).count_ones();
            u += (a | b).count_ones();
        }
        if u == 0 {
            1.0
        } else {
            f64::from(i) / f64::from(u)
        }
    }
}

/// `|a ∩ b| / |a ∪ b|` of two occupancy grids of equal size (1 for two empty grids, as
/// SoftRas's formula gives 0/0 there; [`Error::Input`] for different sizes).
pub fn voxel_iou(a: &[bool], b: &[bool]) -> Result<f64> {
    if a.len() != b.len() {
        return Err(Error::Input(format!(
            "voxel grids of {} and {} cells",
            a.len(),
            b.len()
        )));
    }
    let (mut i, mut u) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        i += usize::from(x && y);
        u += usize::from(x || y);
    }
    Ok(if u == 0 { 1.0 } else { i as f64 / u as f64 })
}

/// Each cell occupied in at least half of `grids` (all of one size; [`Error::Input`] for none
/// or different sizes).
pub fn mean_shape(grids: &[&[bool]]) -> Result<Vec<bool>> {
    let Some(first) = grids.first() else {
        return Err(Error::Input("the mean shape of no objects".into()));
    };
    if grids.iter().any(|g| g.len() != first.len()) {
        return Err(Error::Input("voxel grids of different sizes".into()));
    }
    let mut counts = vec![0usize; first.len()];
    for g in grids {
        for (c, &x) in counts.iter_mut().zip(g.iter()) {
            *c += usize::from(x);
        }
    }
    Ok(counts.iter().map(|&c| 2 * c >= grids.len()).collect())
}

/// The index of the mask in `candidates` with the largest IoU against `query` (the first of
/// equals); `None` for no candidates.
pub fn retrieve(query: &Mask, candidates: &[Mask]) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, c) in candidates.iter().enumerate() {
        let iou = query.iou(c);
        if best.is_none_or(|(_, b)| iou > b) {
            best = Some((i, iou));
        }
    }
    best.map(|b| b.0)
}

/// One row of the table: a class and its mean 3D IoUs.
#[derive(Clone, Debug, PartialEq)]
pub struct ScoreRow {
    /// The class.
    pub class: String,
    /// Test inputs scored (objects × views).
    pub inputs: usize,
    /// Each model's reconstructions (the table's columns after `inputs`).
    pub reconstructions: Vec<f64>,
    /// The retrieval baseline.
    pub retrieval: f64,
    /// Retrieval answering with the retrieved object's visual hull instead of its voxels: what
    /// retrieval could know from silhouettes alone, as the network does.
    pub retrieval_hull: f64,
    /// The class's mean shape.
    pub mean_shape: f64,
    /// The visual hull of each test object's own 24 silhouettes ([`visual_hull_iou`]): what
    /// silhouettes at the dataset's views can pin down at best, not a method.
    pub visual_hull: f64,
}

/// The table as text: a column per model (`models` names them, in the order of
/// [`ScoreRow::reconstructions`]), then the baselines; one row per class, then the mean over
/// classes.
pub fn format_table(models: &[String], rows: &[ScoreRow]) -> String {
    use std::fmt::Write;
    let widths: Vec<usize> = models.iter().map(|m| m.chars().count().max(14)).collect();
    let mut s = String::new();
    let _ = write!(s, "{:<22} {:>7}", "class", "inputs");
    for (m, w) in models.iter().zip(&widths) {
        let _ = write!(s, " {m:>w$}");
    }
    let _ = writeln!(
        s,
        " {:>10} {:>15} {:>11} {:>12}",
        "retrieval", "retrieval hull", "mean shape", "visual hull"
    );
    let line = |s: &mut String, class: &str, inputs: usize, recon: &[f64], rest: [f64; 4]| {
        let _ = write!(s, "{class:<22} {inputs:>7}");
        for (r, w) in recon.iter().zip(&widths) {
            let _ = write!(s, " {r:>w$.4}");
        }
        let _ = writeln!(
            s,
            " {:>10.4} {:>15.4} {:>11.4} {:>12.4}",
            rest[0], rest[1], rest[2], rest[3]
        );
    };
    for r in rows {
        line(
            &mut s,
            &r.class,
            r.inputs,
            &r.reconstructions,
            [r.retrieval, r.retrieval_hull, r.mean_shape, r.visual_hull],
        );
    }
    if !rows.is_empty() {
        let n = rows.len() as f64;
        let mean = |f: &dyn Fn(&ScoreRow) -> f64| rows.iter().map(f).sum::<f64>() / n;
        let recon: Vec<f64> = (0..models.len())
            .map(|k| mean(&|r: &ScoreRow| r.reconstructions.get(k).copied().unwrap_or(f64::NAN)))
            .collect();
        line(
            &mut s,
            "mean",
            rows.iter().map(|r| r.inputs).sum::<usize>(),
            &recon,
            [
                mean(&|r| r.retrieval),
                mean(&|r| r.retrieval_hull),
                mean(&|r| r.mean_shape),
                mean(&|r| r.visual_hull),
            ],
        );
    }
    s
}

/// Object `n`'s visual hull in NMR order: the 32³ voxels whose centres fall inside its
/// silhouette (alpha ≥ 128) in all [`super::dataset::VIEWS`] views, as their cameras
/// ([`super::dataset::view_camera`]) project them.
pub fn visual_hull_voxels(class: &super::dataset::ClassData, n: usize) -> Result<Vec<bool>> {
    use super::dataset::{IMAGE_SIZE, VIEWS, VOXEL_RES, occupancy_to_nmr, view_camera, voxel_cube};
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
pub fn visual_hull_iou(class: &super::dataset::ClassData, n: usize) -> Result<f64> {
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
    /// the convention of the dataset's ground truth ([`super::dataset::voxelize_shapes`]), so a
    /// perfect mesh scores 1. A fold that overlaps the surface empties the region it doubles.
    #[default]
    Parity,
}

impl Voxelizer {
    /// `positions`/`faces` voxelized at 32³ on the dataset's lattice, in NMR order
    /// ([`super::dataset::voxel_cube`], [`super::dataset::occupancy_to_nmr`]).
    pub fn voxelize(&self, positions: &[[f32; 3]], faces: &[[u32; 3]]) -> Result<Vec<bool>> {
        use super::dataset::{VOXEL_RES, occupancy_to_nmr, voxel_cube};
        use crate::field::voxel;
        let occ = match self {
            Voxelizer::SoftRas => voxel::voxelize_mesh_conservative(
                positions,
                faces,
                &voxel_cube(),
                VOXEL_RES as u32,
            )?,
            Voxelizer::Parity => {
                voxel::voxelize_mesh(positions, faces, &voxel_cube(), VOXEL_RES as u32)?.occupancy
            }
        };
        occupancy_to_nmr(&occ)
    }
}

/// The 3D IoU of the reconstruction from each input `(object, view)` of `class` against the
/// object's voxels: batches of the reconstructor's capacity, each predicted mesh voxelized by
/// `voxelizer`.
pub fn reconstruction_ious(
    ctx: &crate::gpu::Context,
    recon: &super::model::Reconstructor,
    class: &super::dataset::ClassData,
    inputs: &[(usize, usize)],
    voxelizer: Voxelizer,
) -> Result<Vec<f64>> {
    let faces = super::train::template().faces;
    let mut ious = Vec::with_capacity(inputs.len());
    for chunk in inputs.chunks(recon.capacity() as usize) {
        let images = input_images(class, chunk);
        let meshes = recon.reconstruct(ctx, &images)?;
        for (mesh, &(n, _)) in meshes.iter().zip(chunk) {
            ious.push(voxel_iou(
                &voxelizer.voxelize(&mesh.positions, &faces)?,
                class.voxels_of(n),
            )?);
        }
    }
    Ok(ious)
}

/// The images of `(object, view)` inputs of `class`, one after another.
fn input_images(class: &super::dataset::ClassData, inputs: &[(usize, usize)]) -> Vec<u8> {
    inputs
        .iter()
        .flat_map(|&(n, v)| class.image(n, v).iter().copied())
        .collect()
}

/// As [`reconstruction_ious`] for a conditioned field: each input's field occupied at the voxel
/// centres ([`super::field::FieldReconstructor::occupancy`]) against the object's voxels.
pub fn field_reconstruction_ious(
    ctx: &crate::gpu::Context,
    recon: &super::field::FieldReconstructor,
    class: &super::dataset::ClassData,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_iou_counts_pixels_at_half_alpha_and_above() {
        let a = Mask::from_alpha(&[0, 127, 128, 255, 200, 0, 0]);
        let b = Mask::from_alpha(&[255, 255, 128, 0, 200, 0, 0]);
        // a = {2, 3, 4}, b = {0, 1, 2, 4}: ∩ = {2, 4}, ∪ = {0, 1, 2, 3, 4}.
        assert_eq!(a.iou(&b), 2.0 / 5.0);
        assert_eq!(
            Mask::from_alpha(&[0; 70]).iou(&Mask::from_alpha(&[0; 70])),
            1.0
        );
    }

    #[test]
    fn retrieval_picks_the_best_match_and_the_first_of_equals() {
        let q = Mask::from_alpha(&[255, 255, 0, 0]);
        let c = [
            Mask::from_alpha(&[0, 0, 255, 255]),
            Mask::from_alpha(&[255, 0, 0, 0]),
            Mask::from_alpha(&[0, 255, 0, 0]),
        ];
        assert_eq!(retrieve(&q, &c), Some(1));
        assert_eq!(retrieve(&q, &[]), None);
    }

    #[test]
    fn mean_shape_keeps_cells_of_at_least_half_the_objects() {
        let (a, b, c) = (
            [true, true, false, false],
            [true, false, true, false],
            [true, false, false, false],
        );
        assert_eq!(
            mean_shape(&[&a, &b, &c]).unwrap(),
            vec![true, false, false, false]
        );
        assert_eq!(
            mean_shape(&[&a, &b]).unwrap(),
            vec![true, true, true, false]
        );
        assert!(matches!(mean_shape(&[]), Err(Error::Input(_))));
        assert_eq!(voxel_iou(&a, &b).unwrap(), 1.0 / 3.0);
        assert!(matches!(voxel_iou(&a, &[true]), Err(Error::Input(_))));
    }
}
