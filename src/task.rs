//! The scene's teleoperation task (`[task]`): the paper's pouring experiment, run headless
//! (physics, mapping, simulated arm; no rendering) for every mode and trial, summarised under
//! `"object"` in `report.json` beside the paper's figures.

use std::sync::Arc;

use avatarm_mapping::pouring::{PUBLISHED, PouringTask, TrialSetup, run_trials};
use avatarm_sim::PropShape;
use serde_json::json;

use crate::scene::Scene;

/// The real side of the task from the scene: robot, tool link, arm joints, the bottle.
pub fn trial_setup(scene: &Scene, task: &PouringTask) -> Result<TrialSetup, String> {
    let model = Arc::clone(&scene.model);
    let tcp = model
        .link_id(&task.tcp_link)
        .map_err(|e| format!("task.tcp_link: {e}"))?;
    let arm: Vec<usize> = if task.arm_joints.is_empty() {
        model
            .dof_names()
            .iter()
            .enumerate()
            .filter(|(_, n)| !n.contains("finger"))
            .map(|(i, _)| i)
            .collect()
    } else {
        task.arm_joints
            .iter()
            .map(|n| {
                model
                    .dof_index(n)
                    .map_err(|e| format!("task.arm_joints: {e}"))
            })
            .collect::<Result<_, _>>()?
    };
    let prop = scene
        .props
        .iter()
        .find(|p| p.name == task.object)
        .ok_or_else(|| format!("task.object: no prop named '{}' in the scene", task.object))?;
    let (radius, height) = match prop.shape {
        PropShape::Bottle { radius, height } | PropShape::Cylinder { radius, height } => {
            (radius, height)
        }
        _ => {
            return Err(format!(
                "task.object '{}': the pouring task needs a bottle or cylinder prop",
                task.object
            ));
        }
    };
    Ok(TrialSetup {
        model,
        base: scene.robot_base(),
        q_start: scene.q0.clone(),
        tcp,
        arm,
        sim: scene.file.robot.sim,
        control_rate_hz: scene.file.control_rate_hz,
        bottle_base: prop.pose,
        bottle_radius_m: radius,
        bottle_height_m: height,
    })
}

/// Runs every trial of the task and returns the report's `"object"` section.
pub fn object_report(scene: &Scene, task: &PouringTask) -> Result<serde_json::Value, String> {
    let setup = trial_setup(scene, task)?;
    let total = task.modes.len() as u64 * u64::from(task.trials);
    let bar = indicatif::ProgressBar::new(total);
    let modes = run_trials(task, &setup, |mode, trial| {
        bar.set_message(format!("{mode:?} trial {trial}"));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let mut out = serde_json::Map::new();
    for (mode, summary) in modes {
        out.insert(
            mode.name().to_owned(),
            serde_json::to_value(summary).map_err(|e| e.to_string())?,
        );
    }
    out.insert(
        "published".into(),
        serde_json::to_value(PUBLISHED).map_err(|e| e.to_string())?,
    );
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
        let report = object_report(&scene, &task).expect("trials");
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
        assert_eq!(report["published"]["pos_rmse_m"]["mean"], 0.0173);
        let bad = PouringTask {
            object: "glass?".into(),
            ..task
        };
        let err = object_report(&scene, &bad).expect_err("no such prop");
        assert!(err.contains("task.object"), "{err}");
    }
}
