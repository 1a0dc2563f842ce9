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

use softvk::fit::articulated::{ArticulatedFit, ArticulatedLog, fit_articulated};
use softvk::fit::pose::PoseTarget;
use softvk::fit::rig::Rig;
use softvk::gpu::{Context, ContextOptions};
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::{Result, io};

use crate::cli::output::{encode_compare, encode_png};
use crate::cli::session::summary;

mod args;
mod report;
pub use args::*;
use report::angles_json;

/// Runs `softvk fit-articulated`.
pub fn run(args: &FitArticulatedArgs) -> Result<()> {
    let rig = Rig::figure();
    let (init, target_angles) = args.angles(&rig)?;
    let (size, image_target) = args.size_and_target()?;
    let (camera, lighting, opts) = (
        args.view.camera()?,
        args.raster.lighting(),
        args.options(size)?,
    );
    let (outputs, mesh_path) = args.outputs()?;

    let ctx = Context::new(&ContextOptions::from_env())?;
    let renderer = Renderer::new(&ctx)?;
    let render_at = |angles: &[f64], s: &RasterSettings| -> Result<Vec<[f32; 4]>> {
        let mesh = rig.posed_mesh(angles);
        let views = renderer.render_views(
            &ctx,
            &mesh,
            &[camera],
            &lighting,
            s,
            Method::Tiled { tile: opts.tile },
        )?;
        Ok(views.images)
    };
    // The sharp target (for the picture and the final loss), in the checkpoint's inputs.
    let target = match (image_target, &target_angles) {
        (Some(t), _) => t,
        (None, Some(a)) => render_at(a, &opts.settings)?,
        (None, None) => unreachable!("clap requires --target or --target-angles"),
    };
    let fingerprint = ArticulatedFit::fingerprint(&rig, &camera, &lighting, &target, &init, &opts);
    let (session, watch) = args.checkpoints.watched(
        CHECKPOINT_FILE,
        fingerprint,
        args.quiet,
        opts.iterations,
        |l: &ArticulatedLog| {
            format!(
                "loss {:.5}  σ {:.0e}  blur {:.1} px",
                l.loss, l.sigma, l.blur
            )
        },
    )?;
    let mut per_stage = |sigma, gamma| {
        render_at(
            target_angles.as_deref().expect("with --target-angles"),
            &RasterSettings {
                sigma,
                gamma,
                ..opts.settings
            },
        )
    };
    let fit_target = match target_angles {
        Some(_) => PoseTarget::PerStage(&mut per_stage),
        None => PoseTarget::Fixed(&target),
    };
    let result = fit_articulated(
        &ctx, &rig, &camera, &lighting, fit_target, &init, &opts, session,
    )?;
    watch.finish();
    let start_image = render_at(&init, &opts.settings)?;
    ctx.check_validation()?;

    let (json, worst) = angles_json(&rig, &init, target_angles.as_deref(), &opts, &result);
    let [out, render_path, compare_path] = [0, 1, 2].map(|i| outputs.paths[i].clone());
    let render = encode_png(&result.image, size, &render_path)?;
    let sheet = [
        ("target", &target),
        ("start", &start_image),
        ("result", &result.image),
    ];
    let compare = encode_compare(&sheet, size, &compare_path)?;
    // The OBJ first (it commits its own atomic file): if it fails, nothing has been written.
    let posed = rig.posed_mesh(&result.angles);
    io::write_obj_colored(
        &mesh_path,
        &posed.positions,
        posed.vertex_colors.as_deref(),
        &posed.faces,
    )?;
    outputs.commit(&[json.as_bytes(), &render, &compare])?;
    let initial_loss = result.log.first().map_or(f64::NAN, |l| l.loss);
    let what = format!(
        "; loss {initial_loss:.3e} → {:.3e}{}",
        result.loss,
        worst.map_or(String::new(), |w| format!("; worst joint error {w:.2}°"))
    );
    let wrote = [out.as_path(), &render_path, &compare_path, &mesh_path];
    let (first, done) = (result.first_iteration, result.iterations);
    println!("{}", summary(first, done, result.seconds, &what, &wrote));
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
