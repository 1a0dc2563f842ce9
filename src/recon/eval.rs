//! Scoring reconstructions as SoftRas's table does (3D IoU of 32³ voxel grids on the test
//! split, every view of every object as an input), and the two baselines computed beside it:
//!
//! - **retrieval**: the training object whose silhouette, seen from the input's view, best
//!   matches the input's silhouette (2D IoU of the alpha masks at 0.5), its voxels as the
//!   answer. It searches every training object of every class: it knows no more than the
//!   network (one image).
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
    /// The network's reconstructions.
    pub reconstruction: f64,
    /// The retrieval baseline.
    pub retrieval: f64,
    /// The class's mean shape.
    pub mean_shape: f64,
}

/// The table as text: one row per class, then the mean over classes.
pub fn format_table(rows: &[ScoreRow]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<22} {:>7} {:>14} {:>10} {:>11}",
        "class", "inputs", "reconstruction", "retrieval", "mean shape"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<22} {:>7} {:>14.4} {:>10.4} {:>11.4}",
            r.class, r.inputs, r.reconstruction, r.retrieval, r.mean_shape
        );
    }
    if !rows.is_empty() {
        let n = rows.len() as f64;
        let mean = |f: fn(&ScoreRow) -> f64| rows.iter().map(f).sum::<f64>() / n;
        let _ = writeln!(
            s,
            "{:<22} {:>7} {:>14.4} {:>10.4} {:>11.4}",
            "mean",
            rows.iter().map(|r| r.inputs).sum::<usize>(),
            mean(|r| r.reconstruction),
            mean(|r| r.retrieval),
            mean(|r| r.mean_shape)
        );
    }
    s
}

/// The 3D IoU of the reconstruction from each input `(object, view)` of `class` against the
/// object's voxels: batches of the reconstructor's capacity, each predicted mesh voxelized at
/// 32³ on the dataset's lattice ([`super::dataset::voxel_cube`],
/// [`super::dataset::occupancy_to_nmr`]).
pub fn reconstruction_ious(
    ctx: &crate::gpu::Context,
    recon: &super::model::Reconstructor,
    class: &super::dataset::ClassData,
    inputs: &[(usize, usize)],
) -> Result<Vec<f64>> {
    use super::dataset::{VOXEL_RES, occupancy_to_nmr, voxel_cube};
    let faces = super::train::template().faces;
    let mut ious = Vec::with_capacity(inputs.len());
    for chunk in inputs.chunks(recon.capacity() as usize) {
        let images: Vec<u8> = chunk
            .iter()
            .flat_map(|&(n, v)| class.image(n, v).iter().copied())
            .collect();
        let meshes = recon.reconstruct(ctx, &images)?;
        for (mesh, &(n, _)) in meshes.iter().zip(chunk) {
            let vox = crate::field::voxel::voxelize_mesh(
                &mesh.positions,
                &faces,
                &voxel_cube(),
                VOXEL_RES as u32,
            )?;
            ious.push(voxel_iou(
                &occupancy_to_nmr(&vox.occupancy)?,
                class.voxels_of(n),
            )?);
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
