//! `softvk fit-pose --mesh M.obj --target T.png --out pose.json [view] [raster]`: the rigid pose
//! (rotation and translation) of a textured mesh that makes its render match a target RGBA
//! image ([`softvk::fit::pose`]), with a σ/γ schedule from blurry to sharp.
//!
//! - The target is a PNG with an alpha channel (what `softvk render` writes): the loss is the
//!   MSE over R, G, B and A, so the alpha carries the silhouette. Its size is the image size;
//!   `--size`/`--width --height` must agree with it when given.
//! - `[raster]`'s `--sigma`/`--gamma` are the schedule's sharp end (default SoftRas's 1e-5,
//!   1e-4); `--sigma-start`/`--gamma-start` its blurry start; `--no-schedule` renders every
//!   iteration sharp. Lighting is on (SoftRas's defaults) so that shading constrains the
//!   rotation too; a mesh without a texture renders white and is fitted by shape and shading.
//! - `--init-rotation x,y,z` is an axis-angle vector **in degrees**: its direction is the axis,
//!   its length the angle (`0,90,0` is a quarter turn about +y). Rotations turn about the mesh's
//!   vertex centroid: `p' = R (p − c) + c + t`.
//! - `--starts K`: K fits from the K lowest-loss of `--candidates` rotations spread over all
//!   rotations, the lowest final loss kept ([`softvk::fit::pose::fit_pose_multistart`]);
//!   `pose.json` lists every start and the winner.
//!
//! Writes `pose.json` (rotation as axis-angle, 3×3 matrix and quaternion, translation, centre,
//! final loss, iterations, angle to the initial rotation), the final render (`--render`,
//! default `<out stem>-render.png` beside it), a heat map of |render − target| (`--error`,
//! default `<out stem>-error.png`) and the target, the start and the result side by side
//! (`--compare`, default `<out stem>-compare.png`). Every file is written atomically after the
//! fit; any error is one line and leaves no file.

use std::path::PathBuf;

use glam::DVec3;
use serde_json::{Value, json};
use softvk::fit::pose::{
    Pose, PoseFit, PoseTarget, Schedule, fit_pose, fit_pose_multistart, rotation_distance,
    screened_starts,
};
use softvk::fit::report;
use softvk::fit::session::Progress;
use softvk::gpu::{Context, ContextOptions};
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::{Error, Result};

use crate::cli::output::{SideFile, encode_compare, encode_png};
use crate::cli::session::{Outputs, Watch, interrupted, summary};

mod args;
pub use args::*;

/// The least angle between two of `--starts`' screened starts.
const MIN_START_SEPARATION_DEG: f64 = 30.0;

/// The checkpoint's file in `--checkpoint DIR` / `--resume DIR`.
pub const CHECKPOINT_FILE: &str = "pose-fit.ckpt";

