//! `avatarm bench gpu`: the erase's GPU time per pass at several frame sizes and for one or
//! several cameras, beside a floor measured in the same run on the same GPU: a plain copy of
//! the images the passes read (the mask twin's render, the live frame, H). The ratio to the
//! floor says how far the passes are from what the memory allows; on a software renderer
//! (llvmpipe) both are CPU work and the ratio is what stays comparable between machines.
//!
//! Each point is a headless app with the erase alone, no simulated room: the scene's mask twin
//! (its description, `[twin]` detail and occluders) moves along the scene's timeline, the
//! believed camera's pose and vertical field of view at each size, a new synthetic live frame
//! uploaded every update and H once, and every pass run every update (as for a camera frame on
//! every display frame). A warm-up runs first; its times are left out. Where `nvidia-smi`
//! exists, the GPU's SM clock is read before and after each point: a GPU left idle by a light
//! load stays at its idle clock, and its times are then not the hardware's floor.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use avatarm_core::dr::{EraseSettings, Photometric};
use avatarm_core::rng::Rng;
use avatarm_core::robot::JointMap;
use avatarm_core::stats::Spread;
use avatarm_core::vision::camera::{Intrinsics, PinholeCamera};
use avatarm_erase::{
    EraseJob, EraseParams, ErasePassesPlugin, FLOOR_SPAN, GpuTimes, PASS_NAMES, SpanTimes,
    UPLOAD_SPAN, composite_image,
};
use avatarm_scene::Scene;
use avatarm_twin::flat::{FlatPart, FlatView, flat_target_image};
use avatarm_twin::layers;
use avatarm_twin::prelude::*;
use bevy::app::ScheduleRunnerPlugin;
use bevy::camera::visibility::RenderLayers;
use bevy::log::LogPlugin;
use bevy::prelude::{
    App, AppExit, Assets, Commands, Entity, Image, Mesh3d, MessageWriter, Query, Res, ResMut,
    Resource, Startup, UVec2, Update,
};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::AppError;
use crate::bench::chart::{self, Chart, axes, drawing_error, legend, padded, save_chart};

/// What `avatarm bench gpu` measures.
#[derive(Debug, Clone)]
pub struct GpuSweep {
    /// Frame sizes (px).
    pub sizes: Vec<(u32, u32)>,
    /// Cameras erased per update (each its own mask render and passes).
    pub cameras: Vec<u32>,
    /// Updates measured per point (after the warm-up).
    pub frames: u32,
    /// The mask's dilation (px).
    pub dilate_px: u32,
    /// Feathering (px).
    pub feather_px: u32,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for GpuSweep {
    fn default() -> Self {
        Self {
            sizes: vec![(640, 480), (1280, 720), (1920, 1080)],
            cameras: vec![1, 2],
            frames: 120,
            dilate_px: 0,
            feather_px: 0,
            progress: false,
        }
    }
}

/// Updates before the measured ones (pipelines, first uploads).
const WARMUP: u32 = 20;

/// Updates after the measured ones for their timestamps to come back.
const DRAIN: u32 = 12;

/// One point: a frame size and a number of cameras.
#[derive(Debug, Clone)]
pub struct GpuPoint {
    /// Frame size (px).
    pub size: (u32, u32),
    /// Cameras.
    pub cameras: u32,
    /// Every camera's whole erase per update (mask twin and passes, all cameras summed).
    pub erase: Spread,
    /// The same without the mask twin's render: threshold, dilation, feathering, composite.
    pub passes: Spread,
    /// The mask twin's flat render, all cameras.
    pub mask_twin: Spread,
    /// The uploads' GPU copies, all cameras.
    pub upload: Option<Spread>,
    /// The floor: a copy of the images the passes read, all cameras.
    pub floor: Spread,
    /// Each span's own times (name, spread, samples).
    pub spans: Vec<(String, Spread, usize)>,
    /// Wall time per update of the bench app (ms, median).
    pub update_ms: f64,
    /// The GPU's clock before and after, where `nvidia-smi` reports it.
    pub clock: Option<String>,
}

impl GpuPoint {
    /// The whole erase over the floor (medians).
    pub fn erase_over_floor(&self) -> f64 {
        self.erase.median / self.floor.median
    }

