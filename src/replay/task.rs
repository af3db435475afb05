//! The scene's teleoperation task (`[task]`): the paper's pouring experiment, run headless
//! (physics, mapping, simulated arm; no rendering) for every mode and trial, summarised under
//! `"object"` in `report.json` beside the paper's figures.

use std::collections::BTreeMap;

use avatarm_core::sim::SimRobotParams;
use avatarm_core::teleop::hand::HandNoise;
use avatarm_mapping::pouring::{
    ModeSummary, PUBLISHED, PaperFigures, PouringTask, TrialSetup, run_trials,
};
use serde::{Deserialize, Serialize};

use crate::AppError;

/// The report's `"object"` section: each mode's summary (under its name, `paper` or
/// `closed_loop`), the paper's figures beside them and the set-up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectReport {
    /// Each mode's trials and their mean and sample std, by the mode's name.
    #[serde(flatten)]
    pub modes: BTreeMap<String, ModeSummary>,
    /// The paper's figures (Table I).
    pub published: PaperFigures,
    /// How the trials were run.
    pub setup: TaskSetup,
}

/// How the task's trials were run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskSetup {
    /// Trials per mode.
    pub trials: u32,
    /// The task's seed.
    pub seed: u64,
    /// Each trial's length (s).
    pub duration_s: f64,
    /// The control rate (Hz).
    pub control_rate_hz: f64,
    /// The simulated arm's timing.
    pub robot_sim: SimRobotParams,
    /// The TCP speed cap (m/s).
    pub max_tcp_speed: f64,
    /// The closed loop's gain (1/s).
    pub closed_loop_gain: f64,
    /// Tremor and tracking noise.
    pub hand_noise: HandNoise,
    /// The twin's scale relative to the real bottle.
    pub k: f64,
    /// How to read the errors.
    pub note: String,
}

/// Runs every trial of the task and returns the report's `"object"` section.
pub fn object_report(task: &PouringTask, setup: &TrialSetup) -> Result<ObjectReport, AppError> {
    let total = task.modes.len() as u64 * u64::from(task.trials);
    let bar = crate::progress::bar(total, "pouring trials", true);
    let modes = run_trials(task, setup, |mode, trial| {
        bar.set_message(format!("{mode:?} trial {trial}"));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    Ok(ObjectReport {
        modes: modes
            .into_iter()
            .map(|(mode, summary)| (mode.name().to_owned(), summary))
            .collect(),
        published: PUBLISHED,
        setup: TaskSetup {
            trials: task.trials,
            seed: task.seed,
            duration_s: task.duration_s,
            control_rate_hz: setup.control_rate_hz,
            robot_sim: setup.sim,
            max_tcp_speed: task.max_tcp_speed,
            closed_loop_gain: task.gain,
            hand_noise: task.noise,
            k: task.k,
            note: "errors between the real bottle (simulation ground truth) and its twin mapped into the real world, from the moment the gripper closes to the end of the trial; mean and sample std over trials".into(),
        },
    })
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
            let m = &report.modes[mode];
            for (key, figure) in [
                ("pos_rmse_m", m.pos_rmse_m),
                ("roll_rmse_deg", m.roll_rmse_deg),
                ("pitch_rmse_deg", m.pitch_rmse_deg),
                ("yaw_rmse_deg", m.yaw_rmse_deg),
            ] {
                assert!(
                    figure.mean.is_finite() && figure.std.is_finite(),
                    "{mode} {key}"
                );
            }
            assert_eq!(m.trials.len(), 2);
        }
        // The section reads back as it was written.
        let text = serde_json::to_string(&report).expect("serialised");
        let back: ObjectReport = serde_json::from_str(&text).expect("read back");
        assert_eq!(back, report);
        // The paper's figures sit beside ours, every one of them, under their own keys.
        let json = serde_json::to_value(&report).expect("serialised");
        for (key, figure) in [
            ("pos_rmse_m", PUBLISHED.pos_rmse_m),
            ("roll_rmse_deg", PUBLISHED.roll_rmse_deg),
            ("pitch_rmse_deg", PUBLISHED.pitch_rmse_deg),
            ("yaw_rmse_deg", PUBLISHED.yaw_rmse_deg),
        ] {
            assert_eq!(json["published"][key]["mean"], figure.mean, "{key}");
            assert_eq!(json["published"][key]["std"], figure.std, "{key}");
        }
        assert!(json["paper"]["pos_rmse_m"]["mean"].is_number(), "{json}");
    }
}
