//! `avatarm replay`: a scene replayed without a window (each camera in turn), or with
//! `--recording` a recorded session through the erase; frames and `report.json` in `--out`.

use std::path::PathBuf;

use avatarm_scene::Scene;
use clap::Args;

use crate::AppError;
use crate::cli::args::packages;
use crate::cli::overrides::EraseOverrides;
use crate::replay::ReplayOptions;

/// The arguments of `avatarm replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// The scene file (not with --recording).
    #[arg(required_unless_present = "recording", conflicts_with = "recording")]
    scene: Option<PathBuf>,
    /// A recording (MCAP, `avatarm import` writes one): its frames and joint states through
    /// the erase, with the robot's --urdf.
    #[arg(long, value_name = "FILE.mcap", requires = "urdf")]
    recording: Option<PathBuf>,
    /// With --recording: the robot's description.
    #[arg(long, value_name = "URDF")]
    urdf: Option<PathBuf>,
    /// With --recording: a camera file instead of the recording's calibration (ROS
    /// camera_info or OpenCV YAML, or a 3x3 K).
    #[arg(long, value_name = "FILE")]
    camera: Option<PathBuf>,
    /// With --recording: a pose file instead of the recording's camera pose (under
    /// camera_from_base or base_from_camera).
    #[arg(long, value_name = "FILE")]
    pose: Option<PathBuf>,
    /// With --recording and no --background: pixels this far beyond a frame's mask are not
    /// used for the background built from the footage (px).
    #[arg(long = "background-margin", value_name = "PX", default_value_t = 8)]
    background_margin: u32,
    /// With --recording of a camera on a head (Alice's): the scene file of its room, whose
    /// boxes that are not objects (desk, wall, floor) are the proxy that a view-following
    /// background re-projects the frames' views through, so that H follows the head (the
    /// footage's median is then only the fallback where no view saw a pixel).
    #[arg(long, value_name = "SCENE", requires = "recording")]
    room: Option<PathBuf>,
    /// With --recording: refine the mask's margin band to each frame (on the CPU; on by
    /// default): the band's pixels that look like the background H (within 30 levels) are
    /// given back to the frame, those that differ and touch the robot's core stay erased.
    #[arg(long = "refine-edges", value_name = "on|off", value_parser = crate::cli::overrides::on_off, requires = "recording")]
    refine_edges: Option<bool>,
    /// With a scene: replay only its camera NAME (one of its [[cameras]]; default: each
    /// camera in turn, into DIR/NAME/).
    #[arg(long, value_name = "NAME", conflicts_with = "recording")]
    view: Option<String>,
    /// With a scene: also write the replay as a recording (MCAP): the frames, the robot's
    /// joints at each capture, the believed camera, the true silhouettes as reference
    /// masks, Avatarm's erased frames and masks.
    #[arg(long, value_name = "FILE.mcap", conflicts_with = "recording")]
    record: Option<PathBuf>,
    /// Run without a window (replays are always headless; accepted for clarity).
    #[arg(long)]
    headless: bool,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Save every N-th camera frame.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    frames_every: u32,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
    #[command(flatten)]
    overrides: EraseOverrides,
}

