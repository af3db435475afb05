//! The replay's report: the stages' timings, spreads and means, the lens and a moving head's
//! figures.

use super::*;

/// Median and 95th percentile of some times, or null.
pub(crate) fn spread(values: &[f64]) -> serde_json::Value {
    if values.is_empty() {
        return json!(null);
    }
    match avatarm_core::stats::Spread::some_of(values) {
        Some(s) => json!({"median": s.median, "p95": s.p95}),
        None => json!(null),
    }
}

pub(super) fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut s, mut n) = (0.0, 0usize);
    for v in values {
        s += v;
        n += 1;
    }
    (n > 0).then(|| s / n as f64)
}

/// `timing_ms`: the erase's mask (the mask twin's render and the dilation passes) and
/// composite (feathering and the composite, which thresholds too when nothing dilates) per
/// camera frame, timed on the GPU when the device has timestamp queries, else the CPU
/// reference; each pass, the uploads and every other timed view (the room's cameras, the
/// ground truth, the interaction camera) beside them.
pub(super) fn stage_timings(replay: &Replay, gpu: &SpanTimes) -> serde_json::Value {
    let cpu_mask: Vec<f64> = replay.scores.iter().map(|f| f.cpu_mask_ms).collect();
    let cpu_comp: Vec<f64> = replay.scores.iter().map(|f| f.cpu_composite_ms).collect();
    let since = |name: &str| {
        gpu.since(
            name,
            replay.gpu_measured_at_start.get(name).copied().unwrap_or(0),
        )
    };
    let passes: Vec<(&str, Vec<f64>)> = PASS_NAMES
        .iter()
        .map(|&name| (name, since(name)))
        .filter(|(_, ms)| !ms.is_empty())
        .collect();
    // The n-th render of each pass works on the same camera frame (a frame's spans arrive
    // together or not at all).
    let per_frame = |names: &[&str]| -> Vec<f64> {
        let chosen: Vec<&Vec<f64>> = passes
            .iter()
            .filter(|(n, _)| names.contains(n))
            .map(|(_, ms)| ms)
            .collect();
        let n = chosen.iter().map(|v| v.len()).min().unwrap_or(0);
        (0..n).map(|i| chosen.iter().map(|v| v[i]).sum()).collect()
    };
    let gpu_mask = per_frame(&PASS_NAMES[..3]);
    let gpu_comp = per_frame(&PASS_NAMES[3..]);
    let gpu_erase = per_frame(&PASS_NAMES);
    let on_gpu = !gpu_mask.is_empty() && !gpu_comp.is_empty();
    let source = match (&gpu.unavailable, on_gpu) {
        (_, true) => "gpu".to_string(),
        (Some(why), false) => format!("cpu reference: {why}"),
        (None, false) => "cpu reference: no GPU pass time arrived".to_string(),
    };
    let entry = |ms: &[f64]| json!({"ms": spread(ms), "renders_timed": ms.len()});
    let gpu_passes: serde_json::Map<String, serde_json::Value> = passes
        .iter()
        .map(|(name, ms)| (name.to_string(), entry(ms)))
        .collect();
    let views: serde_json::Map<String, serde_json::Value> = gpu
        .spans
        .keys()
        .filter(|k| !PASS_NAMES.contains(&k.as_str()) && *k != UPLOAD_SPAN && *k != UPLOAD_CPU_SPAN)
        .map(|name| (name.clone(), entry(&since(name))))
        .collect();
    json!({
        "mask": spread(if on_gpu { &gpu_mask } else { &cpu_mask }),
        "composite": spread(if on_gpu { &gpu_comp } else { &cpu_comp }),
        "erase": spread(&gpu_erase),
        "upload": spread(&since(UPLOAD_SPAN)),
        "upload_cpu": spread(&since(UPLOAD_CPU_SPAN)),
        "frame": spread(&replay.frame_ms),
        "source": source,
        "gpu_passes": gpu_passes,
        "gpu_views": views,
        "cpu_reference": {"mask": spread(&cpu_mask), "composite": spread(&cpu_comp)},
        "note": "mask: the mask twin's flat render plus the dilation passes; composite: the feathering and composite passes (the composite thresholds too when nothing dilates); erase: all of them; each the GPU time between timestamps written around the pass (source \"gpu\"), or the CPU reference of the same steps when the device has no timestamp queries; upload: the GPU copies of the live frame and H from their staging buffers, upload_cpu: the CPU copies into them; gpu_views: every other timed render (cameras and flat views) in this replay; cpu_reference: avatarm_core::dr on the same frame; frame: wall time per app update, all cameras included",
    })
}

