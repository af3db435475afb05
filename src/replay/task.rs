//! The scene's teleoperation task (`[task]`): the paper's pouring experiment, run headless
//! (physics, mapping, simulated arm; no rendering) for every mode and trial, summarised under
//! `"object"` in `report.json` beside the paper's figures.

use avatarm_mapping::pouring::{PUBLISHED, PouringTask, TrialSetup, run_trials};
use serde_json::json;

use crate::AppError;

/// Runs every trial of the task and returns the report's `"object"` section.
pub fn object_report(
    task: &PouringTask,
    setup: &TrialSetup,
) -> Result<serde_json::Value, AppError> {
    let total = task.modes.len() as u64 * u64::from(task.trials);
    let bar = crate::progress::bar(total, "pouring trials", true);
    let modes = run_trials(task, setup, |mode, trial| {
        bar.set_message(format!("{mode:?} trial {trial}"));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let mut out = serde_json::Map::new();
    for (mode, summary) in modes {
        out.insert(mode.name().to_owned(), serde_json::to_value(summary)?);
    }
    out.insert("published".into(), serde_json::to_value(PUBLISHED)?);
    out.insert(
        "setup".into(),
        json!({
            "trials": task.trials,
            "seed": task.seed,
            "duration_s": task.duration_s,
            "control_rate_hz": setup.control_rate_hz,
            "robot_sim": setup.sim,
            "max_tcp_speed": task.max_tcp_speed,
            "closed_loop_gain": task.gain,
            "hand_noise": task.noise,
            "k": task.k,
            "note": "errors between the real bottle (simulation ground truth) and its twin mapped into the real world, from the moment the gripper closes to the end of the trial; mean and sample std over trials",
        }),
    );
    Ok(serde_json::Value::Object(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use avatarm_core::robot::PackagePath;
    use avatarm_scene::Scene;

    #[test]
    fn the_pouring_scene_reports_both_modes_beside_the_paper() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/pouring.toml");
        let scene = Scene::load(&path, &PackagePath::default()).expect("scene");
        let task = PouringTask {
            trials: 2,
            duration_s: 4.0,
            ..scene.file.task.clone().expect("[task]")
        };
        let setup = scene.trial.as_ref().expect("the task's set-up");
        let report = object_report(&task, setup).expect("trials");
        for mode in ["paper", "closed_loop"] {
            let m = &report[mode];
            for key in [
                "pos_rmse_m",
                "roll_rmse_deg",
                "pitch_rmse_deg",
                "yaw_rmse_deg",
            ] {
                assert!(
                    m[key]["mean"].as_f64().is_some_and(f64::is_finite),
                    "{mode} {key}"
                );
                assert!(m[key]["std"].as_f64().is_some(), "{mode} {key}");
            }
            assert_eq!(m["trials"].as_array().map(Vec::len), Some(2));
        }
        // The paper's figures sit beside ours, every one of them.
        for (key, figure) in [
            ("pos_rmse_m", PUBLISHED.pos_rmse_m),
            ("roll_rmse_deg", PUBLISHED.roll_rmse_deg),
            ("pitch_rmse_deg", PUBLISHED.pitch_rmse_deg),
            ("yaw_rmse_deg", PUBLISHED.yaw_rmse_deg),
        ] {
            assert_eq!(report["published"][key]["mean"], figure.mean, "{key}");
            assert_eq!(report["published"][key]["std"], figure.std, "{key}");
        }
    }
}
