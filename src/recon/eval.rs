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

/// The baselines' columns, in the order of [`ScoreRow::baselines`], named by what each knows
/// that a single-view network does not.
pub const BASELINES: [&str; 4] = [
    "retrieval (knows view)",
    "retrieval hull (knows view)",
    "mean shape (knows class)",
    "visual hull (24 views)",
];

/// What each of [`BASELINES`] is and knows: the table's legend.
pub const BASELINE_LEGEND: [&str; 4] = [
    "retrieval (knows view): the training object (any class) whose silhouette from the input's \
     own view index best matches the input's; answers with its true voxels. It is told the \
     viewpoint, which the network is not, and returns hollows no silhouette shows.",
    "retrieval hull (knows view): the same retrieved object answered with its visual hull (what \
     its 24 silhouettes can carve): retrieval told the viewpoint, knowing only silhouettes.",
    "mean shape (knows class): the class's mean training occupancy (≥ half the objects), the \
     same answer for every input; it is told the class.",
    "visual hull (24 views): the test object's own hull from its 24 silhouettes, not a method \
     but what silhouettes at these views can decide.",
];

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

/// Each object's mean of `per_input`, whose inputs are `views` consecutive views per object.
pub fn per_object(per_input: &[f64], views: usize) -> Vec<f64> {
    per_input.chunks(views.max(1)).map(mean).collect()
}

/// The table as text: a column per network (`networks` names them, in the order of
/// [`ScoreRow::networks`]), then the [`BASELINES`]; one row per class (its mean over test
/// objects), then the mean over classes.
pub fn format_table(networks: &[String], rows: &[ScoreRow]) -> String {
    use std::fmt::Write;
    let names: Vec<&str> = networks
        .iter()
        .map(String::as_str)
        .chain(BASELINES)
        .collect();
    let widths: Vec<usize> = names.iter().map(|m| m.chars().count().max(10)).collect();
    let mut s = String::new();
    let _ = write!(s, "{:<22} {:>7}", "class", "inputs");
    for (m, w) in names.iter().zip(&widths) {
        let _ = write!(s, " {m:>w$}");
    }
    s.push('\n');
    let line = |s: &mut String, class: &str, inputs: usize, values: &[f64]| {
        let _ = write!(s, "{class:<22} {inputs:>7}");
        for (r, w) in values.iter().zip(&widths) {
            let _ = write!(s, " {r:>w$.4}");
        }
        s.push('\n');
    };
    let means = column_means(rows);
    for (r, values) in rows.iter().zip(&means) {
        line(&mut s, &r.class, r.inputs, values);
    }
    if !rows.is_empty() {
        let inputs = rows.iter().map(|r| r.inputs).sum::<usize>();
        line(&mut s, "mean", inputs, &means[rows.len()]);
    }
    s
}

/// Each class's mean over objects of each column (networks, then baselines), then the mean of
/// those over classes.
fn column_means(rows: &[ScoreRow]) -> Vec<Vec<f64>> {
    let mut means: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            r.networks
                .iter()
                .chain(&r.baselines)
                .map(|v| mean(v))
                .collect()
        })
        .collect();
    let columns = means.first().map_or(0, Vec::len);
    let overall = (0..columns)
        .map(|k| mean(&means.iter().map(|c| c[k]).collect::<Vec<_>>()))
        .collect();
    means.push(overall);
    means
}

/// A mean difference and its percentile bootstrap interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// The observed mean difference.
    pub mean: f64,
    /// The lower percentile (2.5 % for a 95 % interval).
    pub lo: f64,
    /// The upper percentile.
    pub hi: f64,
}

/// Resamples of [`compare`]'s bootstrap.
pub const RESAMPLES: usize = 10_000;
/// Seed of [`compare`]'s bootstrap.
pub const BOOTSTRAP_SEED: u64 = 0;

