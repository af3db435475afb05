//! What `replay --recording` writes: each frame's mask and erased image, overlays, the erased
//! session as a recording, and the report.

use super::*;
use crate::replay::report::{GpuVsCpu, mean};

/// Writes PNGs into the output folder and reads each back (for the erased recording).
struct Images<'a> {
    out: &'a Path,
    size: (u32, u32),
}

impl Images<'_> {
    /// Saves `img` as `name`; returns the file's bytes.
    fn png(&self, name: &str, img: &image::DynamicImage) -> Result<Vec<u8>, AppError> {
        let path = self.out.join(name);
        img.save(&path)
            .map_err(|source| AppError::write_image(&path, source))?;
        std::fs::read(&path).map_err(|source| AppError::Io {
            path,
            action: "read",
            source,
        })
    }

    /// A 0/1 mask as a grey image (white where 1).
    fn gray(&self, m: &[u8]) -> Result<image::DynamicImage, AppError> {
        let (w, h) = self.size;
        image::GrayImage::from_raw(w, h, m.iter().map(|&v| v * 255).collect())
            .map(image::DynamicImage::ImageLuma8)
            .ok_or(AppError::ImageSize {
                what: "mask".into(),
                width: w,
                height: h,
            })
    }

    /// An RGBA8 frame as an RGB image.
    fn rgb(&self, rgba: &[u8]) -> Result<image::DynamicImage, AppError> {
        let (w, h) = self.size;
        image::RgbaImage::from_raw(w, h, rgba.to_vec())
            .map(|i| image::DynamicImage::ImageRgb8(image::DynamicImage::ImageRgba8(i).to_rgb8()))
            .ok_or(AppError::ImageSize {
                what: "erased frame".into(),
                width: w,
                height: h,
            })
    }
}

/// What the pass over the frames found.
#[derive(Default)]
struct Tally {
    /// Each frame's masked share (%).
    coverage: Vec<f64>,
    /// The largest GPU-vs-CPU difference of the composites (8-bit levels).
    max_diff: u8,
    /// The most pixels where the GPU and CPU masks differ in one frame.
    mismatch: u64,
    /// The frames with a reference mask, scored.
    scored: Vec<FrameVsReference>,
    /// Every pixel any frame's mask covered (0/1).
    robot_union: Vec<u8>,
    /// Each frame's rim.
    rims: Vec<FrameRim>,
}

/// Pixels this far beyond the mask are left out of the photometric fit the refinement and
/// the rim make when the erase made none (px).
const PHOTOMETRIC_EXCLUDE_PX: u32 = 8;

/// One frame as written: its mask, erased image and erased region (0/1, the feathered mask
/// at ≥ 0.5), the band refined where asked, and the rim they leave.
struct Erased {
    mask: Vec<u8>,
    composite: Vec<u8>,
    region: Vec<u8>,
    rim: Option<dr::RimScore>,
}

/// The frame's mask and erased image, the margin's band refined to the frame with
/// `--refine-edges` (the composite then made again on the CPU, [`dr::composite`]), and the
/// rim left ([`dr::rim_score`]; none without H). `known`: where H was seen (the rest was
/// filled), `None` when all of it is trusted.
fn erased(
    o: &RecordingOptions,
    input: &Input,
    result: &FrameOutput,
    (mask, composite): (&[u8], &[u8]),
    known: Option<&[u8]>,
    truth: Option<&[u8]>,
) -> Result<Erased, AppError> {
    let (w, h) = input.size;
    let settings = o.settings;
    let region = |m: &[u8]| -> Vec<u8> {
        dr::feather_alpha(m, w, h, settings.feather_px)
            .iter()
            .map(|&a| u8::from(a >= 0.5))
            .collect()
    };
    let Some((live, Some(bg), photometric)) = &result.inputs else {
        return Ok(Erased {
            region: region(mask),
            mask: mask.to_vec(),
            composite: composite.to_vec(),
            rim: None,
        });
    };
    let live = RgbaView::new("live frame", w, h, live)?;
    let bg_view = RgbaView::new("background", w, h, bg)?;
    // H' to tell the robot from the room by: the erase's own photometric fit where it made
    // one, else one made here (a camera's white balance that moves between frames would
    // otherwise make every pixel differ from H); the composite keeps the erase's setting.
    let seen_as = if settings.photometric {
        *photometric
    } else {
        let near_robot = dr::dilate(mask, w, h, PHOTOMETRIC_EXCLUDE_PX);
        dr::fit_photometric(&live, &bg_view, Some(&near_robot), 4)?
    };
    let h_prime = dr::compensated(&bg_view, &seen_as);
    let rim_settings = dr::RimSettings::default();
    let (mask, composite) = if o.refine_edges && settings.enabled {
        let refined = dr::refine_band(
            &live,
            &h_prime,
            mask,
            known,
            settings.dilate_px,
            1,
            &rim_settings,
        )?;
        let alpha = dr::feather_alpha(&refined, w, h, settings.feather_px);
        let again = dr::composite(&live, &bg_view, &alpha, settings.alpha_h, photometric)?;
        (refined, again)
    } else {
        (mask.to_vec(), composite.to_vec())
    };
    let region = region(&mask);
    let rim = dr::rim_score(
        &live,
        &composite,
        &h_prime,
        &region,
        known,
        truth,
        &rim_settings,
    )?;
    Ok(Erased {
        mask,
        composite,
        region,
        rim,
    })
}

