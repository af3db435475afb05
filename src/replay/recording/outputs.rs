//! What `replay --recording` writes: each frame's mask and erased image, overlays, the erased
//! session as a recording, and the report.

use super::*;

/// The frame (RGBA8, `width` wide) with the mask tinted red over it, image `edges` (0/1 per
/// pixel, as `avatarm calibrate --edges` fits to) in yellow, and the reference mask's outline
/// in green on top: where the mask lands against where the robot is, by eye.
pub(crate) fn overlay(
    frame: &[u8],
    mask: &[u8],
    edges: Option<&[u8]>,
    reference: Option<&[u8]>,
    width: u32,
) -> Vec<u8> {
    let w = width as usize;
    let mut out = frame.to_vec();
    for (i, px) in out.chunks_exact_mut(4).enumerate() {
        if edges.is_some_and(|e| e[i] > 0) {
            px.copy_from_slice(&EDGE_COLOUR);
        } else if mask[i] > 0 {
            px[0] = ((u16::from(px[0]) + 255) / 2) as u8;
            px[1] /= 2;
            px[2] /= 2;
        }
    }
    if let Some(r) = reference {
        let h = r.len() / w;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let edge = r[i] > 0
                    && [(0, -1), (0, 1), (-1, 0), (1, 0)].iter().any(|(dx, dy)| {
                        let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                        nx < 0
                            || ny < 0
                            || nx >= w as i64
                            || ny >= h as i64
                            || r[ny as usize * w + nx as usize] == 0
                    });
                if edge {
                    out[i * 4..i * 4 + 4].copy_from_slice(&[40, 255, 40, 255]);
                }
            }
        }
    }
    out
}

/// The colour [`overlay`] draws image edges in (RGBA8).
pub(crate) const EDGE_COLOUR: [u8; 4] = [255, 220, 0, 255];

pub(super) fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