/// The paired, stratified percentile bootstrap of the mean over strata of each stratum's mean
/// of `a − b`: each stratum (a class) is a pair of columns over the same units (test objects);
/// a resample draws, within each stratum, as many units as it has with replacement, the same
/// units for both columns (so what the two share, the difficulty of each object, cancels), and
/// the interval is the 2.5 and 97.5 percentiles of `resamples` resampled statistics, from a
/// fixed `seed`. [`Error::Input`] for no strata, an empty stratum or columns of different
/// lengths.
pub fn paired_bootstrap(
    strata: &[(&[f64], &[f64])],
    resamples: usize,
    seed: u64,
) -> Result<Interval> {
    if strata.is_empty() || resamples == 0 {
        return Err(Error::Input("a bootstrap of nothing".into()));
    }
    let diffs: Vec<Vec<f64>> = strata
        .iter()
        .map(|(a, b)| {
            if a.len() != b.len() || a.is_empty() {
                return Err(Error::Input(format!(
                    "a paired bootstrap of columns of {} and {} units",
                    a.len(),
                    b.len()
                )));
            }
            Ok(a.iter().zip(b.iter()).map(|(x, y)| x - y).collect())
        })
        .collect::<Result<_>>()?;
    let statistic = |d: &[Vec<f64>], pick: &mut dyn FnMut(usize) -> usize| {
        d.iter()
            .map(|d| (0..d.len()).map(|_| d[pick(d.len())]).sum::<f64>() / d.len() as f64)
            .sum::<f64>()
            / d.len() as f64
    };
    let observed = diffs.iter().map(|d| mean(d)).sum::<f64>() / diffs.len() as f64;
    let mut rng = crate::rng::SplitMix64(seed);
    let mut stats: Vec<f64> = (0..resamples)
        .map(|_| statistic(&diffs, &mut |n| (rng.next() % n as u64) as usize))
        .collect();
    stats.sort_by(f64::total_cmp);
    Ok(Interval {
        mean: observed,
        lo: percentile(&stats, 0.025),
        hi: percentile(&stats, 0.975),
    })
}

/// The `p` quantile of sorted `v`, linear between the nearest ranks.
fn percentile(v: &[f64], p: f64) -> f64 {
    let x = p * (v.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, x - x.floor());
    if i + 1 < v.len() {
        v[i] + f * (v[i + 1] - v[i])
    } else {
        v[i]
    }
}

/// Each network column minus each baseline, and each network column after the first minus the
/// first (a conditioned field against the mesh network, a recipe against another), per class
/// and over the classes (the mean of the class means, resampled within each class), as
/// [`paired_bootstrap`] intervals with [`RESAMPLES`] and [`BOOTSTRAP_SEED`].
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// `[class][network][baseline]`, classes in the table's order.
    pub classes: Vec<Vec<[Interval; 4]>>,
    /// `[network][baseline]` over all classes.
    pub mean: Vec<[Interval; 4]>,
    /// `[class][network − 1]`: network k (from 1) minus network 0, classes in the table's
    /// order, then the mean over classes.
    pub versus_first: Vec<Vec<Interval>>,
}

/// The [`Comparison`] of `rows`' networks against their baselines.
pub fn compare(rows: &[ScoreRow]) -> Result<Comparison> {
    let networks = rows.first().map_or(0, |r| r.networks.len());
    if rows.iter().any(|r| r.networks.len() != networks) {
        return Err(Error::Input("classes of different network columns".into()));
    }
    let interval = |rows: &[ScoreRow], k: usize, b: usize| {
        let strata: Vec<(&[f64], &[f64])> = rows
            .iter()
            .map(|r| (&r.networks[k][..], &r.baselines[b][..]))
            .collect();
        paired_bootstrap(&strata, RESAMPLES, BOOTSTRAP_SEED)
    };
    let versus_first = |rows: &[ScoreRow]| -> Result<Vec<Interval>> {
        (1..networks)
            .map(|k| {
                let strata: Vec<(&[f64], &[f64])> = rows
                    .iter()
                    .map(|r| (&r.networks[k][..], &r.networks[0][..]))
                    .collect();
                paired_bootstrap(&strata, RESAMPLES, BOOTSTRAP_SEED)
            })
            .collect()
    };
    let of = |rows: &[ScoreRow]| -> Result<Vec<[Interval; 4]>> {
        (0..networks)
            .map(|k| {
                let v = (0..4)
                    .map(|b| interval(rows, k, b))
                    .collect::<Result<Vec<_>>>()?;
                Ok([v[0], v[1], v[2], v[3]])
            })
            .collect()
    };
    Ok(Comparison {
        classes: rows
            .iter()
            .map(|r| of(std::slice::from_ref(r)))
            .collect::<Result<_>>()?,
        mean: of(rows)?,
        versus_first: rows
            .iter()
            .map(|r| versus_first(std::slice::from_ref(r)))
            .chain([versus_first(rows)])
            .collect::<Result<_>>()?,
    })
}