/// Writes each frame's mask, erased image and overlay, the erased session (`erased.mcap`), H
/// where it came from the footage, and `report.json`; returns the report.
pub(super) fn write_outputs(
    o: &RecordingOptions,
    input: &Input,
    outputs: &[FrameOutput],
    background: &Option<(BackgroundEstimate, String)>,
    times: &avatarm_erase::SpanTimes,
    started: Instant,
) -> Result<RecordingReport, AppError> {
    let images = Images {
        out: &o.out,
        size: input.size,
    };
    let mcap_path = o.out.join("erased.mcap");
    // Where H was seen: one background for the whole replay of a still camera (a camera that
    // moved has one per still stretch, a camera on a head one per view: each filled where
    // unseen, trusted as it is).
    let known = background
        .as_ref()
        .filter(|_| {
            input.head_mount.is_none() && input.drift.as_ref().is_none_or(|d| d.refits.is_empty())
        })
        .map(|(e, _)| e.seen.as_slice());
    let tally = write_frames(o, input, outputs, &images, &mcap_path, known)?;
    let background_report = background_report(o, input, outputs, background, &tally, &images)?;
    let report = report(
        o,
        input,
        tally,
        background_report,
        times,
        &mcap_path,
        started,
    );
    crate::replay::write_json(&o.out.join("report.json"), &report)?;
    Ok(report)
}

