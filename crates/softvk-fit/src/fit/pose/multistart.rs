//! Several starts spread over the rotations, screened by their loss, each fitted: a pose many
//! radians away lands in a wrong minimum from one start.

use glam::DQuat;

use super::{
    Pose, PoseFit, PoseFitOptions, PoseFitResult, PoseLog, PoseProblem, PoseTarget, fit_pose,
    rotation_distance,
};
use crate::fit::session::{Progress, Session};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::lighting::Lighting;
use crate::mesh::Mesh;

/// `k` unit quaternions spread evenly over all rotations: the super-Fibonacci spiral (Alexa,
/// "Super-Fibonacci Spirals", CVPR 2022), turned so that its first point is the identity. Written
/// here (a dozen lines) rather than taken from a crate: no maintained Rust crate offers it.
pub fn spread_rotations(k: u32) -> Vec<DQuat> {
    // ψ: the real root of ψ⁴ = ψ + 4 (the paper's second irrational).
    const PSI: f64 = 1.533_751_168_755_204_3;
    let n = f64::from(k);
    let points: Vec<DQuat> = (0..k)
        .map(|i| {
            let s = f64::from(i) + 0.5;
            let (r, big_r) = ((s / n).sqrt(), (1.0 - s / n).sqrt());
            let alpha = std::f64::consts::TAU * s / std::f64::consts::SQRT_2;
            let beta = std::f64::consts::TAU * s / PSI;
            DQuat::from_xyzw(
                r * alpha.sin(),
                r * alpha.cos(),
                big_r * beta.sin(),
                big_r * beta.cos(),
            )
            .normalize()
        })
        .collect();
    let Some(first) = points.first().copied() else {
        return Vec::new();
    };
    // Right-multiplying every point by one rotation moves them rigidly on the sphere.
    points
        .iter()
        .map(|&q| (q * first.inverse()).normalize())
        .collect()
}

/// `k` starting poses: `init`'s rotation composed with [`spread_rotations`] (the first start is
/// `init` itself), each with `init`'s translation.
pub fn spread_starts(init: &Pose, k: u32) -> Vec<Pose> {
    let q = init.quaternion();
    spread_rotations(k)
        .into_iter()
        .enumerate()
        .map(|(i, s)| Pose {
            rotation: if i == 0 {
                init.rotation
            } else {
                (q * s).to_scaled_axis()
            },
            translation: init.translation,
        })
        .collect()
}

/// `k` starts for a multi-start fit chosen by the loss: `candidates` rotations spread over all
/// rotations ([`spread_rotations`], composed with `init`'s; `init`'s translation) are rendered
/// against `target` at the options' sharp σ/γ, and the `k` lowest losses are kept, best first,
/// skipping any candidate within `separation` (radians) of one already kept, so that the starts
/// lie in different basins. With `candidates ≤ k` it is [`spread_starts`].
#[allow(clippy::too_many_arguments)]
pub fn screened_starts(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    target: &[[f32; 4]],
    init: &Pose,
    k: u32,
    candidates: u32,
    separation: f64,
    opts: &PoseFitOptions,
) -> Result<Vec<Pose>> {
    if candidates <= k {
        return Ok(spread_starts(init, k));
    }
    let s = &opts.settings;
    let mut problem = PoseProblem::new(ctx, mesh, camera, lighting, target, s, opts.tile)?;
    let mut scored = Vec::with_capacity(candidates as usize);
    for pose in spread_starts(init, candidates) {
        let loss = problem.evaluate(ctx, &pose, s.sigma, s.gamma)?.loss;
        scored.push((loss, pose));
    }
    // Lowest loss first; ties in the spiral's order; NaN last.
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut kept: Vec<Pose> = Vec::with_capacity(k as usize);
    for (_, pose) in &scored {
        if kept.len() == k as usize {
            break;
        }
        if kept
            .iter()
            .all(|p| rotation_distance(p.rotation, pose.rotation) >= separation)
        {
            kept.push(*pose);
        }
    }
    // Fewer than k far enough apart: fill with the next best.
    for (_, pose) in &scored {
        if kept.len() == k as usize {
            break;
        }
        if !kept.contains(pose) {
            kept.push(*pose);
        }
    }
    Ok(kept)
}