#[expect(
    clippy::too_many_lines,
    reason = "every frame's outputs and the report written in one pass over the frames"
)]
pub(super) fn write_outputs(
    o: &RecordingOptions,
    input: &Input,
    outputs: &[FrameOutput],
    background: &Option<(BackgroundEstimate, String)>,
    times: &avatarm_erase::SpanTimes,
    started: Instant,
) -> Result<serde_json::Value, AppError> {
    let (w, h) = input.size;
    let out = &o.out;
    let png = |name: String, img: image::DynamicImage| -> Result<Vec<u8>, AppError> {
        let path = out.join(&name);
        img.save(&path)
            .map_err(|source| AppError::write_image(&path, source))?;
        std::fs::read(&path).map_err(|source| AppError::Io {
            path,
            action: "read",
            source,
        })
    };
    let gray = |m: &[u8]| -> Result<image::DynamicImage, AppError> {
        image::GrayImage::from_raw(w, h, m.iter().map(|&v| v * 255).collect())
            .map(image::DynamicImage::ImageLuma8)
            .ok_or(AppError::ImageSize {
                what: "mask".into(),
                width: w,
                height: h,
            })
    };
    let rgb = |rgba: &[u8]| -> Result<image::DynamicImage, AppError> {
        image::RgbaImage::from_raw(w, h, rgba.to_vec())
            .map(|i| image::DynamicImage::ImageRgb8(image::DynamicImage::ImageRgba8(i).to_rgb8()))
            .ok_or(AppError::ImageSize {
                what: "erased frame".into(),
                width: w,
                height: h,
            })
    };
    let mcap_path = out.join("erased.mcap");
    let mut mcap = RecordingWriter::create(&mcap_path)?;
    let first_stamp = input.frames.first().map_or(0, |f| f.stamp_ns);
    mcap.calibration(first_stamp, &input.calibration)?;
    match input.head_mount {
        Some(mount) => {
            mcap.camera_mount(first_stamp, &mount)?;
            for p in &input.recording.head_poses {
                mcap.head_pose(p)?;
            }
        }
        None => mcap.camera_pose(first_stamp, &input.camera.world_from_camera)?,
    }
    for s in &input.recording.joint_states {
        mcap.joint_states(s)?;
    }
    let settings = o.settings;
    // The lens map the mask was drawn through (the same function as the pipeline's).
    let lens = &input.lens_map;
    let (mut coverage, mut max_diff, mut mismatch) = (Vec::new(), 0u8, 0u64);
    let mut scored = Vec::new();
    let mut robot_union = vec![0u8; (w * h) as usize];
    for (i, (frame, result)) in input.frames.iter().zip(outputs).enumerate() {
        let (Some(mask), Some(composite)) = (&result.mask, &result.composite) else {
            return Err(AppError::command(
                "replay --recording",
                format!("frame {i}: its mask or erased image never arrived"),
            ));
        };
        coverage.push(100.0 * mask.iter().filter(|&&m| m > 0).count() as f64 / mask.len() as f64);
        // The CPU reference on the same inputs.
        if let (Some((rw, rh, raw)), Some((live, bg, photometric))) = (&result.raw, &result.inputs)
        {
            let raw = RgbaView::new("mask twin render", *rw, *rh, raw)?;
            let cpu_mask = dr::threshold_mask(
                &raw,
                w,
                h,
                &settings.ranges,
                settings.mask_radius(),
                lens.0.as_deref(),
            )?;
            let alpha = dr::feather_alpha(&cpu_mask, w, h, settings.feather_px);
            let black = vec![0u8; live.len()];
            let alpha_h = if settings.enabled && bg.is_some() {
                settings.alpha_h
            } else {
                0.0
            };
            let live_view = RgbaView::new("live frame", w, h, live)?;
            let bg_view = RgbaView::new("background", w, h, bg.as_deref().unwrap_or(&black))?;
            let cpu = dr::composite(&live_view, &bg_view, &alpha, alpha_h, photometric)?;
            mismatch =
                mismatch.max(mask.iter().zip(&cpu_mask).filter(|(a, b)| a != b).count() as u64);
            let diff = composite
                .chunks_exact(4)
                .zip(cpu.chunks_exact(4))
                .flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])))
                .max()
                .unwrap_or(0);
            max_diff = max_diff.max(diff);
        }
        let erased_region: Vec<u8> = dr::feather_alpha(mask, w, h, settings.feather_px)
            .iter()
            .map(|&a| u8::from(a >= 0.5))
            .collect();
        for (u, &m) in robot_union.iter_mut().zip(mask) {
            *u |= m;
        }
        if let Some(truth) = &input.references[i]
            && let Some(s) = dr::mask_scores(&erased_region, truth)
        {
            scored.push(json!({
                "frame": i,
                "stamp_ns": frame.stamp_ns,
                "iou": s.iou,
                "leak_pct": s.leak_pct,
                "overmask_pct": s.overmask_pct,
                "robot_px": s.robot_px,
            }));
        }
        if let Some(live) = result.inputs.as_ref().map(|x| &x.0) {
            let picture = overlay(live, mask, None, input.references[i].as_deref(), w);
            png(format!("overlay_{i:05}.png"), rgb(&picture)?)?;
        }
        let erased_png = png(format!("erased_{i:05}.png"), rgb(composite)?)?;
        let mask_png = png(format!("mask_{i:05}.png"), gray(mask)?)?;
        mcap.frame(frame)?;
        mcap.erased(&CompressedFrame {
            stamp_ns: frame.stamp_ns,
            format: ImageFormat::Png,
            data: erased_png,
        })?;
        mcap.mask(&CompressedFrame {
            stamp_ns: frame.stamp_ns,
            format: ImageFormat::Png,
            data: mask_png,
        })?;
    }
    for m in &input.recording.reference_masks {
        mcap.reference_mask(m)?;
    }
    mcap.finish()?;
    let background_report = match background {
        Some((estimate, origin)) => {
            png("background.png".into(), rgb(&estimate.rgba)?)?;
            png("background_seen.png".into(), gray(&estimate.seen)?)?;
            json!({
                "source": origin,
                "margin_px": o.background_margin_px,
                "robot_region_seen_pct": estimate.seen_fraction(&robot_union).map(|f| 100.0 * f),
                "filled_pct_of_frame": 100.0 * estimate.filled_fraction(),
                "note": "robot_region_seen_pct: of the pixels any frame's mask covered, the share whose background some frame showed; the rest was filled from the surroundings (background_seen.png: white where seen)",
            })
        }
        None => json!({"source": o.background.as_ref().map(|p| p.display().to_string())}),
    };
    let mut background_report = background_report;
    if let Some(vb) = &input.view_background {
        let seen: Vec<f64> = outputs
            .iter()
            .filter_map(|f| f.view.and_then(|v| v.0))
            .collect();
        let nearest: Vec<f64> = outputs
            .iter()
            .filter_map(|f| f.view.and_then(|v| v.1))
            .map(f64::to_degrees)
            .collect();
        background_report["view_following"] = json!({
            "room": o.room.as_ref().map(|p| p.display().to_string()),
            "proxy_rects": vb.proxy.rects.len(),
            "max_views": vb.max_views,
            "min_separation_deg": vb.min_separation_rad.to_degrees(),
            "robot_region_seen_pct_mean": mean(&seen).map(|f| 100.0 * f),
            "nearest_view_deg": spread(&nearest),
            "note": "each frame's H: the kept views re-projected through the room's boxes where the robot may be, the frame itself elsewhere; robot_region_seen_pct_mean: of the robot's region, the share some view saw (the footage's median fills the rest)",
        });
    }
    let get = |key: &str| -> Vec<f64> { scored.iter().filter_map(|s| s[key].as_f64()).collect() };
    let (iou, leak, over) = (get("iou"), get("leak_pct"), get("overmask_pct"));
    let span = |name: &str| {
        spread(
            &times
                .spans
                .get(name)
                .map_or_else(Vec::new, |s| s.ms.iter().copied().collect::<Vec<_>>()),
        )
    };
    let gpu_passes: serde_json::Map<String, serde_json::Value> = PASS_NAMES
        .iter()
        .filter(|n| times.spans.contains_key(**n))
        .map(|n| (n.to_string(), span(n)))
        .collect();
    let k = &input.camera.intrinsics;
    let report = json!({
        "recording": o.recording.display().to_string(),
        "robot": input.model.name,
        "frames": input.frames.len(),
        "size": [w, h],
        "camera": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
                   "distortion_model": input.calibration.distortion_model.ros_name(),
                   "lens": crate::replay::lens_report(&input.lens, lens.0.as_deref()),
                   "head": input.head_mount.map(|m| {
                       let q = m.rotation;
                       json!({"head_poses": input.recording.head_poses.len(),
                              "head_from_camera": {"translation": [m.translation.x, m.translation.y, m.translation.z],
                                                   "quaternion_xyzw": [q.i, q.j, q.k, q.w]}})
                   })},
        "erase": {"dilate_px": settings.dilate_px, "feather_px": settings.feather_px,
                  "resolution_scale": settings.resolution_scale, "photometric": settings.photometric},
        "background": background_report,
        "mask": {
            "coverage_pct_mean": mean(&coverage),
            "vs_reference": {
                "frames_scored": scored.len(),
                "iou_mean": mean(&iou),
                "iou_min": iou.iter().copied().reduce(f64::min),
                "leak_pct_mean": mean(&leak),
                "overmask_pct_mean": mean(&over),
                "per_frame": scored,
            },
        },
        "gpu_vs_cpu": {"max_abs_diff": max_diff, "mask_mismatch_px_max": mismatch},
        "timing_ms": {"gpu_passes": gpu_passes, "upload": span(UPLOAD_SPAN),
                      "source": times.unavailable.clone().unwrap_or_else(|| "gpu".into())},
        "wall_time_s": started.elapsed().as_secs_f64(),
        "notes": input.notes,
        "outputs": {"mcap": mcap_path.display().to_string()},
    });
    let path = out.join("report.json");
    let text = serde_json::to_string_pretty(&report)?;
    std::fs::write(&path, text + "\n").map_err(|e| AppError::write(path, e))?;
    Ok(report)
}