/// Runs `softvk fit-pose`.
pub fn run(args: &FitPoseArgs) -> Result<()> {
    let (size, target) = args.view.target(&args.target)?;
    let camera = args.view.camera()?;
    let lighting = args.raster.lighting();
    let opts = args.options(size)?;
    let tile = opts.tile;
    let init = Pose {
        rotation: DVec3::from(args.init_rotation.unwrap_or([0.0; 3])) * (1f64.to_radians()),
        translation: DVec3::from(args.init_translation.unwrap_or([0.0; 3])),
    };
    let mesh = super::args::load_mesh(&args.mesh, args.raster.texture_res, args.normalize)?;
    if args.raster.vertex_colors && mesh.vertex_colors.is_none() {
        return Err(Error::Input(format!(
            "--vertex-colors: {} has no vertex colours (every `v` line needs `x y z r g b`)",
            args.mesh.display()
        )));
    }
    let starts = args.starts();
    if args.candidates.is_some() && starts == 1 {
        return Err(Error::Input(
            "--candidates chooses the starts of --starts K (K > 1)".into(),
        ));
    }
    if starts > 1 && (args.checkpoints.checkpoint.is_some() || args.checkpoints.resume.is_some()) {
        return Err(Error::Input(
            "--starts with --checkpoint/--resume: a checkpoint holds one fit".into(),
        ));
    }
    let ctx = Context::new(&ContextOptions::from_env())?;
    // The checkpoint is checked before anything is written.
    let fingerprint = PoseFit::fingerprint(&mesh, &camera, &lighting, &target, &init, &opts);
    let session = args.checkpoints.session(CHECKPOINT_FILE, fingerprint)?;
    let side = |flag, path, suffix| SideFile { flag, path, suffix };
    let outputs = Outputs::beside(
        &args.out,
        "pose",
        &[
            side("--render", args.render.as_deref(), "-render.png"),
            side("--error", args.error.as_deref(), "-error.png"),
            side("--compare", args.compare.as_deref(), "-compare.png"),
        ],
    )?;
    let watch = Watch::new(args.quiet, u64::from(opts.iterations));
    let bar = watch.bar();
    let mut multi = None;
    let result = if starts > 1 {
        let candidates = args.candidates.unwrap_or(32 * starts);
        bar.set_message(format!("screening {candidates} rotations"));
        let inits = screened_starts(
            &ctx,
            &mesh,
            &camera,
            &lighting,
            &target,
            &init,
            starts,
            candidates,
            MIN_START_SEPARATION_DEG.to_radians(),
            &opts,
        )?;
        bar.set_length(u64::from(opts.iterations) * u64::from(starts));
        let m = fit_pose_multistart(
            &ctx,
            &mesh,
            &camera,
            &lighting,
            PoseTarget::Fixed(&target),
            &inits,
            &opts,
            |k, l| {
                bar.set_position(k as u64 * u64::from(opts.iterations) + u64::from(l.iteration));
                bar.set_message(format!(
                    "start {}/{}  loss {:.5}  σ {:.0e}",
                    k + 1,
                    starts,
                    l.loss,
                    l.sigma
                ));
                super::interrupt::requested().is_none()
            },
        )?;
        let best = m.best.clone();
        multi = Some(m);
        best
    } else {
        let hooks = |p: &Progress<'_, '_, PoseFit<'_>>| {
            let l = p.row();
            let message = format!("loss {:.5}  σ {:.0e}", l.loss, l.sigma);
            Ok(watch.update(l.iteration, message))
        };
        fit_pose(
            &ctx,
            &mesh,
            &camera,
            &lighting,
            PoseTarget::Fixed(&target),
            &init,
            &opts,
            session.hooks(hooks),
        )?
    };
    bar.finish_and_clear();
    ctx.check_validation()?;
    // The log holds every iteration (a resumed fit's first ones from its checkpoint).
    let initial_loss = result.log.first().map_or(f64::NAN, |l| l.loss);

    let pose = &result.pose;
    let m = pose.matrix();
    let q = pose.quaternion();
    let angle = pose.rotation.length();
    // Non-finite numbers become null (serde_json's f64 conversion).
    let mut json = json!({
        "convention": "p' = R (p - centre) + centre + translation; rotation as axis-angle \
                       (radians), matrix row-major, quaternion w, x, y, z",
        "rotation_axis_angle": pose.rotation.to_array(),
        "rotation_angle_degrees": angle.to_degrees(),
        "rotation_axis": if angle > 0.0 {
            (pose.rotation / angle).to_array()
        } else {
            [1.0, 0.0, 0.0]
        },
        "rotation_matrix": [m.row(0).to_array(), m.row(1).to_array(), m.row(2).to_array()],
        "quaternion_wxyz": [q.w, q.x, q.y, q.z],
        "translation": pose.translation.to_array(),
        "centre": result.centre.to_array(),
        "angle_to_init_degrees": rotation_distance(pose.rotation, init.rotation).to_degrees(),
        "initial_loss": initial_loss,
        "loss": result.loss,
        "iterations": result.iterations,
    });
    let fields = json.as_object_mut().expect("an object");
    // Stopped early by Ctrl-C / SIGTERM (`cli::interrupt`): the pose after the last step.
    if let Some(note) = interrupted(result.iterations, opts.iterations) {
        fields.insert("interrupted".into(), json!(note));
    }
    if let Some(m) = &multi {
        fields.insert("best_start".into(), json!(m.best_start));
        fields.insert(
            "starts".into(),
            Value::Array(
                m.starts
                    .iter()
                    .map(|s| {
                        json!({
                            "init_rotation_axis_angle": s.init.rotation.to_array(),
                            "rotation_axis_angle": s.pose.rotation.to_array(),
                            "translation": s.pose.translation.to_array(),
                            "loss": s.loss,
                            "seconds": s.seconds,
                        })
                    })
                    .collect(),
            ),
        );
    }
    fields.insert("sigma".into(), json!(opts.settings.sigma));
    fields.insert("gamma".into(), json!(opts.settings.gamma));
    fields.insert("schedule".into(), schedule_json(opts.schedule.as_ref()));
    fields.insert("seconds".into(), json!(result.seconds));
    let json = format!(
        "{}\n",
        serde_json::to_string_pretty(&json).expect("JSON of numbers")
    );

    let [out, render_path, error_path, compare_path] = [0, 1, 2, 3].map(|i| &outputs.paths[i]);
    let render_png = encode_png(&result.image, size, render_path)?;
    let error_map = report::error_map(&result.image, &target);
    let error_png = encode_png(&error_map, size, error_path)?;
    // The start (the winning one of several), posed about the same centre and rendered as the
    // result was.
    let start_pose = multi.as_ref().map_or(init, |m| m.starts[m.best_start].init);
    let start_mesh = Mesh {
        positions: start_pose
            .apply(
                &mesh
                    .positions
                    .iter()
                    .map(|p| DVec3::from(p.map(f64::from)))
                    .collect::<Vec<_>>(),
                result.centre,
            )
            .iter()
            .map(|p| p.as_vec3().to_array())
            .collect(),
        ..mesh.clone()
    };
    let start = Renderer::new(&ctx)?
        .render_views(
            &ctx,
            &start_mesh,
            &[camera],
            &lighting,
            &opts.settings,
            Method::Tiled { tile },
        )?
        .images;
    ctx.check_validation()?;
    let sheet = [
        ("target", &target),
        ("start", &start),
        ("result", &result.image),
    ];
    let compare_png = encode_compare(&sheet, size, compare_path)?;
    let what = format!(
        "; loss {initial_loss:.3e} → {:.3e}; rotation {:.2}° about {:?}, translation {:?}",
        result.loss,
        angle.to_degrees(),
        pose.rotation
            .normalize_or_zero()
            .to_array()
            .map(|c| (c * 1e4).round() / 1e4),
        pose.translation.to_array().map(|c| (c * 1e4).round() / 1e4),
    );
    let wrote = [out, render_path, error_path, compare_path].map(PathBuf::as_path);
    let line = summary(
        result.first_iteration,
        result.iterations,
        result.seconds,
        &what,
        &wrote,
    );
    outputs.commit(&[json.as_bytes(), &render_png, &error_png, &compare_png])?;
    println!("{line}");
    Ok(())
}

/// A σ/γ schedule in a fit's JSON (`null` without one).
pub fn schedule_json(schedule: Option<&Schedule>) -> Value {
    schedule.map_or(
        Value::Null,
        |s| json!({"sigma_start": s.sigma_start, "gamma_start": s.gamma_start, "stages": s.stages}),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_numbers_are_finite_or_null() {
        // What pose.json relies on: a non-finite loss or pose is written as null.
        assert_eq!(json!(0.1).to_string(), "0.1");
        assert!(json!(f64::NAN).is_null() && json!(f64::INFINITY).is_null());
        assert_eq!(json!([1.0, -2.5]).to_string(), "[1.0,-2.5]");
    }
}