/// The erased session as a recording: the recording's camera, head poses and joint states,
/// then each frame with its erased image and mask, and the reference masks.
fn write_frames(
    o: &RecordingOptions,
    input: &Input,
    outputs: &[FrameOutput],
    images: &Images,
    mcap_path: &Path,
    known: Option<&[u8]>,
) -> Result<Tally, AppError> {
    let (w, h) = input.size;
    let mut mcap = RecordingWriter::create(mcap_path)?;
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
    let mut tally = Tally {
        robot_union: vec![0u8; (w * h) as usize],
        ..Tally::default()
    };
    for (i, (frame, result)) in input.frames.iter().zip(outputs).enumerate() {
        let (Some(mask), Some(composite)) = (&result.mask, &result.composite) else {
            return Err(AppError::command(
                "replay --recording",
                format!("frame {i}: its mask or erased image never arrived"),
            ));
        };
        if let Some((diff, mismatch)) = cpu_check(o.settings, input, result, mask, composite)? {
            tally.max_diff = tally.max_diff.max(diff);
            tally.mismatch = tally.mismatch.max(mismatch);
        }
        // The robot's region: where the drawn masks (before any refinement) reached.
        for (u, &m) in tally.robot_union.iter_mut().zip(mask) {
            *u |= m;
        }
        let Erased {
            mask,
            composite,
            region: erased_region,
            rim,
        } = erased(
            o,
            input,
            result,
            (mask, composite),
            known,
            input.references[i].as_deref(),
        )?;
        let (mask, composite) = (&mask, &composite);
        tally
            .coverage
            .push(100.0 * mask.iter().filter(|&&m| m > 0).count() as f64 / mask.len() as f64);
        if let Some(truth) = &input.references[i]
            && let Some(s) = dr::mask_scores(&erased_region, truth)
        {
            tally.scored.push(FrameVsReference {
                frame: i,
                stamp_ns: frame.stamp_ns,
                iou: s.iou,
                leak_pct: s.leak_pct,
                overmask_pct: s.overmask_pct,
                robot_px: s.robot_px,
            });
        }
        if let Some(r) = rim {
            tally.rims.push(FrameRim {
                frame: i,
                ring_px: r.ring_px,
                rim_px: r.rim_px,
                rim_pct: r.rim_pct,
                truth_pct: r.truth_pct,
            });
        }
        if let Some(live) = result.inputs.as_ref().map(|x| &x.0) {
            let picture = overlay(live, mask, None, input.references[i].as_deref(), w);
            images.png(&format!("overlay_{i:05}.png"), &images.rgb(&picture)?)?;
        }
        let erased_png = images.png(&format!("erased_{i:05}.png"), &images.rgb(composite)?)?;
        let mask_png = images.png(&format!("mask_{i:05}.png"), &images.gray(mask)?)?;
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
    Ok(tally)
}

/// The CPU reference ([`avatarm_core::dr`]) on the inputs the GPU passes had: the largest
/// difference of the composites (8-bit levels) and the pixels where the masks differ; `None`
/// for a frame whose inputs were not kept.
fn cpu_check(
    settings: EraseSettings,
    input: &Input,
    result: &FrameOutput,
    mask: &[u8],
    composite: &[u8],
) -> Result<Option<(u8, u64)>, AppError> {
    let (Some((rw, rh, raw)), Some((live, bg, photometric))) = (&result.raw, &result.inputs) else {
        return Ok(None);
    };
    let (w, h) = input.size;
    let raw = RgbaView::new("mask twin render", *rw, *rh, raw)?;
    // The lens map the mask was drawn through (the same function as the pipeline's).
    let cpu_mask = dr::threshold_mask(
        &raw,
        w,
        h,
        &settings.ranges,
        settings.mask_radius(),
        input.lens_map.0.as_deref(),
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
    let mismatch = mask.iter().zip(&cpu_mask).filter(|(a, b)| a != b).count() as u64;
    let diff = composite
        .chunks_exact(4)
        .zip(cpu.chunks_exact(4))
        .flat_map(|(a, b)| (0..3).map(move |c| a[c].abs_diff(b[c])))
        .max()
        .unwrap_or(0);
    Ok(Some((diff, mismatch)))
}

/// Where H came from; built from the footage, `background.png` and `background_seen.png`
/// (white where some frame showed the pixel) are written; a view-following background's
/// figures beside it.
fn background_report(
    o: &RecordingOptions,
    input: &Input,
    outputs: &[FrameOutput],
    background: &Option<(BackgroundEstimate, String)>,
    tally: &Tally,
    images: &Images,
) -> Result<RecordingBackground, AppError> {
    let mut report = match background {
        Some((estimate, origin)) => {
            images.png("background.png", &images.rgb(&estimate.rgba)?)?;
            images.png("background_seen.png", &images.gray(&estimate.seen)?)?;
            RecordingBackground {
                source: Some(origin.clone()),
                margin_px: Some(o.background_margin_px),
                robot_region_seen_pct: estimate
                    .seen_fraction(&tally.robot_union)
                    .map(|f| 100.0 * f),
                filled_pct_of_frame: Some(100.0 * estimate.filled_fraction()),
                note: Some("robot_region_seen_pct: of the pixels any frame's mask covered, the share whose background some frame showed; the rest was filled from the surroundings (background_seen.png: white where seen)".into()),
                view_following: None,
            }
        }
        None => RecordingBackground {
            source: o.background.as_ref().map(|p| p.display().to_string()),
            margin_px: None,
            robot_region_seen_pct: None,
            filled_pct_of_frame: None,
            note: None,
            view_following: None,
        },
    };
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
        report.view_following = Some(ViewFollowing {
            room: o.room.as_ref().map(|p| p.display().to_string()),
            proxy_rects: vb.proxy.rects.len(),
            max_views: vb.max_views,
            min_separation_deg: vb.min_separation_rad.to_degrees(),
            robot_region_seen_pct_mean: mean(&seen).map(|f| 100.0 * f),
            nearest_view_deg: Spread::some_of(&nearest),
            note: "each frame's H: the kept views re-projected through the room's boxes where the robot may be, the frame itself elsewhere; robot_region_seen_pct_mean: of the robot's region, the share some view saw (the footage's median fills the rest)".into(),
        });
    }
    Ok(report)
}

/// The rim over the frames scored; `None` with none.
fn rim_report(rims: Vec<FrameRim>) -> Option<RimReport> {
    if rims.is_empty() {
        return None;
    }
    let settings = dr::RimSettings::default();
    let pct: Vec<f64> = rims.iter().map(|r| r.rim_pct).collect();
    let truth: Vec<f64> = rims.iter().filter_map(|r| r.truth_pct).collect();
    Some(RimReport {
        ring_px: settings.ring_px,
        difference_levels: settings.difference,
        frames_scored: rims.len(),
        rim_pct_mean: mean(&pct),
        rim_pct_max: pct.iter().copied().reduce(f64::max),
        truth_pct_mean: mean(&truth),
        per_frame: rims,
        note: format!(
            "rim_pct: of the pixels within {} px outside the erased region (where some frame showed H, for a camera that stood still throughout; all of the ring otherwise), the share the erased frame still shows differing from H' by more than {} levels in a colour likelier the robot's (learnt from the frame inside the mask) than the room's (H' by the erase's photometric fit, or one made for this where the erase made none); truth_pct: the share of that ring the reference masks say is the robot (truth_pct_mean: over the frames with a reference mask); the refinement and the rim are CPU passes after the GPU's, whose agreement with the CPU reference (gpu_vs_cpu) is checked before them",
            settings.ring_px, settings.difference
        ),
    })
}

/// The report of a finished replay.
fn report(
    o: &RecordingOptions,
    input: &Input,
    tally: Tally,
    background: RecordingBackground,
    times: &avatarm_erase::SpanTimes,
    mcap_path: &Path,
    started: Instant,
) -> RecordingReport {
    let (w, h) = input.size;
    let settings = o.settings;
    let scored = tally.scored;
    let get = |f: fn(&FrameVsReference) -> f64| -> Vec<f64> { scored.iter().map(f).collect() };
    let (iou, leak, over) = (get(|s| s.iou), get(|s| s.leak_pct), get(|s| s.overmask_pct));
    let span = |name: &str| {
        Spread::some_of(
            &times
                .spans
                .get(name)
                .map_or_else(Vec::new, |s| s.ms.iter().copied().collect::<Vec<_>>()),
        )
    };
    let gpu_passes = PASS_NAMES
        .iter()
        .filter(|n| times.spans.contains_key(**n))
        .map(|n| (n.to_string(), span(n)))
        .collect();
    let k = &input.camera.intrinsics;
    RecordingReport {
        recording: o.recording.display().to_string(),
        robot: input.model.name.clone(),
        frames: input.frames.len(),
        size: [w, h],
        camera: RecordingCamera {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            distortion_model: input.calibration.distortion_model.ros_name().to_owned(),
            lens: crate::replay::lens_report(&input.lens, input.lens_map.0.as_deref()),
            head: input.head_mount.map(|m| {
                let (q, t) = (m.rotation, m.translation);
                HeadMount {
                    head_poses: input.recording.head_poses.len(),
                    head_from_camera: MountPose {
                        translation: [t.x, t.y, t.z],
                        quaternion_xyzw: [q.i, q.j, q.k, q.w],
                    },
                }
            }),
        },
        erase: RecordingErase {
            dilate_px: settings.dilate_px,
            dilate_from: o.dilate_from.said(),
            feather_px: settings.feather_px,
            resolution_scale: settings.resolution_scale,
            photometric: settings.photometric,
            refine_edges: o.refine_edges,
        },
        background,
        mask: RecordingMask {
            coverage_pct_mean: mean(&tally.coverage),
            vs_reference: VsReference {
                frames_scored: scored.len(),
                iou_mean: mean(&iou),
                iou_min: iou.iter().copied().reduce(f64::min),
                leak_pct_mean: mean(&leak),
                overmask_pct_mean: mean(&over),
                per_frame: scored,
            },
            rim: rim_report(tally.rims),
        },
        gpu_vs_cpu: GpuVsCpu {
            max_abs_diff: Some(tally.max_diff),
            mask_mismatch_px_max: Some(tally.mismatch),
        },
        timing_ms: RecordingTimings {
            gpu_passes,
            upload: span(UPLOAD_SPAN),
            source: times.unavailable.clone().unwrap_or_else(|| "gpu".into()),
        },
        drift: input.drift.clone(),
        wall_time_s: started.elapsed().as_secs_f64(),
        notes: input.notes.clone(),
        outputs: RecordingOutputs {
            mcap: mcap_path.display().to_string(),
        },
    }
}