    /// The passes without the twin's render over the floor (medians).
    pub fn passes_over_floor(&self) -> f64 {
        self.passes.median / self.floor.median
    }
}

/// What the bench wrote.
#[derive(Debug, Clone)]
pub struct GpuOutputs {
    /// The points, in sweep order.
    pub points: Vec<GpuPoint>,
    /// One line per point and span.
    pub csv: PathBuf,
    /// The chart.
    pub svg: PathBuf,
    /// The chart as an image.
    pub png: PathBuf,
}

/// Runs the sweep with `scene`'s robot, camera and erase settings, writing into `out`.
pub fn run_gpu(scene: &Scene, sweep: &GpuSweep, out: &Path) -> Result<GpuOutputs, AppError> {
    if sweep.sizes.is_empty() || sweep.cameras.is_empty() {
        return Err(AppError::flag(
            "bench gpu",
            "the sweep is empty: give at least one size and one camera count",
        ));
    }
    if let Some(&(w, h)) = sweep.sizes.iter().find(|&&(w, h)| w == 0 || h == 0) {
        return Err(AppError::flag("--sizes", format!("{w}x{h} has no pixels")));
    }
    if let Some(&n) = sweep.cameras.iter().find(|&&n| n == 0 || n > 8) {
        return Err(AppError::flag("--cameras", format!("{n}: give 1 to 8")));
    }
    if sweep.frames < 10 {
        return Err(AppError::flag(
            "--frames",
            format!("{} is too few to time (10 or more)", sweep.frames),
        ));
    }
    let mut settings = scene.file.erase;
    (settings.dilate_px, settings.feather_px) = (sweep.dilate_px, sweep.feather_px);
    settings.validate("bench gpu")?;
    chart::register_font()?;
    std::fs::create_dir_all(out).map_err(|source| AppError::Io {
        path: out.to_owned(),
        action: "create",
        source,
    })?;
    let runs: Vec<((u32, u32), u32)> = sweep
        .sizes
        .iter()
        .flat_map(|&s| sweep.cameras.iter().map(move |&n| (s, n)))
        .collect();
    let bar = crate::progress::bar(runs.len() as u64, "bench gpu", sweep.progress);
    let mut points = Vec::with_capacity(runs.len());
    for (size, cameras) in runs {
        bar.set_message(format!("{}x{} x{cameras}", size.0, size.1));
        points.push(measure(scene, &settings, size, cameras, sweep.frames)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let csv = out.join("gpu_erase.csv");
    write_csv(&csv, &points)?;
    let (svg, png) = (out.join("gpu_erase.svg"), out.join("gpu_erase.png"));
    save_chart(
        &GpuChart {
            points: &points,
            title: format!(
                "Erase GPU time ({}, dilate {} px, feather {} px)",
                scene.file.name, settings.dilate_px, settings.feather_px
            ),
        },
        (1100, 520),
        &svg,
        &png,
    )?;
    Ok(GpuOutputs {
        points,
        csv,
        svg,
        png,
    })
}

/// The bench app's state.
#[derive(Resource)]
struct Bench {
    scene: Scene,
    settings: EraseSettings,
    size: (u32, u32),
    cameras: u32,
    frames: u32,
    update: u32,
    twin: Option<Entity>,
    jobs: Vec<Entity>,
    live: [Arc<Vec<u8>>; 2],
    background: Arc<Vec<u8>>,
    marks: std::collections::BTreeMap<String, u64>,
    last: Option<Instant>,
    update_ms: Vec<f64>,
    result: Arc<Mutex<Option<Measured>>>,
}

/// What a point's app hands back when it stops: the spans, their counts at the warm-up's end,
/// and the wall time of each measured update (ms).
type Measured = (SpanTimes, std::collections::BTreeMap<String, u64>, Vec<f64>);

/// A span name of camera `i` of `n` (no prefix with one camera).
fn label(i: u32, n: u32) -> String {
    if n == 1 {
        String::new()
    } else {
        format!("camera {}: ", i + 1)
    }
}

fn measure(
    scene: &Scene,
    settings: &EraseSettings,
    size: (u32, u32),
    cameras: u32,
    frames: u32,
) -> Result<GpuPoint, AppError> {
    let clock_before = gpu_clock();
    let result = Arc::new(Mutex::new(None));
    let pixels = (size.0 * size.1 * 4) as usize;
    let noise = |seed: u64| {
        let mut rng = Rng::stream(0x6770_7500, seed);
        Arc::new(
            (0..pixels)
                .map(|i| {
                    if i % 4 == 3 {
                        255
                    } else {
                        (rng.next_u64() >> 56) as u8
                    }
                })
                .collect::<Vec<u8>>(),
        )
    };
    let mut app = App::new();
    let mut plugins = crate::app::headless_plugins();
    // The process's logger is set once, by the first point's app.
    static LOGGING: std::sync::Once = std::sync::Once::new();
    let mut first = false;
    LOGGING.call_once(|| first = true);
    if !first {
        plugins = plugins.disable::<LogPlugin>();
    }
    app.add_plugins((
        plugins,
        ScheduleRunnerPlugin::run_loop(Duration::ZERO),
        RobotTwinPlugin,
    ));
    app.add_plugins(ErasePassesPlugin)
        .insert_resource(Bench {
            scene: scene.clone(),
            settings: *settings,
            size,
            cameras,
            frames,
            update: 0,
            twin: None,
            jobs: Vec::new(),
            live: [noise(1), noise(2)],
            background: noise(3),
            marks: Default::default(),
            last: None,
            update_ms: Vec::new(),
            result: result.clone(),
        })
        .add_systems(Startup, setup_bench)
        .add_systems(Update, drive_bench);
    app.run();
    let (times, marks, update_ms) =
        result
            .lock()
            .ok()
            .and_then(|mut r| r.take())
            .ok_or_else(|| {
                AppError::command("bench gpu", "the app stopped before its times arrived")
            })?;
    let update_ms = Spread::some_of(&update_ms).map_or(f64::NAN, |s| s.median);
    let clock = match (clock_before, gpu_clock()) {
        (Some(a), Some(b)) => Some(format!("before: {a}; after: {b}")),
        _ => None,
    };
    summarise(&times, &marks, size, cameras, update_ms, clock)
}

/// The point's figures out of the spans timed after the warm-up.
fn summarise(
    times: &SpanTimes,
    marks: &std::collections::BTreeMap<String, u64>,
    size: (u32, u32),
    cameras: u32,
    update_ms: f64,
    clock: Option<String>,
) -> Result<GpuPoint, AppError> {
    if let Some(why) = &times.unavailable {
        return Err(AppError::command("bench gpu", why.clone()));
    }
    let since = |name: &str| times.since(name, marks.get(name).copied().unwrap_or(0));
    // Per update, summed over the spans given (of every camera): the n-th sample of each span
    // is the same update's (a frame's spans arrive together or not at all).
    // A span that some camera timed and another did not (the frame's spans ran out) would sum
    // fewer cameras than the point says: refused.
    let mut missing = Vec::new();
    let mut per_update = |names: &[&str]| -> Vec<f64> {
        let mut series = Vec::new();
        for n in names {
            let of_each: Vec<(String, Vec<f64>)> = (0..cameras)
                .map(|i| format!("{}{n}", label(i, cameras)))
                .map(|name| {
                    let v = since(&name);
                    (name, v)
                })
                .collect();
            if of_each.iter().any(|(_, v)| v.is_empty()) {
                if of_each.iter().any(|(_, v)| !v.is_empty()) {
                    missing.extend(
                        of_each
                            .iter()
                            .filter(|(_, v)| v.is_empty())
                            .map(|(name, _)| name.clone()),
                    );
                }
                continue;
            }
            series.extend(of_each.into_iter().map(|(_, v)| v));
        }
        let n = series.iter().map(Vec::len).min().unwrap_or(0);
        (0..n).map(|k| series.iter().map(|s| s[k]).sum()).collect()
    };
    let need = |what: &str, v: Vec<f64>| {
        Spread::some_of(&v).ok_or_else(|| {
            AppError::command(
                "bench gpu",
                format!(
                    "bench gpu {}x{} x{cameras}: no {what} time arrived",
                    size.0, size.1
                ),
            )
        })
    };
    let erase = need("erase", per_update(&PASS_NAMES))?;
    let passes = need("pass", per_update(&PASS_NAMES[1..]))?;
    let mask_twin = need("mask twin", per_update(&PASS_NAMES[..1]))?;
    let floor = need("copy floor", per_update(&[FLOOR_SPAN]))?;
    let upload = Spread::some_of(&per_update(&[UPLOAD_SPAN]));
    if !missing.is_empty() {
        missing.sort();
        missing.dedup();
        return Err(AppError::command(
            "bench gpu",
            format!(
                "bench gpu {}x{} x{cameras}: some cameras were not timed ({})",
                size.0,
                size.1,
                missing.join(", ")
            ),
        ));
    }
    let spans = times
        .spans
        .keys()
        .filter_map(|name| {
            let v = since(name);
            Spread::some_of(&v).map(|s| (name.clone(), s, v.len()))
        })
        .collect();
    Ok(GpuPoint {
        size,
        cameras,
        erase,
        passes,
        mask_twin,
        upload,
        floor,
        spans,
        update_ms,
        clock,
    })
}

fn setup_bench(
    mut commands: Commands,
    mut bench: ResMut<Bench>,
    mut assets: TwinAssets,
    mut images: ResMut<Assets<Image>>,
) {
    let scene = bench.scene.clone();
    let layer = RenderLayers::layer(layers::MASK_TWIN);
    let twin = spawn_twin_with_visuals(
        &mut commands,
        &mut assets,
        &scene.twin_model,
        &scene.robot_base(),
        TwinAppearance::Flat(FlatPart::ROBOT),
        crate::app::twin_detail(&scene.file.twin),
        &layer,
        "bench gpu: mask twin",
    );
    bench.twin = Some(twin.root);
    for (mesh, transform) in crate::app::scene_occluders(&scene) {
        commands.spawn((
            Mesh3d(assets.meshes.add(mesh)),
            FlatPart::OCCLUDER,
            transform,
            layer.clone(),
        ));
    }
    let (w, h) = bench.size;
    let k = Intrinsics::from_fov_y(scene.believed_camera.intrinsics.fov_y_rad(), w, h);
    let raw_k = k.scaled(bench.settings.resolution_scale);
    let camera = PinholeCamera {
        intrinsics: raw_k,
        world_from_camera: scene.believed_camera.world_from_camera,
    };
    for i in 0..bench.cameras {
        let label = label(i, bench.cameras);
        let raw = images.add(flat_target_image(raw_k.width, raw_k.height));
        let job = commands
            .spawn((
                FlatView {
                    camera,
                    target: raw.clone(),
                    clear: 0,
                    active: true,
                    name: format!("{label}{}", PASS_NAMES[0]),
                },
                layer.clone(),
                EraseJob {
                    label,
                    raw,
                    mask: images.add(flat_target_image(w, h)),
                    composite: images.add(composite_image(w, h)),
                    params: EraseParams::new(
                        &bench.settings,
                        &Photometric::default(),
                        true,
                        UVec2::new(raw_k.width, raw_k.height),
                        UVec2::new(w, h),
                    ),
                    render: true,
                    frame: None,
                    background: Some(bench.background.clone()),
                    lens: None,
                    measure_floor: true,
                },
            ))
            .id();
        bench.jobs.push(job);
    }
}

fn drive_bench(
    mut bench: ResMut<Bench>,
    times: Res<GpuTimes>,
    mut twins: Query<&mut RobotTwin>,
    mut jobs: Query<(&mut EraseJob, &mut FlatView)>,
    mut exit: MessageWriter<AppExit>,
) {
    let b = &mut *bench;
    let n = b.update;
    b.update += 1;
    let measuring = n < WARMUP + b.frames;
    if n == WARMUP {
        b.marks = times.marks();
        b.last = Some(Instant::now());
    } else if n > WARMUP && measuring {
        let now = Instant::now();
        if let Some(last) = b.last.replace(now) {
            b.update_ms.push((now - last).as_secs_f64() * 1e3);
        }
    }
    // The arm along the scene's timeline, a camera frame per update.
    let t = f64::from(n) / b.scene.file.camera.fps;
    if let (Some(q), Some(twin)) = (b.scene.trajectory.sample(t), b.twin)
        && let Ok(mut twin) = twins.get_mut(twin)
    {
        twin.positions = JointMap::new(&b.scene.model, &b.scene.twin_model).apply(q.as_slice());
        twin.stamp_s = Some(t);
    }
    for &entity in &b.jobs {
        if let Ok((mut job, mut view)) = jobs.get_mut(entity) {
            job.render = measuring;
            view.active = measuring;
            job.frame = measuring.then(|| b.live[(n % 2) as usize].clone());
            if n > 0 {
                job.background = None;
            }
        }
    }
    if n == WARMUP + b.frames + DRAIN {
        if let Ok(mut slot) = b.result.lock() {
            *slot = Some((
                times.snapshot(),
                b.marks.clone(),
                std::mem::take(&mut b.update_ms),
            ));
        }
        exit.write(AppExit::Success);
    }
}

/// The GPU's name and SM clock (current / maximum), where `nvidia-smi` answers.
fn gpu_clock() -> Option<String> {
    let out = std::process::Command::new("nvidia-smi")
        .args([
            "--query-gpu=name,clocks.sm,clocks.max.sm",
            "--format=csv,noheader",
        ])
        .output()
        .ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    let line = text.lines().next()?.trim().to_owned();
    (out.status.success() && !line.is_empty()).then_some(line)
}

fn write_csv(path: &Path, points: &[GpuPoint]) -> Result<(), AppError> {
    let mut rows = Vec::new();
    for p in points {
        let common = format!("{},{},{}", p.size.0, p.size.1, p.cameras);
        let ratio = |s: &Spread| s.median / p.floor.median;
        for (name, s) in [
            ("erase (all cameras)", p.erase),
            ("passes (all cameras)", p.passes),
            ("mask twin (all cameras)", p.mask_twin),
            ("copy floor (all cameras)", p.floor),
        ] {
            rows.push(format!(
                "{common},{name},{:.4},{:.4},,{:.2},{:.2},\"{}\"",
                s.median,
                s.p95,
                ratio(&s),
                p.update_ms,
                p.clock.as_deref().unwrap_or("")
            ));
        }
        for (name, s, samples) in &p.spans {
            rows.push(format!(
                "{common},{name},{:.4},{:.4},{samples},{:.2},{:.2},\"{}\"",
                s.median,
                s.p95,
                ratio(s),
                p.update_ms,
                p.clock.as_deref().unwrap_or("")
            ));
        }
    }
    chart::write_table(
        path,
        "width,height,cameras,span,median_ms,p95_ms,samples,ratio_to_floor,update_wall_ms,gpu_clock",
        rows,
    )
}

/// A line of the chart: its name, its value at a point, its style (0 strong, 1 light, 2 grey).
type Series = (&'static str, fn(&GpuPoint) -> f64, u8);

/// GPU time against pixels per update: the whole erase and the copy floor for each camera
/// count, and the passes alone.
struct GpuChart<'a> {
    points: &'a [GpuPoint],
    title: String,
}

impl Chart for GpuChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), AppError>
    where
        DB::ErrorType: 'static,
    {
        let err = drawing_error::<DB::ErrorType>;
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(&self.title, ("sans-serif", 20)).map_err(err)?;
        let mp = |p: &GpuPoint| f64::from(p.size.0 * p.size.1 * p.cameras) / 1e6;
        let x = padded(self.points.iter().map(mp).chain([0.0]));
        let y = padded(
            self.points
                .iter()
                .flat_map(|p| [p.erase.median, p.floor.median, p.passes.median])
                .chain([0.0]),
        );
        let mut c = axes(
            &root,
            (0.0, x.1),
            (0.0, y.1),
            "megapixels erased per update (all cameras)",
            "GPU time, ms (median)",
        )?;
        let mut cams: Vec<u32> = self.points.iter().map(|p| p.cameras).collect();
        cams.sort_unstable();
        cams.dedup();
        let colours = [BLUE, GREEN, MAGENTA, CYAN];
        for (ci, &n) in cams.iter().enumerate() {
            let colour = colours[ci % colours.len()];
            let mut pts: Vec<&GpuPoint> = self.points.iter().filter(|p| p.cameras == n).collect();
            pts.sort_by(|a, b| mp(a).total_cmp(&mp(b)));
            let series: [Series; 3] = [
                ("whole erase", |p| p.erase.median, 0),
                ("passes without the twin", |p| p.passes.median, 1),
                ("copy floor", |p| p.floor.median, 2),
            ];
            for (name, value, style) in series {
                let line: Vec<(f64, f64)> = pts.iter().map(|p| (mp(p), value(p))).collect();
                let stroke = match style {
                    0 => colour.stroke_width(3),
                    1 => colour.mix(0.6).stroke_width(2),
                    _ => BLACK.mix(0.5 + 0.2 * ci as f64).stroke_width(1),
                };
                let label = format!("{name}, {n} camera{}", if n == 1 { "" } else { "s" });
                c.draw_series(LineSeries::new(line.clone(), stroke))
                    .map_err(err)?
                    .label(label)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], stroke));
                c.draw_series(line.iter().map(|&xy| Circle::new(xy, 3, stroke.filled())))
                    .map_err(err)?;
            }
        }
        legend(&mut c, SeriesLabelPosition::UpperLeft)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_sums_each_update_over_its_cameras_and_passes() {
        let mut t = SpanTimes::default();
        let mut put = |name: &str, ms: &[f64]| {
            let s = t.spans.entry(name.to_owned()).or_default();
            s.ms.extend(ms.iter().copied());
            s.measured = ms.len() as u64;
        };
        for cam in ["camera 1: ", "camera 2: "] {
            put(&format!("{cam}mask twin"), &[9.0, 1.0, 1.0, 2.0]);
            put(&format!("{cam}composite"), &[9.0, 2.0, 2.0, 3.0]);
            put(&format!("{cam}copy floor"), &[9.0, 0.5, 0.5, 0.5]);
        }
        // The first sample of each span came before the mark: left out.
        let marks = t.marks().into_keys().map(|k| (k, 1)).collect();
        let p = summarise(&t, &marks, (4, 3), 2, 1.0, None).expect("point");
        // Per update: 2 x (1 + 2), 2 x (1 + 2), 2 x (2 + 3) -> median 6.
        assert_eq!(p.erase.median, 6.0);
        assert_eq!(p.erase.p95, 10.0);
        assert_eq!(p.passes.median, 4.0);
        assert_eq!(p.mask_twin.median, 2.0);
        assert_eq!(p.floor.median, 1.0);
        assert_eq!(p.erase_over_floor(), 6.0);
        assert!(p.upload.is_none());
        // A span that never arrived is an error naming it.
        let mut empty = SpanTimes::default();
        empty.spans.insert("mask twin".into(), Default::default());
        let e = summarise(&empty, &Default::default(), (4, 3), 1, 1.0, None).expect_err("no times");
        assert!(e.to_string().contains("no erase time"), "{e}");
    }
}
