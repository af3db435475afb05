//! `avatarm bench video`: the video's codecs against each other. A recording's erased frames
//! (what the robot site sends: the robot gone, so little moves) and its camera frames (the
//! arm moving: the hard case for a codec that codes differences) are each cropped to each
//! frame size's aspect and scaled to it, then coded in order as a camera at `fps` would be, by
//! JPEG at several qualities and by H.264 (OpenH264, Constrained Baseline) at several bit
//! rates: the bit rate, the encode and decode time per frame, and the PSNR of what a viewer
//! shows against the frame before coding (a frame H.264's rate control skipped is scored as
//! the frame before it, which the viewer keeps showing). JPEG at quality 85 (the default
//! codec) is the baseline of each source and size, and every row gives its bit rate and
//! encode time as ratios against it, measured in the same run.

use std::path::{Path, PathBuf};
use std::time::Instant;

use avatarm_net::codec::{Decoded, EncoderSettings, VideoDecoder, VideoEncoder, psnr_rgba};
use avatarm_net::msg::Codec;
use avatarm_net::msg::{FrameHeader, PROTOCOL_VERSION};
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

use super::chart::{Chart, axes, drawing_error, legend, padded, save_chart, write_table};
use crate::AppError;
use avatarm_core::stats::Spread;

/// What `bench video` codes.
#[derive(Debug, Clone)]
pub struct VideoSweep {
    /// Frame sizes (width, height; even).
    pub sizes: Vec<(u32, u32)>,
    /// JPEG qualities.
    pub jpeg_qualities: Vec<u8>,
    /// H.264 bit rates (Mbit/s).
    pub h264_mbit_s: Vec<f64>,
    /// The camera's frame rate (Hz): the bit rate is per second of video at it.
    pub fps: f64,
    /// Seconds between H.264 IDR frames.
    pub keyframe_interval_s: f64,
    /// Frames coded (the recording's first, looped when it has fewer).
    pub frames: usize,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for VideoSweep {
    fn default() -> Self {
        Self {
            sizes: vec![(640, 480), (1280, 720)],
            jpeg_qualities: vec![50, 70, 85, 95],
            h264_mbit_s: vec![0.5, 1.0, 2.0, 4.0, 8.0],
            fps: 30.0,
            keyframe_interval_s: 2.0,
            frames: 90,
            progress: false,
        }
    }
}

/// One codec setting at one size.
#[derive(Debug, Clone, Serialize)]
pub struct VideoPoint {
    /// `erased` or `camera` frames.
    pub source: String,
    /// Width (px).
    pub width: u32,
    /// Height (px).
    pub height: u32,
    /// `jpeg` or `h264`.
    pub codec: String,
    /// The encoder (`jpeg-encoder (SIMD)`, `image`, `openh264`).
    pub encoder: String,
    /// JPEG quality, or the H.264 target (Mbit/s).
    pub setting: f64,
    /// Frames coded.
    pub frames: usize,
    /// Of them, skipped by H.264's rate control.
    pub skipped: usize,
    /// Bit rate at the camera's frame rate (Mbit/s).
    pub mbit_s: f64,
    /// Mean size of a keyframe (kB).
    pub keyframe_kb: f64,
    /// Mean size of the other frames (kB; JPEG has none).
    pub delta_kb: f64,
    /// Encode time per frame (ms), RGBA in.
    pub encode_ms: Spread,
    /// Decode time per frame (ms), RGBA out.
    pub decode_ms: Spread,
    /// PSNR of the decoded frames (dB, RGB, mean).
    pub psnr_db: f64,
    /// The worst frame's PSNR (dB).
    pub psnr_min_db: f64,
    /// Bit rate over JPEG quality 85's (the `image` crate's encoder, the baseline) at this size.
    pub rate_ratio: f64,
    /// Median encode time over that baseline's at this size.
    pub encode_ratio: f64,
}

/// What `bench video` wrote.
#[derive(Debug)]
pub struct VideoOutputs {
    /// Every point.
    pub points: Vec<VideoPoint>,
    /// The CSV.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart as PNG.
    pub png: PathBuf,
}

/// A recording's erased frames and its camera frames (those it has, at most `limit` of
/// each), decoded to RGBA8, named `erased` and `camera`. Errors name the file and the frame.
pub fn source_frames(
    recording: &Path,
    limit: usize,
) -> Result<Vec<(String, Vec<image::RgbaImage>)>, AppError> {
    let rec = avatarm_record::Recording::open(recording)?;
    let mut sources = Vec::new();
    for (name, frames) in [("erased", &rec.erased), ("camera", &rec.frames)] {
        if frames.is_empty() {
            continue;
        }
        let mut images = Vec::new();
        for (i, f) in frames.iter().take(limit).enumerate() {
            let img = image::load_from_memory(&f.data).map_err(|e| AppError::Image {
                path: recording.join(format!("{name}[{i}]")),
                action: "read",
                source: e,
            })?;
            images.push(img.into_rgba8());
        }
        sources.push((name.to_owned(), images));
    }
    if sources.is_empty() {
        return Err(AppError::flag(
            "--recording",
            format!("{}: no erased or camera frames", recording.display()),
        ));
    }
    Ok(sources)
}

/// `img` cropped about its centre to the aspect of `width` x `height` and scaled to it.
pub fn fit(img: &image::RgbaImage, width: u32, height: u32) -> image::RgbaImage {
    let (w, h) = img.dimensions();
    let target = f64::from(width) / f64::from(height);
    let (cw, ch) = if f64::from(w) / f64::from(h) > target {
        (((f64::from(h) * target).round() as u32).clamp(1, w), h)
    } else {
        (w, ((f64::from(w) / target).round() as u32).clamp(1, h))
    };
    let crop = image::imageops::crop_imm(img, (w - cw) / 2, (h - ch) / 2, cw, ch).to_image();
    if (cw, ch) == (width, height) {
        crop
    } else {
        image::imageops::resize(&crop, width, height, image::imageops::FilterType::Triangle)
    }
}

/// Codes `frames` (all `width` x `height`) with `settings`, decoding each as a viewer would.
fn code(
    source: &str,
    frames: &[image::RgbaImage],
    settings: EncoderSettings,
    fps: f64,
) -> Result<VideoPoint, AppError> {
    let mut encoder = VideoEncoder::new(settings)?;
    let mut decoder = VideoDecoder::new();
    let (width, height) = frames[0].dimensions();
    let (mut encode, mut decode, mut psnr) = (Vec::new(), Vec::new(), Vec::new());
    let (mut key_bytes, mut keys, mut delta_bytes, mut deltas) = (0usize, 0usize, 0usize, 0usize);
    let mut skipped = 0;
    let mut shown: Option<Vec<u8>> = None;
    for (i, frame) in frames.iter().enumerate() {
        let now = i as f64 / fps;
        let started = Instant::now();
        let coded = encoder.encode(frame.as_raw(), width, height, now, false)?;
        encode.push(started.elapsed().as_secs_f64() * 1e3);
        let Some(coded) = coded else {
            // Skipped: the viewer keeps the frame before.
            skipped += 1;
            if let Some(before) = &shown {
                psnr.push(psnr_rgba(frame.as_raw(), before).unwrap_or(f64::NAN));
            }
            continue;
        };
        if coded.keyframe {
            key_bytes += coded.bytes.len();
            keys += 1;
        } else {
            delta_bytes += coded.bytes.len();
            deltas += 1;
        }
        let header = FrameHeader {
            v: PROTOCOL_VERSION,
            camera: "bench".into(),
            index: i as u64,
            codec: settings.codec.name().into(),
            seq: coded.seq,
            stream: coded.stream,
            keyframe: coded.keyframe,
            width,
            height,
            capture_s: now,
            arrived_s: now,
            erased_s: now,
            sent_s: now,
            arrived_update: 0,
            handed_update: 0,
            camera_pose: FrameHeader::pose_of(&nalgebra::Isometry3::identity()),
        };
        let started = Instant::now();
        let decoded = decoder.decode(&header, &coded.bytes)?;
        decode.push(started.elapsed().as_secs_f64() * 1e3);
        match decoded {
            Decoded::Image { rgba, .. } => {
                psnr.push(psnr_rgba(frame.as_raw(), &rgba).unwrap_or(f64::NAN));
                shown = Some(rgba);
            }
            Decoded::Stale => {
                return Err(AppError::command(
                    "bench video",
                    format!(
                        "{} frame {i} of an unbroken stream was taken as stale",
                        settings.codec
                    ),
                ));
            }
            Decoded::NeedKeyframe { reason } => {
                return Err(AppError::command(
                    "bench video",
                    format!(
                        "{} frame {i} of an unbroken stream did not decode: {reason}",
                        settings.codec
                    ),
                ));
            }
        }
    }
    let n = frames.len();
    let kb = |bytes: usize, count: usize| {
        if count == 0 {
            f64::NAN
        } else {
            bytes as f64 / count as f64 / 1e3
        }
    };
    Ok(VideoPoint {
        source: source.into(),
        width,
        height,
        codec: settings.codec.name().into(),
        encoder: match settings.codec {
            Codec::Jpeg => settings.jpeg_encoder.name().into(),
            Codec::H264 => "openh264".into(),
        },
        setting: match settings.codec {
            Codec::Jpeg => f64::from(settings.jpeg_quality),
            Codec::H264 => f64::from(settings.bitrate_bps) / 1e6,
        },
        frames: n,
        skipped,
        mbit_s: (key_bytes + delta_bytes) as f64 * 8.0 / 1e6 / (n as f64 / fps),
        keyframe_kb: kb(key_bytes, keys),
        delta_kb: kb(delta_bytes, deltas),
        encode_ms: Spread::of(&encode),
        decode_ms: Spread::of(&decode),
        psnr_db: psnr.iter().sum::<f64>() / psnr.len().max(1) as f64,
        psnr_min_db: psnr.iter().copied().fold(f64::INFINITY, f64::min),
        rate_ratio: f64::NAN,
        encode_ratio: f64::NAN,
    })
}

/// The sweep's encoder settings, the baseline first: JPEG at 85 through the `image` crate's
/// encoder; then the SIMD encoder at 85 and the other qualities, then H.264 at each target.
/// Errors name the flag whose value is out of range.
fn sweep_settings(sweep: &VideoSweep) -> Result<Vec<EncoderSettings>, AppError> {
    // The baseline is what coded the robot site's video before the SIMD encoder.
    let mut settings = vec![
        EncoderSettings {
            codec: Codec::Jpeg,
            jpeg_quality: 85,
            jpeg_encoder: avatarm_net::codec::JpegEncoder::Image,
            ..EncoderSettings::default()
        },
        EncoderSettings {
            codec: Codec::Jpeg,
            jpeg_quality: 85,
            ..EncoderSettings::default()
        },
    ];
    settings.extend(
        sweep
            .jpeg_qualities
            .iter()
            .filter(|&&q| q != 85)
            .map(|&q| EncoderSettings {
                codec: Codec::Jpeg,
                jpeg_quality: q,
                ..EncoderSettings::default()
            }),
    );
    for &m in &sweep.h264_mbit_s {
        if !(m.is_finite() && (0.01..=200.0).contains(&m)) {
            return Err(AppError::flag(
                "--h264",
                format!("{m} Mbit/s must be 0.01..=200"),
            ));
        }
        settings.push(EncoderSettings {
            codec: Codec::H264,
            bitrate_bps: (m * 1e6).round() as u32,
            ..EncoderSettings::default()
        });
    }
    for s in &mut settings {
        s.fps = sweep.fps as f32;
        s.keyframe_interval_s = sweep.keyframe_interval_s;
        s.validate()?;
    }
    Ok(settings)
}

/// Runs the sweep on each named source of frames, writes `video_codecs.csv` and the chart
/// into `out`.
pub fn run_video(
    sources: &[(String, Vec<image::RgbaImage>)],
    sweep: &VideoSweep,
    out: &Path,
) -> Result<VideoOutputs, AppError> {
    if sources.is_empty() || sources.iter().any(|(_, f)| f.is_empty()) {
        return Err(AppError::flag("--recording", "no frames"));
    }
    if !(sweep.fps.is_finite() && (1.0..=240.0).contains(&sweep.fps)) {
        return Err(AppError::flag(
            "--fps",
            format!("{} must be 1..=240", sweep.fps),
        ));
    }
    if sweep.frames == 0 {
        return Err(AppError::flag("--frames", "must be at least 1"));
    }
    for &(w, h) in &sweep.sizes {
        if !(w.is_multiple_of(2)
            && h.is_multiple_of(2)
            && (16..=4096).contains(&w)
            && (16..=4096).contains(&h))
        {
            return Err(AppError::flag(
                "--sizes",
                format!("{w}x{h}: each side even, 16..=4096"),
            ));
        }
    }
    let settings = sweep_settings(sweep)?;
    std::fs::create_dir_all(out).map_err(|e| AppError::write(out, e))?;
    let bar = crate::progress::bar(
        (sources.len() * sweep.sizes.len() * settings.len()) as u64,
        "video",
        sweep.progress,
    );
    let mut points = Vec::new();
    for ((name, frames), &(w, h)) in sources
        .iter()
        .flat_map(|s| sweep.sizes.iter().map(move |z| (s, z)))
    {
        let sized: Vec<image::RgbaImage> = (0..sweep.frames)
            .map(|i| fit(&frames[i % frames.len()], w, h))
            .collect();
        let first = points.len();
        for s in &settings {
            bar.set_message(format!("{name} {w}x{h} {}", s.codec));
            points.push(code(name, &sized, *s, sweep.fps)?);
            bar.inc(1);
        }
        // The baseline (JPEG at 85) is this size's first point.
        let (rate, enc) = (points[first].mbit_s, points[first].encode_ms.median);
        for p in &mut points[first..] {
            p.rate_ratio = p.mbit_s / rate;
            p.encode_ratio = p.encode_ms.median / enc;
        }
    }
    bar.finish_and_clear();
    let csv = out.join("video_codecs.csv");
    write_table(
        &csv,
        "source,width,height,codec,encoder,setting,frames,skipped,mbit_s,keyframe_kb,delta_kb,\
encode_ms_median,encode_ms_p95,decode_ms_median,decode_ms_p95,psnr_db,psnr_min_db,rate_vs_jpeg85,\
encode_vs_jpeg85",
        points.iter().map(|p| {
            format!(
                "{},{},{},{},{},{},{},{},{:.3},{:.2},{:.2},{:.2},{:.2},{:.2},{:.2},{:.2},{:.2},{:.3},{:.3}",
                p.source,
                p.width,
                p.height,
                p.codec,
                p.encoder,
                p.setting,
                p.frames,
                p.skipped,
                p.mbit_s,
                p.keyframe_kb,
                p.delta_kb,
                p.encode_ms.median,
                p.encode_ms.p95,
                p.decode_ms.median,
                p.decode_ms.p95,
                p.psnr_db,
                p.psnr_min_db,
                p.rate_ratio,
                p.encode_ratio
            )
        }),
    )?;
    let svg = out.join("video_codecs.svg");
    let png = out.join("video_codecs.png");
    let title = format!(
        "Video codecs: quality against bit rate at {} fps ({} frames each of {} video)",
        sweep.fps,
        sweep.frames,
        sources
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>()
            .join(" and ")
    );
    save_chart(
        &VideoChart {
            points: &points,
            sizes: &sweep.sizes,
            title: &title,
        },
        (560 * sweep.sizes.len().max(1) as u32, 560),
        &svg,
        &png,
    )?;
    Ok(VideoOutputs {
        points,
        csv,
        svg,
        png,
    })
}

struct VideoChart<'a> {
    points: &'a [VideoPoint],
    sizes: &'a [(u32, u32)],
    title: &'a str,
}

