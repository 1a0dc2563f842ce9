//! `softvk fit-articulated --out angles.json (--target T.png | --target-angles A,B,...)`: the
//! joint angles of the built-in skinned figure ([`softvk::fit::rig::Rig::figure`]) that make its
//! render match a target RGBA image ([`softvk::fit::articulated`]), with the σ/γ
//! schedule and a blurred image loss from wide to sharp.
//!
//! - `--target T.png`: a PNG with an alpha channel (as `softvk render` writes), the image size
//!   unless `--size`/`--width --height` say otherwise (they must agree). The loss compares R, G,
//!   B and A.
//! - `--target-angles`: the figure itself posed at these angles (degrees, one per joint, in the
//!   order `angles.json` lists them) is the target, rendered again at every σ/γ stage (both
//!   images equally soft: the loss landscape of the talk); `angles.json` then gives each
//!   joint's error.
//! - `--init-angles` (degrees) is the start [default: the rest pose, all 0].
//!
//! Writes `angles.json` (per joint: name, fitted angle, start, and with `--target-angles` the
//! target and the error; the losses, iterations, options), the final render (`--render`,
//! default `<out stem>-render.png`), the target, the start and the result side by side
//! (`--compare`, default `<out stem>-compare.png`) and the posed mesh with its colours
//! (`--mesh-out`, default `<out stem>-posed.obj`). Everything is written after the fit; any
//! error is one line and leaves no file.

use std::path::PathBuf;

use serde_json::{Value, json};
use softvk::fit::articulated::{
    ArticulatedFit, ArticulatedFitOptions, BlurSchedule, fit_articulated,
};
use softvk::fit::pose::{PoseTarget, Schedule};
use softvk::fit::report;
use softvk::fit::rig::Rig;
use softvk::fit::session::Progress;
use softvk::gpu::{Context, ContextOptions};
use softvk::io;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::{Error, Result};

use crate::cli::output::load_target;
use crate::cli::output::{AtomicFile, ImageFormat, SideFile, encode_sheet_png, side_files};
use crate::cli::session::Watch;

mod args;
pub use args::*;

/// Degrees to radians, one per joint of `rig` ([`Error::Input`] naming `flag` otherwise).
fn joint_angles(rig: &Rig, flag: &str, degrees: &[f64]) -> Result<Vec<f64>> {
    if degrees.len() != rig.joint_count() {
        let names: Vec<&str> = rig.joints.iter().map(|j| j.name.as_str()).collect();
        return Err(Error::Input(format!(
            "{flag}: the figure has {} joints ({}); got {} angles",
            rig.joint_count(),
            names.join(", "),
            degrees.len()
        )));
    }
    Ok(degrees.iter().map(|d| d.to_radians()).collect())
}

