//! `angles.json` of a finished articulated fit.

use serde_json::{Value, json};
use softvk::fit::articulated::{ArticulatedFitOptions, ArticulatedFitResult};
use softvk::fit::rig::Rig;

use crate::cli::fit_pose::schedule_json;
use crate::cli::session::interrupted;

/// `angles.json`: per joint its name, fitted angle and start (with `target_angles`, the
/// target and the error; all in degrees), then the losses, the iterations, the options and the
/// wall time; and the worst joint error (degrees), where the target's angles are known.
pub fn angles_json(
    rig: &Rig,
    init: &[f64],
    target_angles: Option<&[f64]>,
    opts: &ArticulatedFitOptions,
    result: &ArticulatedFitResult,
) -> (String, Option<f64>) {
    let degrees = |a: &[f64]| a.iter().map(|x| x.to_degrees()).collect::<Vec<_>>();
    let errors = target_angles.map(|t| {
        let e: Vec<f64> = result.angles.iter().zip(t).map(|(a, b)| a - b).collect();
        (degrees(t), degrees(&e))
    });
    let (fitted, start) = (degrees(&result.angles), degrees(init));
    let joints: Vec<Value> = (0..rig.joint_count())
        .map(|j| {
            let name = &rig.joints[j].name;
            let mut o = json!({"name": name, "angle_degrees": fitted[j], "init_degrees": start[j]});
            if let Some((t, e)) = &errors {
                o["target_degrees"] = json!(t[j]);
                o["error_degrees"] = json!(e[j]);
            }
            o
        })
        .collect();
    let initial_loss = result.log.first().map_or(f64::NAN, |l| l.loss);
    let mut json = json!({
        "rig": "figure",
        "convention": "each joint turns its bones by its angle about its axis through its pivot \
                       (right-handed, degrees); 0 is the rest pose",
        "joints": joints,
        "initial_loss": initial_loss,
        "loss": result.loss,
        "iterations": result.iterations,
        "target": if errors.is_some() { "rendered per stage from --target-angles" }
                  else { "image" },
        "sigma": opts.settings.sigma,
        "gamma": opts.settings.gamma,
        "schedule": schedule_json(opts.schedule.as_ref()),
        "blur": opts.blur.as_ref().map_or(Value::Null, |b| {
            json!({"start_pixels": b.start, "stages": b.stages})
        }),
        "seconds": result.seconds,
    });
    let worst = errors.map(|(_, e)| e.iter().fold(0.0, |w: f64, x| w.max(x.abs())));
    if let Some(w) = worst {
        json["worst_error_degrees"] = json!(w);
    }
    if let Some(note) = interrupted(result.iterations, opts.iterations) {
        json["interrupted"] = json!(note);
    }
    let json = format!(
        "{}\n",
        serde_json::to_string_pretty(&json).expect("JSON of numbers")
    );
    (json, worst)
}