/// The report's account of the camera's lens: its model and coefficients, whether the mask
/// honoured it and the size of the mask's pinhole render.
pub(crate) fn lens_report(lens: &Distortion, map: Option<&DistortionMap>) -> serde_json::Value {
    json!({
        "model": lens.ros_name(),
        "coefficients": lens.coefficients(),
        "honoured": map.is_some(),
        "mask_render": map.map(|m| [m.pinhole.width, m.pinhole.height]),
        // Pixels never masked: past a barrel's fold, or beyond the render's 3x cap.
        "pixels_unmapped": map.map(|m| m.unmapped),
        "pixels_outside_render": map.map(|m| m.outside),
    })
}

/// The `head` section of a replay's report (null for a fixed camera): the head's motion and
/// tracking, and how far each frame's mask camera was from the true camera.
pub(super) fn head_report(
    s: &avatarm_scene::Scene,
    errors: &[HeadFrameError],
    scores: &[FrameScore],
    erase: &EraseState,
) -> serde_json::Value {
    let Some(head) = &s.head else {
        return serde_json::Value::Null;
    };
    // The background's PSNR in the robot's region against how far the frame's camera was from
    // the nearest view captured before it.
    let psnr_at: std::collections::HashMap<i64, f64> = scores
        .iter()
        .filter_map(|f| f.psnr_robot_db.map(|p| (frame_key(f.t_s), p)))
        .collect();
    let by_angle = |angle: &dyn Fn(&HeadFrameError) -> Option<f64>| -> serde_json::Value {
        let bins = [
            (0.0, 1.0),
            (1.0, 2.0),
            (2.0, 4.0),
            (4.0, 8.0),
            (8.0, 16.0),
            (16.0, 180.0),
        ];
        let rows: Vec<serde_json::Value> = bins
            .iter()
            .filter_map(|&(lo, hi)| {
                let psnrs: Vec<f64> = errors
                    .iter()
                    .filter(|e| angle(e).is_some_and(|a| a >= lo && a < hi))
                    .filter_map(|e| psnr_at.get(&frame_key(e.t_s)).copied())
                    .collect();
                (!psnrs.is_empty()).then(|| {
                    json!({
                        "angle_deg": [lo, hi],
                        "frames": psnrs.len(),
                        "psnr_robot_db_mean": mean(psnrs.iter().copied()),
                    })
                })
            })
            .collect();
        json!(rows)
    };
    let seen: Vec<f64> = errors.iter().filter_map(|e| e.seen_share).collect();
    let nearest: Vec<f64> = errors.iter().filter_map(|e| e.nearest_view_deg).collect();
    let cpu: Vec<f64> = errors.iter().filter_map(|e| e.view_background_ms).collect();
    let background = match &erase.view_background {
        Some(vb) => json!({
            "views_kept": vb.views.len(),
            "views_offered": vb.views.offered(),
            "blank_frames_refused": vb.views.blank(),
            "view_times_s": vb.views.times(),
            "seen_share_of_robot_region": mean(seen.iter().copied()),
            "nearest_view_deg": spread(&nearest),
            "cpu_ms": spread(&cpu),
            "psnr_by_nearest_view": by_angle(&|e| e.nearest_view_deg),
        }),
        None => json!(null),
    };
    let angles: Vec<f64> = errors.iter().map(|e| e.angle_deg).collect();
    let offsets: Vec<f64> = errors.iter().map(|e| e.offset_mm).collect();
    let ages: Vec<f64> = errors.iter().filter_map(|e| e.tracking_age_ms).collect();
    let speeds: Vec<f64> = errors.iter().map(|e| e.speed_deg_s).collect();
    let t = &head.tracking;
    json!({
        "peak_speed_deg_s": head.motion.peak_angular_speed(s.file.duration_s).to_degrees(),
        "speed_deg_s_at_frames": spread(&speeds),
        "tracking": {
            "rate_hz": t.rate_hz,
            "latency_s": t.latency_s,
            "position_sigma_mm": t.position_sigma_m * 1e3,
            "angle_sigma_deg": t.angle_sigma_rad.to_degrees(),
        },
        "pose_compensation": s.file.erase.pose_compensation,
        "mask_camera_error_deg": spread(&angles),
        "mask_camera_error_mm": spread(&offsets),
        "newest_tracked_pose_age_ms": spread(&ages),
        "frames": errors.len(),
        "view_background": background,
        "psnr_by_angle_from_photo": by_angle(&|e| Some(e.photo_angle_deg)),
    })
}