/// The comparison as text: `network − baseline: mean [lo, hi]`, a row per class and network,
/// then the means over classes, a column per baseline.
pub fn format_comparison(networks: &[String], rows: &[ScoreRow], cmp: &Comparison) -> String {
    use std::fmt::Write;
    let cell = |i: &Interval| format!("{:+.3} [{:+.3}, {:+.3}]", i.mean, i.lo, i.hi);
    let nw = networks
        .iter()
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(0)
        .max(7);
    let widths: Vec<usize> = BASELINES
        .iter()
        .map(|b| b.chars().count().max(24))
        .collect();
    let mut s = format!(
        "network − baseline: mean [lo, hi], 95 % paired bootstrap over test objects \
         ({RESAMPLES} resamples within each class, seed {BOOTSTRAP_SEED}; the mean row is the \
         mean of the class means)\n"
    );
    let _ = write!(s, "{:<22} {:<nw$}", "class", "network");
    for (b, w) in BASELINES.iter().zip(&widths) {
        let _ = write!(s, " {b:>w$}");
    }
    s.push('\n');
    let classes = rows.iter().map(|r| r.class.as_str()).chain(["mean"]);
    for (class, per) in classes.zip(cmp.classes.iter().chain([&cmp.mean])) {
        for (name, intervals) in networks.iter().zip(per) {
            let _ = write!(s, "{class:<22} {name:<nw$}");
            for (i, w) in intervals.iter().zip(&widths) {
                let _ = write!(s, " {:>w$}", cell(i));
            }
            s.push('\n');
        }
    }
    if let Some(first) = networks.first().filter(|_| networks.len() > 1) {
        let _ = writeln!(
            s,
            "\nnetwork − {first}: mean [lo, hi], the same bootstrap (the same objects for both)"
        );
        let _ = writeln!(s, "{:<22} {:<nw$} {:>24}", "class", "network", "difference");
        let classes = rows.iter().map(|r| r.class.as_str()).chain(["mean"]);
        for (class, per) in classes.zip(&cmp.versus_first) {
            for (name, i) in networks[1..].iter().zip(per) {
                let _ = writeln!(s, "{class:<22} {name:<nw$} {:>24}", cell(i));
            }
        }
    }
    let fewest = rows.iter().map(|r| r.baselines[0].len()).min();
    if let Some(n) = fewest.filter(|&n| n < 10) {
        let _ = writeln!(
            s,
            "(as few as {n} test objects in a class: a percentile bootstrap over so few \
             understates the spread)"
        );
    }
    s
}