/// How one start of a multi-start fit ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartOutcome {
    /// Where it started.
    pub init: Pose,
    /// Where it ended.
    pub pose: Pose,
    /// Its final loss (sharp σ/γ).
    pub loss: f64,
    /// Its wall time.
    pub seconds: f64,
    /// Iterations it ran.
    pub iterations: u32,
}

/// A finished multi-start fit.
#[derive(Clone, Debug)]
pub struct MultiStartResult {
    /// The fit of the start that ended with the lowest loss.
    pub best: PoseFitResult,
    /// Its index in the starts.
    pub best_start: usize,
    /// Every start that ran, in order.
    pub starts: Vec<StartOutcome>,
}

/// Fits the pose from each of `starts` in turn ([`fit_pose`] with the same options, target and
/// schedule) and keeps the fit that ends with the lowest loss (the first of equals; a
/// non-finite loss never wins). The landscape of a rotation has basins: one start from far
/// away lands in a wrong one, while one of several starts spread over the rotations
/// ([`spread_starts`]) usually begins inside the right one. `progress(start, log)` is
/// [`fit_pose`]'s, with the start's index; `false` stops the start it is in and every later one.
///
/// With [`PoseFitOptions::refine`], the starts run the schedule only, and the winner alone is
/// refined: fitted again from its start with the refinement (its schedule's iterations are the
/// same bits), its outcome replaced by the refined one. A start's loss after the schedule
/// already tells the basins apart; refining the losers would only spend iterations.
#[allow(clippy::too_many_arguments)]
pub fn fit_pose_multistart(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    mut target: PoseTarget<'_>,
    starts: &[Pose],
    opts: &PoseFitOptions,
    mut progress: impl FnMut(usize, &PoseLog) -> bool,
) -> Result<MultiStartResult> {
    if starts.is_empty() {
        return Err(Error::Input("a multi-start pose fit needs a start".into()));
    }
    let mut outcomes = Vec::with_capacity(starts.len());
    let mut best: Option<(usize, PoseFitResult)> = None;
    let schedule_only = PoseFitOptions {
        refine: None,
        ..opts.clone()
    };
    let mut fit = |k: usize, opts: &PoseFitOptions, stopped: &mut bool| {
        let here = match &mut target {
            PoseTarget::Fixed(t) => PoseTarget::Fixed(t),
            PoseTarget::PerStage(f) => PoseTarget::PerStage(&mut **f),
        };
        let hooks = |p: &Progress<'_, '_, PoseFit<'_>>| {
            let go_on = progress(k, p.row());
            *stopped |= !go_on;
            Ok(go_on)
        };
        let session = Session::new().hooks(hooks);
        fit_pose(ctx, mesh, camera, lighting, here, &starts[k], opts, session)
    };
    let outcome = |k: usize, result: &PoseFitResult| StartOutcome {
        init: starts[k],
        pose: result.pose,
        loss: result.loss,
        seconds: result.seconds,
        iterations: result.iterations,
    };
    let mut stopped = false;
    for k in 0..starts.len() {
        let result = fit(k, &schedule_only, &mut stopped)?;
        outcomes.push(outcome(k, &result));
        let better = match &best {
            None => true,
            Some((_, b)) => result.loss < b.loss || !b.loss.is_finite() && result.loss.is_finite(),
        };
        if better {
            best = Some((k, result));
        }
        if stopped {
            break;
        }
    }
    let (best_start, mut best) = best.expect("at least one start ran");
    if opts.refine.is_some() && !stopped {
        best = fit(best_start, opts, &mut stopped)?;
        outcomes[best_start] = StartOutcome {
            seconds: outcomes[best_start].seconds + best.seconds,
            iterations: outcomes[best_start].iterations + best.iterations,
            ..outcome(best_start, &best)
        };
    }
    Ok(MultiStartResult {
        best,
        best_start,
        starts: outcomes,
    })
}
