//! How sure each difference is: the paired bootstrap over test objects, within classes, and
//! every network compared with every baseline and with the first network.

use super::{ScoreRow, mean};
use crate::error::{Error, Result};

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
        .map(|_| statistic(&diffs, &mut |n| (rng.next_u64() % n as u64) as usize))
        .collect();
    stats.sort_by(f64::total_cmp);
    Ok(Interval {
        mean: observed,
        lo: percentile(&stats, 0.025),
        hi: percentile(&stats, 0.975),
    })
}

/// The `p` quantile of sorted `v`, linear between the nearest ranks.
pub(super) fn percentile(v: &[f64], p: f64) -> f64 {
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