impl Chart for VideoChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(self.title, ("sans-serif", 18)).map_err(err)?;
        let panels = root.split_evenly((1, self.sizes.len().max(1)));
        for (area, &(w, h)) in panels.iter().zip(self.sizes) {
            let here: Vec<&VideoPoint> = self
                .points
                .iter()
                .filter(|p| (p.width, p.height) == (w, h))
                .collect();
            let x = padded(here.iter().map(|p| p.mbit_s).chain([0.0]));
            let y = padded(here.iter().map(|p| p.psnr_db));
            let mut chart = axes(
                area,
                (0.0, x.1),
                y,
                &format!("{w}x{h}: bit rate (Mbit/s)"),
                "PSNR after coding (dB)",
            )?;
            let mut series: Vec<(&str, &str, &str)> = Vec::new();
            for p in &here {
                let key = (p.source.as_str(), p.codec.as_str(), p.encoder.as_str());
                if !series.contains(&key) {
                    series.push(key);
                }
            }
            for (i, &(source, codec, encoder)) in series.iter().enumerate() {
                let colour = Palette99::pick(i).to_rgba();
                let mut pts: Vec<&&VideoPoint> = here
                    .iter()
                    .filter(|p| p.codec == codec && p.source == source && p.encoder == encoder)
                    .collect();
                pts.sort_by(|a, b| a.mbit_s.total_cmp(&b.mbit_s));
                chart
                    .draw_series(LineSeries::new(
                        pts.iter().map(|p| (p.mbit_s, p.psnr_db)),
                        colour.stroke_width(2),
                    ))
                    .map_err(err)?
                    .label(if codec == "jpeg" {
                        format!("{source} frames, JPEG (quality), {encoder}")
                    } else {
                        format!("{source} frames, H.264 (target Mbit/s)")
                    })
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                    });
                chart
                    .draw_series(pts.iter().map(|p| {
                        EmptyElement::at((p.mbit_s, p.psnr_db))
                            + Circle::new((0, 0), 4, colour.filled())
                            + Text::new(
                                if codec == "jpeg" {
                                    format!("q{}", p.setting)
                                } else {
                                    format!("{}", p.setting)
                                },
                                (6, -16),
                                ("sans-serif", 12).into_font().color(&BLACK),
                            )
                    }))
                    .map_err(err)?;
            }
            legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<image::RgbaImage> {
        (0..6u32)
            .map(|t| {
                image::RgbaImage::from_fn(96, 64, |x, y| {
                    let v = ((x + 3 * t) * 255 / 100) as u8;
                    image::Rgba([v, (y * 4) as u8, 90, 255])
                })
            })
            .collect()
    }

    #[test]
    fn fit_crops_to_the_aspect_then_scales() {
        let img = image::RgbaImage::from_fn(400, 100, |x, _| image::Rgba([x as u8, 0, 0, 255]));
        let out = fit(&img, 64, 32);
        assert_eq!(out.dimensions(), (64, 32));
        // The middle 200 px kept: the left edge is near x = 100.
        assert!((i32::from(out.get_pixel(0, 16)[0]) - 100).abs() <= 4);
    }

    #[test]
    fn the_sweep_writes_a_row_per_setting_with_ratios_to_jpeg_85() {
        let dir = std::env::temp_dir().join(format!("avatarm_bench_video_{}", std::process::id()));
        let sweep = VideoSweep {
            sizes: vec![(64, 48)],
            jpeg_qualities: vec![50, 85],
            h264_mbit_s: vec![0.2],
            frames: 8,
            ..VideoSweep::default()
        };
        let out = run_video(&[("test".into(), frames())], &sweep, &dir).unwrap();
        // The image crate's JPEG at 85 (the baseline), the SIMD encoder's at 85 and 50, H.264.
        assert_eq!(out.points.len(), 4);
        assert_eq!(out.points[0].setting, 85.0);
        assert_eq!(out.points[0].encoder, "image");
        assert_eq!(out.points[0].rate_ratio, 1.0);
        assert_eq!(out.points[1].encoder, "jpeg-encoder (SIMD)");
        // The same quality from either encoder: about the same bits.
        assert!(
            (0.5..2.0).contains(&out.points[1].rate_ratio),
            "{:?}",
            out.points[1]
        );
        assert!(
            out.points
                .iter()
                .all(|p| p.psnr_db > 20.0 && p.mbit_s > 0.0),
            "{:?}",
            out.points
        );
        // Lower JPEG quality, fewer bits.
        assert!(out.points[2].mbit_s < out.points[1].mbit_s);
        let csv = std::fs::read_to_string(&out.csv).unwrap();
        assert_eq!(csv.lines().count(), 5);
        assert!(out.png.is_file() && out.svg.is_file());
        let bad = VideoSweep {
            sizes: vec![(63, 48)],
            ..sweep
        };
        let e = run_video(&[("test".into(), frames())], &bad, &dir).unwrap_err();
        assert!(e.to_string().contains("63x48"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
