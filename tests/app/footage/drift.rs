//! The drift watch of `avatarm replay --recording`: a camera bumped in the middle of a
//! session, found from the frames and fitted again, where the simulated room knows the truth.

use nalgebra::Vector3;

use super::*;
use crate::support::bump::write_bumped;

/// The simulated room's camera bumped by 1 deg two seconds into a 4 s session (every frame
/// and reference mask from then on as the turned camera takes it; the recording's pose stays
/// the one before). Replayed with the drift watch (the default), the move is found within a
/// second and the pose fitted again within 0.2 deg of the turned camera, and the frames after
/// it are erased as well as those before; without it, the mask stays where the camera was and
/// the robot leaks out along one side.
#[test]
fn a_camera_bumped_mid_recording_is_found_and_fitted_again() {
    let out = out_dir("drift");
    let urdf = root().join("assets/robots/sawyer_lite/sawyer_lite.urdf");
    let text = std::fs::read_to_string(root().join("assets/scenes/default.toml"))
        .expect("scene")
        .replace(
            "../robots/sawyer_lite/sawyer_lite.urdf",
            urdf.to_str().expect("utf-8"),
        )
        .replace("duration_s = 10.0", "duration_s = 4.0");
    assert!(text.contains("duration_s = 4.0"));
    let (_, _, r) = record_scene(&out, &text);
    let first = r.frames.first().expect("frames").stamp_ns;
    let bump_ns = first + 2_000_000_000;
    let turn = UnitQuaternion::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(0.3, 1.0, 0.2)),
        1f64.to_radians(),
    );
    let bumped = out.join("bumped.mcap");
    write_bumped(&r, &bumped, bump_ns, &turn);
    let urdf = urdf.to_str().expect("utf-8");
    let watched = replay_recording(&bumped, urdf, &out.join("watched"), &[]);
    let unwatched = replay_recording(
        &bumped,
        urdf,
        &out.join("unwatched"),
        &["--drift-watch", "off"],
    );
    assert!(unwatched.drift.is_none());
    let drift = watched.drift.as_ref().expect("watched");
    eprintln!(
        "drift: {} ({} checks, {:?}/{:?} ms median/p95)",
        drift.note,
        drift.checks.len(),
        drift.check_ms_median,
        drift.check_ms_p95
    );
    assert_eq!(drift.refits.len(), 1, "{drift:?}");
    let refit = &drift.refits[0];
    let frame_ns = |i: usize| r.frames[i].stamp_ns;
    let bump_frame = r.frames.partition_point(|f| f.stamp_ns < bump_ns);
    eprintln!(
        "bumped at frame {bump_frame}: first seen at frame {}, confirmed at frame {} ({:.2} s after), refit {:.2} s, shift {:?} px, chamfer before/turned/refit {:.2}/{:.2}/{:.2} px",
        refit.first_beyond_frame,
        refit.detected_frame,
        (refit.detected_stamp_ns - bump_ns) as f64 * 1e-9,
        refit.refit_s,
        refit.shift_px,
        refit.cost_before_px,
        refit.cost_turned_px,
        refit.cost_refit_px
    );
    assert!(refit.first_beyond_frame >= bump_frame, "{refit:?}");
    assert!(
        frame_ns(refit.detected_frame) - bump_ns <= 1_000_000_000,
        "{refit:?}"
    );
    // The refitted pose against the turned camera (the recording's pose turned).
    let before = r.base_from_camera.expect("pose");
    let truth = before * Isometry3::from_parts(Translation3::identity(), turn.inverse());
    let m = Matrix4::from_fn(|i, j| refit.base_from_camera[i][j]);
    let fitted = Isometry3::from_parts(
        Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_matrix(&m.fixed_view::<3, 3>(0, 0).into_owned()),
    );
    let off = truth.inverse() * fitted;
    let (deg, mm) = (
        off.rotation.angle().to_degrees(),
        1e3 * off.translation.vector.norm(),
    );
    eprintln!("refit vs the turned camera: {deg:.3} deg, {mm:.1} mm");
    assert!(deg <= 0.3, "{deg} deg");
    // Leak against the (turned) reference masks: before the bump, between the bump and the
    // refit, after the refit.
    let leak = |rep: &RecordingReport, from: usize, to: usize| {
        let v: Vec<f64> = rep
            .mask
            .vs_reference
            .per_frame
            .iter()
            .filter(|f| (from..to).contains(&f.frame))
            .map(|f| f.leak_pct)
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let n = r.frames.len();
    let after = refit.detected_frame;
    let (w_before, w_between, w_after) = (
        leak(&watched, 0, bump_frame),
        leak(&watched, bump_frame, after),
        leak(&watched, after, n),
    );
    let u_after = leak(&unwatched, after, n);
    eprintln!(
        "leak %: watched before {w_before:.3}, bump to refit {w_between:.3}, after {w_after:.3}; unwatched after {u_after:.3}"
    );
    // Measured: 0.000 % before the bump, 11.5 % from the bump to the refit, 0.67 % after it
    // (the refit's 0.13 deg, with no dilation), 11.4 % after it unwatched.
    assert!(w_before <= 0.1 && w_after <= 1.0, "{w_before} {w_after}");
    assert!(u_after > 5.0, "{u_after}");
    assert!(w_between > 5.0, "{w_between}");
    // H from the footage is built for each stretch the camera stood still.
    assert!(
        watched
            .notes
            .iter()
            .any(|n| n.contains("each stretch the camera stood still")),
        "{:?}",
        watched.notes
    );
}