/// The table and the comparison as CSV, a row per value: `class,column,minus,mean,lo,hi`
/// (`minus` empty for a column's own mean IoU, whose `lo` and `hi` are empty; class `mean` for
/// the mean over classes), enough to write the tables again.
pub fn table_csv(networks: &[String], rows: &[ScoreRow], cmp: &Comparison) -> String {
    use std::fmt::Write;
    let quote = |t: &str| format!("\"{}\"", t.replace('"', "\"\""));
    let mut s = String::from("class,column,minus,mean,lo,hi\n");
    let names: Vec<&str> = networks
        .iter()
        .map(String::as_str)
        .chain(BASELINES)
        .collect();
    let classes: Vec<&str> = rows
        .iter()
        .map(|r| r.class.as_str())
        .chain(["mean"])
        .collect();
    for (class, values) in classes.iter().zip(&column_means(rows)) {
        for (name, v) in names.iter().zip(values) {
            let _ = writeln!(s, "{},{},,{v},,", quote(class), quote(name));
        }
    }
    for (class, per) in classes.iter().zip(cmp.classes.iter().chain([&cmp.mean])) {
        for (name, intervals) in networks.iter().zip(per) {
            for (b, i) in BASELINES.iter().zip(intervals) {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{}",
                    quote(class),
                    quote(name),
                    quote(b),
                    i.mean,
                    i.lo,
                    i.hi
                );
            }
        }
    }
    if let Some(first) = networks.first() {
        for (class, per) in classes.iter().zip(&cmp.versus_first) {
            for (name, i) in networks[1..].iter().zip(per) {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{}",
                    quote(class),
                    quote(name),
                    quote(first),
                    i.mean,
                    i.lo,
                    i.hi
                );
            }
        }
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
    /// The voxels whose centres have a winding number of magnitude ≥ 0.5
    /// ([`crate::field::voxel::voxelize_mesh_winding`]): the same as parity for a mesh that
    /// does not overlap itself, but a region a fold encloses twice stays inside, and an
    /// inside-out mesh is inside. It needs a closed, consistently oriented mesh, which the
    /// decoder's deformed sphere always is (its faces are the template's); others are refused.
    Winding,
}