/// Runs `softvk fit-articulated`.
pub fn run(args: &FitArticulatedArgs) -> Result<()> {
    // A target re-rendered per stage can start softer than a fixed image.
    let d = if args.target_angles.is_some() {
        ArticulatedFitOptions::for_rendered_target()
    } else {
        ArticulatedFitOptions::default()
    };
    let tile = args.tile.unwrap_or(d.tile);
    Method::check_tile(tile)?;
    let rig = Rig::figure();
    let init = match &args.init_angles {
        Some(a) => joint_angles(&rig, "--init-angles", &a.0)?,
        None => vec![0.0; rig.joint_count()],
    };
    let target_angles = args
        .target_angles
        .as_ref()
        .map(|a| joint_angles(&rig, "--target-angles", &a.0))
        .transpose()?;
    let explicit = args.view.size.is_some() || args.view.width.is_some();
    let (size, image_target) = match &args.target {
        Some(path) => {
            let (tw, th, pixels) = load_target(path)?;
            let size = if explicit { args.view.size() } else { (tw, th) };
            if size != (tw, th) {
                return Err(Error::Input(format!(
                    "the target {} is {tw}x{th} but the image is {}x{}",
                    path.display(),
                    size.0,
                    size.1
                )));
            }
            (size, Some(pixels))
        }
        None if explicit => (args.view.size(), None),
        None => ((d.settings.width, d.settings.height), None),
    };
    let camera = args.view.camera()?;
    let settings = args.raster.settings(size)?;
    let lighting = args.raster.lighting();
    let stages = args.stages;
    let schedule = (!args.no_schedule).then(|| {
        let s = d.schedule.unwrap_or_default();
        Schedule {
            sigma_start: args.sigma_start.unwrap_or(s.sigma_start),
            gamma_start: args.gamma_start.unwrap_or(s.gamma_start),
            stages: stages.unwrap_or(s.stages),
        }
    });
    let blur_default = d.blur.unwrap_or_default();
    let blur = Some(BlurSchedule {
        start: args.blur.unwrap_or(blur_default.start),
        stages: stages.unwrap_or(blur_default.stages),
    })
    .filter(|b| b.start > 0.0);
    let opts = ArticulatedFitOptions {
        iterations: args.iterations.unwrap_or(d.iterations),
        lr: args.lr.unwrap_or(d.lr),
        lr_final: args.lr_final.unwrap_or(d.lr_final),
        schedule,
        blur,
        settings,
        tile,
        ..d
    };
    opts.validate()?;
    let [render_path, compare_path, mesh_path]: [PathBuf; 3] = side_files(
        &args.out,
        "angles",
        &[
            SideFile {
                flag: "--render",
                path: args.render.as_deref(),
                suffix: "-render.png",
            },
            SideFile {
                flag: "--compare",
                path: args.compare.as_deref(),
                suffix: "-compare.png",
            },
            SideFile {
                flag: "--mesh-out",
                path: args.mesh_out.as_deref(),
                suffix: "-posed.obj",
            },
        ],
    )?
    .try_into()
    .expect("three side files");
    let out = AtomicFile::create(&args.out)?;
    let render_file = AtomicFile::create(&render_path)?;
    let compare_file = AtomicFile::create(&compare_path)?;

    let ctx = Context::new(&ContextOptions::from_env())?;
    let renderer = Renderer::new(&ctx)?;
    let render_at = |angles: &[f64], s: &RasterSettings| -> Result<Vec<[f32; 4]>> {
        Ok(renderer
            .render_views(
                &ctx,
                &rig.posed_mesh(angles),
                &[camera],
                &lighting,
                s,
                Method::Tiled { tile },
            )?
            .images)
    };
    // The sharp target (for the picture and the final loss).
    let target = match (&image_target, &target_angles) {
        (Some(t), _) => t.clone(),
        (None, Some(a)) => render_at(a, &settings)?,
        (None, None) => unreachable!("clap requires --target or --target-angles"),
    };
    // The checkpoint is checked before the fit starts (the sharp target is in its inputs).
    let fingerprint = ArticulatedFit::fingerprint(&rig, &camera, &lighting, &target, &init, &opts);
    let session = args.checkpoints.session(CHECKPOINT_FILE, fingerprint)?;
    let watch = Watch::new(args.quiet, u64::from(opts.iterations));
    let mut per_stage = |sigma: f64, gamma: f64| -> Result<Vec<[f32; 4]>> {
        let a = target_angles.as_ref().expect("only with --target-angles");
        render_at(
            a,
            &RasterSettings {
                sigma,
                gamma,
                ..settings
            },
        )
    };
    let fit_target = if target_angles.is_some() {
        PoseTarget::PerStage(&mut per_stage)
    } else {
        PoseTarget::Fixed(&target)
    };
    let result = fit_articulated(
        &ctx,
        &rig,
        &camera,
        &lighting,
        fit_target,
        &init,
        &opts,
        session.hooks(|p: &Progress<'_, '_, ArticulatedFit<'_>>| {
            let l = p.row();
            let message = format!(
                "loss {:.5}  σ {:.0e}  blur {:.1} px",
                l.loss, l.sigma, l.blur
            );
            Ok(watch.update(l.iteration, message))
        }),
    )?;
    watch.finish();
    let start_image = render_at(&init, &settings)?;
    ctx.check_validation()?;

    let initial_loss = result.log.first().map_or(f64::NAN, |l| l.loss);
    let joints: Vec<Value> = rig
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let mut o = json!({
                "name": joint.name,
                "angle_degrees": result.angles[j].to_degrees(),
                "init_degrees": init[j].to_degrees(),
            });
            if let Some(t) = &target_angles {
                let fields = o.as_object_mut().expect("an object");
                fields.insert("target_degrees".into(), json!(t[j].to_degrees()));
                fields.insert(
                    "error_degrees".into(),
                    json!((result.angles[j] - t[j]).to_degrees()),
                );
            }
            o
        })
        .collect();
    let worst_error = target_angles.as_ref().map(|t| {
        result
            .angles
            .iter()
            .zip(t)
            .map(|(a, b)| (a - b).abs().to_degrees())
            .fold(0.0, f64::max)
    });
    let mut json = json!({
        "rig": "figure",
        "convention": "each joint turns its bones by its angle about its axis through its pivot \
                       (right-handed, degrees); 0 is the rest pose",
        "joints": joints,
        "initial_loss": initial_loss,
        "loss": result.loss,
        "iterations": result.iterations,
        "target": if target_angles.is_some() { "rendered per stage from --target-angles" }
                  else { "image" },
        "sigma": opts.settings.sigma,
        "gamma": opts.settings.gamma,
        "schedule": opts.schedule.as_ref().map_or(Value::Null, |s| {
            json!({"sigma_start": s.sigma_start, "gamma_start": s.gamma_start, "stages": s.stages})
        }),
        "blur": opts.blur.as_ref().map_or(Value::Null, |b| {
            json!({"start_pixels": b.start, "stages": b.stages})
        }),
        "seconds": result.seconds,
    });
    let fields = json.as_object_mut().expect("an object");
    if let Some(w) = worst_error {
        fields.insert("worst_error_degrees".into(), json!(w));
    }
    if let Some(signal) = super::interrupt::requested() {
        fields.insert(
            "interrupted".into(),
            json!(format!(
                "{}: stopped after iteration {} of {}",
                super::interrupt::name(signal),
                result.iterations,
                opts.iterations
            )),
        );
    }
    let json = format!(
        "{}\n",
        serde_json::to_string_pretty(&json).expect("JSON of numbers")
    );
    let (w, h) = size;
    let render_png = ImageFormat::Png
        .encode(&result.image, w, h)
        .map_err(|e| Error::Input(format!("{}: {e}", render_path.display())))?;
    let sheet = report::side_by_side(
        &[
            ("target", &target),
            ("start", &start_image),
            ("result", &result.image),
        ],
        w,
        h,
    );
    let compare_png = encode_sheet_png(&sheet, &compare_path)?;
    let posed = rig.posed_mesh(&result.angles);
    // The OBJ first (it commits its own atomic file): if it fails, nothing has been written.
    io::write_obj_colored(
        &mesh_path,
        &posed.positions,
        posed.vertex_colors.as_deref(),
        &posed.faces,
    )?;
    out.commit(json.as_bytes())?;
    render_file.commit(&render_png)?;
    compare_file.commit(&compare_png)?;
    println!(
        "{} iterations in {:.1} s ({:.1} ms per iteration); loss {:.3e} → {:.3e}{}; wrote {}, \
         {}, {} and {}",
        result.iterations,
        result.seconds,
        1e3 * result.seconds / f64::from(result.iterations.max(1)),
        initial_loss,
        result.loss,
        worst_error.map_or(String::new(), |w| format!("; worst joint error {w:.2}°")),
        args.out.display(),
        render_path.display(),
        compare_path.display(),
        mesh_path.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angle_lists_are_finite_numbers() {
        assert_eq!(angle_list("1, -2.5,3").unwrap().0, vec![1.0, -2.5, 3.0]);
        assert!(angle_list("1,,2").is_err());
        assert!(angle_list("1,nan").is_err());
        assert!(angle_list("x").is_err());
    }
}
