//! The arm's rim and the region no frame showed, through the README's chain (`replay
//! --record` -> `calibrate --edges` -> `replay --recording`, no hand-set flag), where the
//! simulated room knows the truth.

use avatarm_core::dr::{self, HoleFill};

use super::*;

/// The pixels of an RGB(A) PNG as RGB.
fn rgb(path: &Path) -> (Vec<[u8; 3]>, u32, u32) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    let (w, h) = img.dimensions();
    (img.pixels().map(|p| p.0).collect(), w, h)
}

fn rgba(rgb: &[[u8; 3]]) -> Vec<u8> {
    rgb.iter().flat_map(|p| [p[0], p[1], p[2], 255]).collect()
}

/// The default room's camera believed 0.5 deg and 5 mm off (the calibration-error scene,
/// no dilation), recorded. Replayed as it is, the erased frames keep a rim of the arm, and
/// the rim the report measures without a reference (robot-coloured pixels left in a 6 px
/// ring) matches the reference masks' count within a point. Calibrated from its own frames'
/// edges and replayed with the pose the calibration wrote and no other flag: the margin it
/// wrote is used, the band it opens is refined to each frame, and neither the leak nor the
/// rim is left; the refinement gives back overmasked pixels without leaking. The region no
/// frame showed is filled by Telea's method closer to the empty room than ring by ring.
#[test]
fn a_camera_half_a_degree_off_loses_its_rim_through_the_readme_s_chain() {
    let out = out_dir("rim");
    let urdf = root().join("assets/robots/sawyer_lite/sawyer_lite.urdf");
    let urdf_arg = urdf.to_str().expect("utf-8");
    let text = std::fs::read_to_string(root().join("assets/scenes/calibration_error.toml"))
        .expect("scene")
        .replace("../robots/sawyer_lite/sawyer_lite.urdf", urdf_arg)
        .replace("rotation_deg = 1.0", "rotation_deg = 0.5")
        .replace("dilate_px = 8", "dilate_px = 0");
    assert!(text.contains("rotation_deg = 0.5") && text.contains("dilate_px = 0"));
    let (_, recording, _) = record_scene(&out, &text);
    // As recorded: a rim, measured alike with and without the reference masks.
    let before = replay_recording(
        &recording,
        urdf_arg,
        &out.join("before"),
        &["--dilate", "0"],
    );
    let rim = |r: &RecordingReport| r.mask.rim.clone().expect("a rim measured");
    let (rim_before, leak_before) = (rim(&before), before.mask.vs_reference.leak_pct_mean);
    eprintln!(
        "believed pose, no dilation: leak {leak_before:?} %, rim {:?} % (reference: {:?} %)",
        rim_before.rim_pct_mean, rim_before.truth_pct_mean
    );
    let (est, truth) = (
        rim_before.rim_pct_mean.expect("rim"),
        rim_before.truth_pct_mean.expect("reference masks"),
    );
    assert!(est > 5.0 && (est - truth).abs() < 1.0, "{rim_before:?}");
    // Calibrated from the frames' own edges: a margin written beside the pose.
    let fitted = out.join("calibrated");
    let (ok, log) = calibrate(&[
        "--recording",
        recording.to_str().expect("utf-8"),
        "--urdf",
        urdf_arg,
        "--edges",
        "--every",
        "8",
        "--hidden-below",
        "0",
        "--out",
        fitted.to_str().expect("utf-8"),
    ]);
    assert!(ok, "{log}");
    let rep: CalibrateReport = report(&fitted.join("report.json"));
    let margin = rep.margin.as_ref().expect("a margin");
    eprintln!(
        "margin {} px (outline p95 {:.1} px, spread {:.1} px)",
        margin.dilate_px, margin.outline_p95_px, margin.spread_px
    );
    assert!(
        !margin.capped && (2..=16).contains(&margin.dilate_px),
        "{margin:?}"
    );
    // Replayed with that pose and no other flag.
    let pose = fitted.join("camera_pose.yaml");
    let pose_arg = pose.to_str().expect("utf-8");
    let after = replay_recording(
        &recording,
        urdf_arg,
        &out.join("after"),
        &["--pose", pose_arg],
    );
    let plain = replay_recording(
        &recording,
        urdf_arg,
        &out.join("after_unrefined"),
        &["--pose", pose_arg, "--refine-edges", "off"],
    );
    assert_eq!(after.erase.dilate_px, margin.dilate_px);
    assert!(
        after.erase.dilate_from.contains("avatarm calibrate"),
        "{:?}",
        after.erase
    );
    assert!(after.erase.refine_edges && !plain.erase.refine_edges);
    let vs = |r: &RecordingReport| {
        let v = &r.mask.vs_reference;
        (
            v.leak_pct_mean.expect("leak"),
            v.overmask_pct_mean.expect("overmask"),
        )
    };
    let ((leak, over), (leak_plain, over_plain)) = (vs(&after), vs(&plain));
    let rim_after = rim(&after);
    eprintln!(
        "calibrated: leak {leak:.3} % / overmask {over:.1} % refined, {leak_plain:.3} % / {over_plain:.1} % by the margin alone; rim {:?} % (reference {:?} %)",
        rim_after.rim_pct_mean, rim_after.truth_pct_mean
    );
    assert!(leak <= 0.5 && leak_plain <= 0.5, "{leak} {leak_plain}");
    assert!(rim_after.rim_pct_mean.expect("rim") <= 0.5, "{rim_after:?}");
    assert!(over < over_plain * 0.85, "{over} {over_plain}");
    // The region no frame showed, filled from what the frames did show, against the empty
    // room the replay photographed: Telea against ring by ring.
    let (empty, w, h) = rgb(&out.join("recorded/background.png"));
    let (seen_rgb, ..) = rgb(&out.join("after/background.png"));
    let seen = image::open(out.join("after/background_seen.png"))
        .expect("seen map")
        .to_luma8();
    let known: Vec<bool> = seen.pixels().map(|p| p.0[0] > 127).collect();
    let unseen: Vec<u8> = known.iter().map(|&k| u8::from(!k)).collect();
    let hole = unseen.iter().filter(|&&u| u != 0).count();
    assert!(hole > 1000, "{hole} pixels never seen");
    let psnr = |fill: HoleFill| {
        let mut filled: Vec<[u8; 3]> = seen_rgb
            .iter()
            .zip(&known)
            .map(|(&p, &k)| if k { p } else { [0; 3] })
            .collect();
        let mut k = known.clone();
        dr::fill_hole(&mut filled, &mut k, w as usize, h as usize, fill);
        dr::psnr_in(&rgba(&filled), &rgba(&empty), &unseen).expect("scored")
    };
    let (rings, telea) = (psnr(HoleFill::Rings), psnr(HoleFill::default()));
    let shipped = dr::psnr_in(&rgba(&seen_rgb), &rgba(&empty), &unseen).expect("scored");
    eprintln!(
        "never seen: {hole} px; PSNR against the empty room: rings {rings:.2} dB, Telea {telea:.2} dB (background.png: {shipped:.2} dB)"
    );
    assert!(
        (shipped - telea).abs() < 1e-9,
        "background.png is Telea's fill"
    );
    assert!(telea > rings, "{telea} {rings}");
}
