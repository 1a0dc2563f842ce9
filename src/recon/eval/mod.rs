//! Scoring reconstructions as SoftRas's table does (3D IoU of 32³ voxel grids on the test
//! split, every view of every object as an input; a predicted mesh voxelized by a
//! [`Voxelizer`]: by voxel centres as the ground truth is, by parity or by winding number, or as
//! SoftRas's evaluation does), another program's voxels read beside them
//! ([`read_predictions`]), the baselines computed beside them, and how sure each difference is
//! ([`compare`]). The baselines, named in the table ([`BASELINES`]) by what they know that a
//! single-view network does not:
//!
//! - **retrieval (knows view)**: the training object whose silhouette from the input's own view
//!   index best matches the input's silhouette (2D IoU of the alpha masks at 0.5), its voxels as
//!   the answer. It searches every training object of every class, but only among silhouettes
//!   seen from exactly the input's camera: it is told the viewpoint, which the network must
//!   infer, and it answers with true voxels, hollows no silhouette shows included.
//!   Beside it, the same retrieval answering with the retrieved object's visual hull (what its
//!   silhouettes show), which is all a silhouette-trained network could have learned of it.
//! - **mean shape (knows class)**: the class's mean training occupancy, thresholded at 0.5 (it
//!   knows the class, which the network does not: an upper-ish bar for "no image needed").
//! - **visual hull** of the test object's own 24 silhouettes ([`visual_hull_iou`]): not a
//!   method, the bound of what silhouettes can decide.
//!
//! A class has few test objects, so its mean moves by several hundredths with the sample alone:
//! each network's difference to each baseline comes with a paired bootstrap interval over test
//! objects ([`paired_bootstrap`]).

mod bootstrap;
mod table;
mod voxels;

#[cfg(test)]
mod tests;

pub use bootstrap::{BOOTSTRAP_SEED, Comparison, Interval, RESAMPLES, compare, paired_bootstrap};
pub use table::{
    BASELINE_LEGEND, BASELINES, format_comparison, format_table, per_object, table_csv,
};
pub use voxels::{
    Voxelizer, field_reconstruction_ious, predicted_ious, predictions_path, read_predictions,
    reconstruction_ious, visual_hull_iou, visual_hull_voxels,
};

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

/// One class of the table: each column's 3D IoU per test object, the mean over the views
/// evaluated (the unit the bootstrap resamples).
#[derive(Clone, Debug, PartialEq)]
pub struct ScoreRow {
    /// The class.
    pub class: String,
    /// Test inputs scored (objects × views).
    pub inputs: usize,
    /// Each network column's (a model under one voxelization, or external predictions) per
    /// object, in the order of the table's network columns.
    pub networks: Vec<Vec<f64>>,
    /// Each baseline's per object, in the order of [`BASELINES`].
    pub baselines: [Vec<f64>; 4],
}

/// The mean of `v` (NaN for none).
fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}
