//! `avatarm calibrate`: the camera's pose (or a head camera's mount) fitted to the robot
//! itself: its silhouettes, the frames' difference from an empty room, or their edges.

use std::path::PathBuf;

use clap::Args;

use crate::AppError;
use crate::cli::args::{frame_range, list, packages};

/// The arguments of `avatarm calibrate`.
#[derive(Args, Debug)]
pub struct CalibrateArgs {
    /// The recording (MCAP): frames, joint states, and the robot's reference masks if any.
    #[arg(long, value_name = "FILE.mcap")]
    recording: PathBuf,
    /// The robot's description.
    #[arg(long, value_name = "URDF")]
    urdf: PathBuf,
    /// Folder searched for package:// URIs (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    package_path: Vec<PathBuf>,
    /// A camera file instead of the recording's calibration.
    #[arg(long, value_name = "FILE")]
    camera: Option<PathBuf>,
    /// The rough pose (under camera_from_base or base_from_camera), else the recording's.
    #[arg(long, value_name = "FILE", conflicts_with = "look_at")]
    pose: Option<PathBuf>,
    /// A recording of a camera on a head: the rough mount (under head_from_camera or
    /// camera_from_head), else the recording's; the fit is then of the mount.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["pose", "look_at"])]
    mount: Option<PathBuf>,
    /// The rough pose as the camera's eye and a point it looks at, in the base frame (m):
    /// EX,EY,EZ,TX,TY,TZ.
    #[arg(
        long = "look-at",
        value_name = "EX,EY,EZ,TX,TY,TZ",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    look_at: Option<Vec<f64>>,
    /// The frames the fit uses: FIRST-LAST ranges or single indices, comma-separated (indices
    /// in the recording, e.g. 0-4 or 0,1,5; the others are held out and only measured).
    /// Default: every frame with a silhouette (a reference mask, or with --background or
    /// --edges every frame).
    #[arg(long, value_name = "FRAMES", value_parser = frame_range, value_delimiter = ',')]
    fit: Vec<(usize, usize)>,
    /// Use only every N-th frame with a silhouette (long recordings).
    #[arg(long, value_name = "N", default_value_t = 1)]
    every: usize,
    /// Keep the fit's frames that the pairing check finds mispaired (another frame's joints
    /// explain their reference mask better than their own); by default the pose is fitted
    /// again without them while at least two frames remain.
    #[arg(long = "keep-mispaired")]
    keep_mispaired: bool,
    /// Also fit the focal lengths fx and fy.
    #[arg(long)]
    intrinsics: bool,
    /// Triangles the robot's silhouette is drawn with (its meshes simplified to about this).
    #[arg(long, value_name = "N", default_value_t = 6000)]
    triangles: usize,
    /// The robot's geometry below this height in its base frame (m) is hidden by the table
    /// it stands on and left out of its silhouette (e.g. 0 for a mounting plate sunk in the
    /// desk).
    #[arg(long = "hidden-below", value_name = "Z", allow_negative_numbers = true)]
    hidden_below: Option<f64>,
    /// An empty-room photograph of the same camera (no robot): the robot's silhouettes
    /// are each frame's difference from it, instead of the recording's reference masks.
    #[arg(long, value_name = "IMAGE")]
    background: Option<PathBuf>,
    /// With --background: the difference (8-bit levels, any channel) that counts as the
    /// robot.
    #[arg(
        long = "background-threshold",
        value_name = "LEVELS",
        default_value_t = 30
    )]
    background_threshold: u8,
    /// Fit to each frame's own image edges (Canny's) instead of silhouettes: no reference
    /// masks or empty-room photograph needed (a moving camera's footage). Reference masks,
    /// where the recording has them, only score the fit.
    #[arg(long, conflicts_with = "background")]
    edges: bool,
    /// With --edges: Canny's LOW,HIGH thresholds on the Sobel gradient's magnitude of the
    /// blurred luma (imageproc's scale: a clean step of N 8-bit levels gives about 2N to
    /// 4N; at most 1141). Each frame's edge map is written to `edges_NNNNN.png`
    /// and drawn in yellow on the overlays, to tune them by eye.
    #[arg(
        long = "edge-thresholds",
        requires = "edges",
        value_name = "LOW,HIGH",
        value_delimiter = ',',
        default_value = "20,60"
    )]
    edge_thresholds: Vec<f32>,
    /// Output folder.
    #[arg(long, value_name = "DIR", default_value = "out/calibrate")]
    out: PathBuf,
}