impl ReplayArgs {
    /// Runs `avatarm replay`.
    pub fn run(self) -> Result<(), AppError> {
        match self {
            Self {
                recording: Some(recording),
                urdf: Some(urdf),
                camera,
                pose,
                background_margin,
                room,
                refine_edges,
                out,
                package_path,
                overrides,
                ..
            } => {
                let mut settings = avatarm_core::dr::EraseSettings::default();
                overrides.apply_to_settings(&mut settings)?;
                let report = crate::replay::recording::run_recording(
                    &crate::replay::recording::RecordingOptions {
                        recording,
                        urdf,
                        packages: packages(package_path),
                        camera,
                        pose,
                        mount: overrides.believed_mount.clone(),
                        settings,
                        dilate_from: if overrides.dilate.is_some() {
                            crate::replay::recording::DilateFrom::Flag
                        } else {
                            crate::replay::recording::DilateFrom::Default
                        },
                        background: overrides.background.clone(),
                        background_margin_px: background_margin,
                        room,
                        drift: settings
                            .drift_watch
                            .then(avatarm_footage::drift::DriftSettings::default),
                        refine_edges: refine_edges.unwrap_or(true),
                        out: out.clone(),
                        progress: true,
                    },
                )?;
                if let Some(d) = &report.drift {
                    eprintln!("drift watch: {}", d.note);
                    for r in &d.refits {
                        eprintln!(
                            "  the camera moved by frame {} (first seen at frame {}: the robot's outline {:.0},{:.0} px off): fitted again on frames {:?} ({:.2} deg, {:.1} mm from the pose before, {:.1} s), used from frame {}",
                            r.detected_frame,
                            r.first_beyond_frame,
                            r.shift_px[0],
                            r.shift_px[1],
                            r.frames,
                            r.moved_deg,
                            r.moved_mm,
                            r.refit_s,
                            r.detected_frame
                        );
                    }
                }
                let vs = &report.mask.vs_reference;
                eprintln!(
                    "replayed {}: {} frames of '{}', mask covering {:.1} % of the frame; against {} reference masks: IoU {}, leak {} %; background: {}; report: {}",
                    report.recording,
                    report.frames,
                    report.robot,
                    report.mask.coverage_pct_mean.unwrap_or(f64::NAN),
                    vs.frames_scored,
                    vs.iou_mean.map_or("-".into(), |v| format!("{v:.3}")),
                    vs.leak_pct_mean.map_or("-".into(), |v| format!("{v:.2}")),
                    report.background.source.as_deref().unwrap_or("none"),
                    out.join("report.json").display()
                );
                Ok(())
            }
            Self {
                scene,
                headless: _,
                out,
                frames_every,
                package_path,
                overrides,
                record,
                view,
                ..
            } => {
                let path =
                    scene.ok_or_else(|| AppError::flag("replay", "give a scene or --recording"))?;
                let packages = packages(package_path);
                let mut scene = Scene::load_view(&path, &packages, view.as_deref())?;
                overrides.apply(&mut scene)?;
                let mut options = ReplayOptions::new(out.clone());
                options.frames_every = frames_every;
                options.progress = true;
                options.record = record;
                if view.is_none() && scene.cameras.len() > 1 {
                    // Each camera in turn.
                    let others = scene.cameras[1..].to_vec();
                    let mut scenes = vec![scene];
                    for name in others {
                        let mut other = Scene::load_view(&path, &packages, Some(&name))?;
                        overrides.apply(&mut other)?;
                        scenes.push(other);
                    }
                    let report = crate::replay::run_views(&scenes, options)?;
                    for camera in &report.cameras {
                        eprintln!(
                            "camera '{}': {} frames, mask IoU {}, leak {} %, PSNR in the robot's region {} dB",
                            camera.camera.name,
                            camera.frames,
                            camera
                                .mask
                                .iou_mean
                                .map_or("-".into(), |v| format!("{v:.3}")),
                            camera
                                .mask
                                .leak_pct_mean
                                .map_or("-".into(), |v| format!("{v:.2}")),
                            camera
                                .dr
                                .psnr_robot_db_mean
                                .map_or("-".into(), |v| format!("{v:.1}")),
                        );
                    }
                    eprintln!(
                        "replayed '{}' through {} cameras; report: {}",
                        scenes[0].file.name,
                        scenes.len(),
                        out.join("report.json").display()
                    );
                    return Ok(());
                }
                let report = crate::replay::run(&scene, options)?;
                eprintln!(
                    "replayed '{}': {} frames, {:.2} s simulated in {:.2} s ({:.2} sim s per wall s); report: {}",
                    scene.file.name,
                    report.frames,
                    report.sim_time_s,
                    report.wall_time_s,
                    report.sim_s_per_wall_s,
                    out.join("report.json").display()
                );
                Ok(())
            }
        }
    }
}