impl Voxelizer {
    /// `positions`/`faces` voxelized at 32³ on the dataset's lattice, in NMR order
    /// ([`super::dataset::voxel_cube`], [`super::dataset::occupancy_to_nmr`]).
    pub fn voxelize(&self, positions: &[[f32; 3]], faces: &[[u32; 3]]) -> Result<Vec<bool>> {
        use super::dataset::{VOXEL_RES, occupancy_to_nmr, voxel_cube};
        use crate::field::voxel;
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
    recon: &super::model::Reconstructor,
    class: &super::dataset::ClassData,
    inputs: &[(usize, usize)],
    voxelizers: &[Voxelizer],
) -> Result<Vec<Vec<f64>>> {
    let faces = super::train::template().faces;
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
    class: &super::dataset::ClassData,
) -> Result<Vec<bool>> {
    use super::dataset::{VIEWS, VOXEL_RES};
    use super::npz::{NpyData, read_npz_array};
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
    class: &super::dataset::ClassData,
    inputs: &[(usize, usize)],
) -> Result<Vec<f64>> {
    use super::dataset::{VIEWS, VOXEL_RES};
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

    /// `mesh` moved by `d`.
    fn moved(mesh: &crate::mesh::Mesh, d: [f32; 3]) -> Vec<[f32; 3]> {
        mesh.positions
            .iter()
            .map(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
            .collect()
    }

    #[test]
    fn winding_and_parity_agree_on_closed_meshes_that_do_not_overlap_themselves() {
        use crate::mesh::Mesh;
        let sphere = Mesh::icosphere(3);
        let sphere: Vec<[f32; 3]> = sphere
            .positions
            .iter()
            .map(|p| [0.41 * p[0] + 0.02, 0.33 * p[1] - 0.03, 0.37 * p[2] + 0.01])
            .collect();
        let template = crate::recon::train::template();
        let bumpy: Vec<[f32; 3]> = template
            .positions
            .iter()
            .map(|p| {
                let r = 0.3 + 0.08 * (3.0 * p[0]).sin() * (2.0 * p[1]).cos();
                p.map(|c| r * c)
            })
            .collect();
        let cuboid = Mesh::cuboid([0.31, 0.22, 0.13]);
        for (positions, faces) in [
            (&sphere, &Mesh::icosphere(3).faces),
            (&bumpy, &template.faces),
            (&cuboid.positions, &cuboid.faces),
        ] {
            let parity = Voxelizer::Parity.voxelize(positions, faces).unwrap();
            let winding = Voxelizer::Winding.voxelize(positions, faces).unwrap();
            assert!(parity.iter().filter(|&&x| x).count() > 100);
            assert_eq!(parity, winding);
        }
    }

    #[test]
    fn winding_keeps_what_a_self_overlap_doubles_where_parity_empties_it() {
        use crate::mesh::Mesh;
        // Two closed boxes in one mesh, overlapping in x ∈ [−0.12, 0.12].
        let cuboid = Mesh::cuboid([0.27, 0.2, 0.18]);
        let (a, b) = (
            moved(&cuboid, [-0.15, 0.0, 0.0]),
            moved(&cuboid, [0.15, 0.0, 0.0]),
        );
        let positions: Vec<[f32; 3]> = a.iter().chain(&b).copied().collect();
        let n = a.len() as u32;
        let faces: Vec<[u32; 3]> = cuboid
            .faces
            .iter()
            .copied()
            .chain(cuboid.faces.iter().map(|f| f.map(|i| i + n)))
            .collect();
        let one = |p: &[[f32; 3]]| Voxelizer::Parity.voxelize(p, &cuboid.faces).unwrap();
        let (a, b) = (one(&a), one(&b));
        let both = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
        assert!(both > 100, "the boxes overlap in {both} voxels");
        let parity = Voxelizer::Parity.voxelize(&positions, &faces).unwrap();
        let winding = Voxelizer::Winding.voxelize(&positions, &faces).unwrap();
        let xor: Vec<bool> = a.iter().zip(&b).map(|(x, y)| x ^ y).collect();
        let or: Vec<bool> = a.iter().zip(&b).map(|(x, y)| x | y).collect();
        assert_eq!(parity, xor, "parity empties the overlap");
        assert_eq!(winding, or, "the winding number keeps it");
    }

    #[test]
    fn an_inside_out_mesh_is_inside_by_winding_and_an_open_one_is_refused() {
        use crate::mesh::Mesh;
        let sphere = Mesh::icosphere(2);
        let positions: Vec<[f32; 3]> = sphere
            .positions
            .iter()
            .map(|p| p.map(|c| 0.4 * c))
            .collect();
        let reversed: Vec<[u32; 3]> = sphere.faces.iter().map(|f| [f[0], f[2], f[1]]).collect();
        let outward = Voxelizer::Winding
            .voxelize(&positions, &sphere.faces)
            .unwrap();
        let inward = Voxelizer::Winding.voxelize(&positions, &reversed).unwrap();
        assert!(outward.iter().filter(|&&x| x).count() > 1000);
        assert_eq!(inward, outward);
        // A hole, or one face turned against its neighbours: no winding number to count.
        let open = &sphere.faces[1..];
        let mut flipped = sphere.faces.clone();
        flipped[3].swap(1, 2);
        for faces in [open, &flipped[..]] {
            let err = Voxelizer::Winding.voxelize(&positions, faces).unwrap_err();
            assert!(
                matches!(&err, Error::Input(m) if m.contains("closed, consistently oriented")),
                "{err}"
            );
        }
    }

    /// Columns of `n` units: `base[i] + shift + noise[i]`, the noise ±`spread` alternating.
    fn shifted(base: &[f64], shift: f64, spread: f64) -> Vec<f64> {
        base.iter()
            .enumerate()
            .map(|(i, b)| b + shift + if i % 2 == 0 { spread } else { -spread })
            .collect()
    }

    /// `n` values spread over [0, 1) (a fixed pseudo-random draw).
    fn spread(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = crate::rng::SplitMix64(seed);
        (0..n).map(|_| rng.unit()).collect()
    }

    #[test]
    fn identical_columns_differ_by_exactly_zero() {
        let a = spread(9, 1);
        let i = paired_bootstrap(&[(&a, &a)], 1000, 7).unwrap();
        assert_eq!((i.mean, i.lo, i.hi), (0.0, 0.0, 0.0));
    }

    #[test]
    fn a_known_shift_is_inside_its_interval_and_more_objects_narrow_it() {
        let width = |n: usize| {
            let b = spread(n, 3);
            let a = shifted(&b, 0.1, 0.1);
            let i = paired_bootstrap(&[(&a, &b)], RESAMPLES, BOOTSTRAP_SEED).unwrap();
            assert!((i.mean - 0.1).abs() < 1e-12, "{i:?}");
            assert!(i.lo < 0.1 && 0.1 < i.hi, "{i:?}");
            assert!(
                i.lo > 0.0,
                "{n} objects: a shift as large as the noise is clear: {i:?}"
            );
            i.hi - i.lo
        };
        let (few, many) = (width(16), width(256));
        // The width goes as 1/√n: 4 times narrower for 16 times the objects.
        assert!(few > 3.0 * many && few < 5.0 * many, "{few} {many}");
    }

    #[test]
    fn pairing_cancels_what_both_columns_share() {
        // Objects of very different difficulty (IoUs over [0, 1)), the network ahead of the
        // baseline by 0.1 on every one.
        let b = spread(24, 5);
        let a: Vec<f64> = b.iter().map(|x| x + 0.1).collect();
        let paired = paired_bootstrap(&[(&a, &b)], RESAMPLES, BOOTSTRAP_SEED).unwrap();
        assert!((paired.lo - 0.1).abs() < 1e-12 && (paired.hi - 0.1).abs() < 1e-12);
        // Resampling the two columns independently sees the spread of difficulty instead.
        let mut rng = crate::rng::SplitMix64(BOOTSTRAP_SEED);
        let mut draw = |v: &[f64]| {
            (0..v.len())
                .map(|_| v[(rng.next() % v.len() as u64) as usize])
                .sum::<f64>()
                / v.len() as f64
        };
        let mut unpaired: Vec<f64> = (0..RESAMPLES).map(|_| draw(&a) - draw(&b)).collect();
        unpaired.sort_by(f64::total_cmp);
        let width = percentile(&unpaired, 0.975) - percentile(&unpaired, 0.025);
        assert!(width > 0.2, "unpaired: {width}");
    }

    #[test]
    fn the_overall_interval_is_of_the_mean_of_class_means_resampled_within_classes() {
        // Class one (2 objects) ahead by 1, class two (8 objects) by 0: the mean of the class
        // means is 0.5 whatever the resample; pooling the objects would say 0.2 and spread.
        let (a1, b1) = ([1.0, 1.0], [0.0, 0.0]);
        let (a2, b2) = (spread(8, 9), spread(8, 9));
        let i = paired_bootstrap(&[(&a1, &b1), (&a2, &b2)], 1000, 0).unwrap();
        assert_eq!((i.mean, i.lo, i.hi), (0.5, 0.5, 0.5));
        assert!(matches!(
            paired_bootstrap(&[(&a1, &b2)], 10, 0),
            Err(Error::Input(_))
        ));
    }

    #[test]
    fn later_networks_are_compared_with_the_first_on_the_same_objects() {
        // Network 1 is network 0 plus 0.05 on every object (objects that vary a lot), network 2
        // is network 0 itself: exact differences, whatever the resample, in every class and
        // over the classes; and they appear in the text and the CSV.
        let row = |class: &str, seed: u64| {
            let n0 = spread(12, seed);
            let n1: Vec<f64> = n0.iter().map(|x| x + 0.05).collect();
            let base = spread(12, seed + 1);
            ScoreRow {
                class: class.into(),
                inputs: 12,
                networks: vec![n0.clone(), n1, n0],
                baselines: [base.clone(), base.clone(), base.clone(), base],
            }
        };
        let rows = [row("a", 3), row("b", 5)];
        let cmp = compare(&rows).unwrap();
        assert_eq!(cmp.versus_first.len(), 3, "two classes and the mean");
        for per in &cmp.versus_first {
            assert_eq!(per.len(), 2);
            for (i, want) in per.iter().zip([0.05, 0.0]) {
                for x in [i.mean, i.lo, i.hi] {
                    assert!((x - want).abs() < 1e-12, "{i:?} vs {want}");
                }
            }
        }
        let names: Vec<String> = ["mesh", "field", "again"].map(String::from).to_vec();
        let text = format_comparison(&names, &rows, &cmp);
        assert!(text.contains("network − mesh"), "{text}");
        let csv = table_csv(&names, &rows, &cmp);
        assert!(csv.contains("\"mean\",\"field\",\"mesh\",0.05"), "{csv}");
        let one = compare(&rows.map(|mut r| {
            r.networks.truncate(1);
            r
        }))
        .unwrap();
        assert!(one.versus_first.iter().all(Vec::is_empty));
    }
}