impl CalibrateArgs {
    /// Runs `avatarm calibrate`.
    pub fn run(self) -> Result<(), AppError> {
        let Self {
            recording,
            urdf,
            package_path,
            camera,
            pose,
            look_at,
            mount,
            fit,
            every,
            intrinsics,
            keep_mispaired,
            triangles,
            hidden_below,
            background,
            background_threshold,
            edges,
            edge_thresholds,
            out,
        } = self;
        let edges = match (edges, edge_thresholds.as_slice()) {
            (false, _) => None,
            (true, &[low, high]) => Some((low, high)),
            (true, v) => {
                return Err(AppError::flag(
                    "--edge-thresholds",
                    format!("{} given: give two numbers, LOW,HIGH", list(v)),
                ));
            }
        };
        if let Some(z) = hidden_below.filter(|z| !z.is_finite()) {
            return Err(AppError::flag(
                "--hidden-below",
                format!("{z} is not a height (m)"),
            ));
        }
        let look_at = match look_at.as_deref() {
            None => None,
            Some(v) if v.iter().any(|x| !x.is_finite()) => {
                return Err(AppError::flag(
                    "--look-at",
                    format!("{v:?}: every coordinate must be a finite number (m)"),
                ));
            }
            Some([ex, ey, ez, tx, ty, tz]) => Some(([*ex, *ey, *ez], [*tx, *ty, *tz])),
            Some(v) => {
                return Err(AppError::flag(
                    "--look-at",
                    format!(
                        "{} given: give six numbers, the eye's x,y,z then the target's",
                        list(v)
                    ),
                ));
            }
        };
        let options = avatarm_footage::calibrate::CalibrateOptions {
            recording,
            urdf,
            packages: packages(package_path),
            camera,
            pose,
            look_at,
            mount,
            fit,
            every,
            fit_focal: intrinsics,
            keep_mispaired,
            budget: triangles.max(100),
            hidden_below,
            background,
            background_threshold,
            edges,
            out: out.clone(),
        };
        let bar = crate::progress::bar(1, "calibrate", true);
        let report = avatarm_footage::calibrate::run(&options, |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        bar.finish_and_clear();
        for note in &report.notes {
            eprintln!("note: {note}");
        }
        let iou = &report.iou;
        let f =
            |v: Option<f64>| v.map_or("- (no reference mask)".to_owned(), |x| format!("{x:.3}"));
        println!(
            "calibrated on {} frames in {:.1} s: IoU {} -> {} on the fit frames, {} -> {} held out; moved {:.2} deg, {:.1} mm from the rough pose; spread over starts {:.2} deg, {:.1} mm",
            report.frames_fit,
            report.wall_time_s,
            f(iou.fit_before),
            f(iou.fit_after),
            f(iou.held_out_before),
            f(iou.held_out_after),
            report.change_from_rough.rotation_deg,
            report.change_from_rough.translation_mm,
            report.uncertainty.spread_deg,
            report.uncertainty.spread_mm,
        );
        println!(
            "{}: {}; report: {}",
            if report.head_from_camera.is_some() {
                "mount"
            } else {
                "pose"
            },
            report.outputs.pose,
            out.join("report.json").display()
        );
        if let Some(mount) = &report.head_from_camera {
            let v = |xs: &[f64; 3]| {
                xs.iter()
                    .map(|x| format!("{x:.6}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            println!(
                "in the scene: [camera.head] mount = {{ xyz = [{}], rpy = [{}] }}",
                v(&mount.translation),
                v(&mount.rpy)
            );
        }
        Ok(())
    }
}
