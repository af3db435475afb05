//! `avatarm import`: a real Leap Motion recording (leapjs-playback JSON, Leap's protocol v6) to
//! a `.hand.jsonl` of Avatarm's 26-joint skeleton (docs/hand.md), and a picture of one frame:
//! the skeleton drawn over the joints as Leap recorded them.

use std::path::{Path, PathBuf};

use avatarm_core::teleop::hand::{HandFrame, Handedness, write_frames};
use avatarm_hand::leap::LeapMount;
use avatarm_hand::leap_recording::LeapRecording;
use nalgebra::{Isometry3, Vector3};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::AppError;
use crate::bench::chart::{Chart, axes, drawing_error, legend, padded, save_chart};

/// What `avatarm import` does.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// The Leap recording (`.json` or `.json.gz`).
    pub recording: PathBuf,
    /// The `.hand.jsonl` to write.
    pub out: PathBuf,
    /// Which hand (default: the first one the recording shows).
    pub hand: Option<Handedness>,
    /// The device on a headset ([`LeapMount::head`]) rather than lying on the desk
    /// ([`LeapMount::desk`]).
    pub head_mounted: bool,
    /// Where the Leap device sits in the scene (m).
    pub device_at: [f64; 3],
    /// A picture of one frame (PNG; an SVG is written beside it).
    pub picture: Option<PathBuf>,
    /// The frame pictured (index among the chosen hand's frames).
    pub frame: usize,
}

/// What was written.
#[derive(Debug, Clone)]
pub struct ImportSummary {
    /// Frames of the chosen hand.
    pub frames: usize,
    /// Their span (s).
    pub duration_s: f64,
    /// The hand.
    pub hand: Handedness,
    /// The picture, when one was asked for.
    pub picture: Option<(PathBuf, PathBuf)>,
}

/// Converts the recording and writes the skeleton, and the picture when asked.
pub fn import_leap(options: &ImportOptions) -> Result<ImportSummary, AppError> {
    let recording = LeapRecording::open(&options.recording)?;
    let [x, y, z] = options.device_at;
    if ![x, y, z].iter().all(|v| v.is_finite()) {
        return Err(AppError::flag(
            "--device-at",
            format!("{x},{y},{z} is not three finite numbers"),
        ));
    }
    let rotation = if options.head_mounted {
        LeapMount::head()
    } else {
        LeapMount::desk()
    };
    let mount = LeapMount::placed(rotation, Vector3::new(x, y, z));
    let frames = recording.hand_frames(options.hand, &mount)?;
    let hand = frames[0].hand;
    std::fs::write(&options.out, write_frames(&frames))
        .map_err(|e| AppError::write(&options.out, e))?;
    let picture = match &options.picture {
        None => None,
        Some(png) => Some(draw_frame(&recording, hand, options.frame, png)?),
    };
    Ok(ImportSummary {
        frames: frames.len(),
        duration_s: frames[frames.len() - 1].t_s - frames[0].t_s,
        hand,
        picture,
    })
}

/// The joints drawn as chains: the wrist to each finger's tip (OpenXR joint order).
const CHAINS: [&[usize]; 5] = [
    &[1, 2, 3, 4, 5],
    &[1, 6, 7, 8, 9, 10],
    &[1, 11, 12, 13, 14, 15],
    &[1, 16, 17, 18, 19, 20],
    &[1, 21, 22, 23, 24, 25],
];

struct FramePicture {
    title: String,
    /// The converted skeleton's joints, Leap frame (mm).
    skeleton: Vec<[f64; 3]>,
    /// The joints as recorded, Leap frame (mm).
    recorded: Vec<[f64; 3]>,
}

/// Draws frame `index` of `hand`: front (Leap x, y) and side (Leap z, y) views.
fn draw_frame(
    recording: &LeapRecording,
    hand: Handedness,
    index: usize,
    png: &Path,
) -> Result<(PathBuf, PathBuf), AppError> {
    let with_hand: Vec<(usize, usize)> = recording
        .frames
        .iter()
        .enumerate()
        .filter_map(|(i, f)| {
            f.hands
                .iter()
                .position(|(_, h)| h.hand == hand)
                .map(|k| (i, k))
        })
        .collect();
    let &(i, k) = with_hand.get(index).ok_or_else(|| {
        AppError::flag(
            "--frame",
            format!("{index}: the hand is in {} frames", with_hand.len()),
        )
    })?;
    let f = &recording.frames[i];
    // The skeleton in Leap's own axes: a mount without rotation, back to millimetres.
    let identity = LeapMount {
        scene_from_leap: Isometry3::identity(),
    };
    let frame: HandFrame = avatarm_hand::leap::leap_frame(&f.hands[k].1, &identity, f.t_s)?;
    let mm = |v: nalgebra::Vector3<f64>| [v.x * 1e3, v.y * 1e3, v.z * 1e3];
    let picture = FramePicture {
        title: format!(
            "{} frame {index} (t = {:.3} s): Avatarm's skeleton over the recorded joints",
            recording
                .path
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
            f.t_s
        ),
        skeleton: frame
            .joints
            .iter()
            .map(|j| mm(j.pose.translation.vector))
            .collect(),
        recorded: f.recorded_joints[k]
            .iter()
            .map(|p| [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])])
            .collect(),
    };
    let svg = png.with_extension("svg");
    save_chart(&picture, (1200, 620), &svg, png)?;
    Ok((png.to_owned(), svg))
}

impl Chart for FramePicture {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(&self.title, ("sans-serif", 20)).map_err(err)?;
        let (left, right) = root.split_horizontally(600);
        self.view(&left, 0, "Leap x (mm, to the user's right)")?;
        self.view(&right, 2, "Leap z (mm, toward the user)")?;
        root.present().map_err(err)
    }
}

impl FramePicture {
    /// One view: horizontal axis `h` (0 = x, 2 = z) against Leap y (up), equal scales.
    fn view<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        h: usize,
        x_desc: &str,
    ) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        let all = || self.skeleton.iter().chain(&self.recorded);
        let (x0, x1) = padded(all().map(|p| p[h]));
        let (y0, y1) = padded(all().map(|p| p[1]));
        // The same millimetres per pixel on both axes.
        let half = (x1 - x0).max(y1 - y0) / 2.0;
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let mut chart = axes(
            area,
            (cx - half, cx + half),
            (cy - half, cy + half),
            x_desc,
            "Leap y (mm, up)",
        )?;
        let blue = RGBColor(30, 90, 200);
        for (c, chain) in CHAINS.iter().enumerate() {
            let series = chart
                .draw_series(LineSeries::new(
                    chain
                        .iter()
                        .map(|&j| (self.skeleton[j][h], self.skeleton[j][1])),
                    blue.stroke_width(3),
                ))
                .map_err(err)?;
            if c == 0 {
                series
                    .label("Avatarm skeleton (26 joints)")
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], blue.stroke_width(3))
                    });
            }
        }
        chart
            .draw_series(
                self.skeleton
                    .iter()
                    .map(|p| Circle::new((p[h], p[1]), 3, blue.filled())),
            )
            .map_err(err)?;
        let orange = RGBColor(230, 120, 20);
        chart
            .draw_series(
                self.recorded
                    .iter()
                    .map(|p| Circle::new((p[h], p[1]), 7, orange.stroke_width(2))),
            )
            .map_err(err)?
            .label("recorded by the Leap (palm, knuckles, joints, tips)")
            .legend(move |(x, y)| Circle::new((x + 9, y), 6, orange.stroke_width(2)));
        legend(&mut chart, SeriesLabelPosition::LowerRight)
    }
}
