//! The benches (`avatarm bench ...`): each writes its chart and table, with a baseline measured in
//! the same run.

use super::*;

/// `avatarm bench twin` on two twins: the table, the chart, and the simplified twin lighter.
#[test]
fn bench_twin_writes_the_chart_and_the_table() {
    if let Err(why) = avatarm_core::shared_data::ros_packages() {
        return why.skip("bench_twin_writes_the_chart_and_the_table");
    }
    let out = out_dir("bench_twin");
    let run = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["bench", "twin", "--out"])
        .arg(&out)
        .args([
            "--variants",
            "visual,keep:0.1",
            "--duration",
            "0.8",
            "--frames-every",
            "3",
        ])
        .output()
        .expect("runs avatarm");
    let stdout = succeeded(&run);
    assert!(stdout.contains("ratios against 'visual'"), "{stdout}");
    let table = Table::read(&out.join("twin_detail.csv"));
    assert_eq!(table.rows.len(), 2, "{}", table.text);
    let cell = |row: usize, name: &str| table.number(row, name);
    let csv = &table.text;
    let (full, light) = (cell(0, "triangles"), cell(1, "triangles"));
    assert!(
        light < 0.15 * full && light > 0.05 * full,
        "{light} of {full}: {csv}"
    );
    for row in 0..2 {
        assert!(cell(row, "gpu_mask_twin_ms") > 0.0, "{csv}");
        assert!(cell(row, "dilate_for_1pct") >= 0.0, "{csv}");
    }
    // The full meshes draw the robot's own silhouette.
    assert!(cell(0, "leak_pct_mean") < 0.1, "{csv}");
    let svg = std::fs::read_to_string(out.join("twin_detail.svg")).expect("svg");
    assert!(svg.contains("Pareto front") && svg.contains("keep 10%"));
}

/// `avatarm bench head` on two speeds and one latency: a row per point, the mount series, the
/// background series, the chart.
#[test]
fn bench_head_writes_the_chart_and_the_table() {
    let out = out_dir("bench_head");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["bench", "head", "--out"])
        .arg(&out)
        .args([
            "--speeds",
            "0,60",
            "--latencies",
            "50",
            "--compensation",
            "off,on",
            "--mount-errors",
            "0,3",
            "--mount-speed",
            "60",
            "--mount-latency",
            "50",
            "--background-views",
            "0,8",
            "--duration",
            "0.8",
            "--camera-size",
            "320x240",
        ])
        .output()
        .expect("runs avatarm");
    let stdout = succeeded(&output);
    let table = Table::read(&out.join("head_erase.csv"));
    let csv = &table.text;
    // 2 speeds x 2 settings; the mount series' 3 degrees and the background series' plain
    // photograph (their other points are in the grid).
    assert_eq!(table.rows.len(), 6, "{csv}\n{stdout}");
    let leak = |row: usize| table.number(row, "leak_pct_mean");
    let psnr = |row: usize| table.number(row, "psnr_db_mean");
    // Rows: (0, off), (0, on), (60, off), (60, on), (60, on, 3 deg), (60, on, the photograph).
    assert!(
        leak(2) > leak(3) + 1.0,
        "60 deg/s: the newest pose leaks: {csv}"
    );
    assert!(
        leak(4) > leak(3) + 1.0,
        "a 3 degree mount error leaks: {csv}"
    );
    assert!(table.number(3, "camera_error_deg_median") < 0.1, "{csv}");
    for row in 0..table.rows.len() {
        let iou = table.number(row, "iou_mean");
        assert!(iou > 0.3 && iou <= 1.0, "{csv}");
        assert!(table.number(row, "frame_ms_median") > 0.0, "{csv}");
    }
    assert_eq!(table.number(5, "background_views"), 0.0, "{csv}");
    assert!(
        psnr(3) > psnr(5) + 3.0,
        "the background that follows the view beats the one photograph: {csv}"
    );
    assert!(
        table.cell(3, "psnr_db_by_photo_angle").contains("deg:"),
        "{csv}"
    );
    let svg = std::fs::read_to_string(out.join("head_erase.svg")).expect("svg");
    assert!(svg.contains("goal: 1 %") && svg.contains("mount"), "svg");
    assert!(svg.contains("the photograph as it is"), "svg");
    let png = image::open(out.join("head_erase.png")).expect("png");
    assert!(png.width() >= 1500);
}

/// `avatarm bench dr` on a two-point sweep: table, chart and fronts, and a coarser mask that
/// does cost accuracy.
#[test]
fn bench_dr_writes_the_chart_and_the_table() {
    let out = out_dir("bench_dr");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["bench", "dr", "--out"])
        .arg(&out)
        .args([
            "--scales",
            "1,0.25",
            "--dilate",
            "0",
            "--feather",
            "0",
            "--latency",
            "on",
            "--duration",
            "0.6",
        ])
        .output()
        .expect("runs avatarm");
    let stdout = succeeded(&status);
    assert!(stdout.contains("ratios against 'x1 d0 f0 LC'"), "{stdout}");
    let table = Table::read(&out.join("dr_speed_accuracy.csv"));
    let csv = &table.text;
    assert_eq!(table.rows.len(), 2, "{csv}");
    let leak = |row: usize| table.number(row, "leak_pct_mean");
    assert!(leak(1) > leak(0) + 0.5, "{csv}");
    // The full-resolution point is the least leaky, so it is on both leak fronts.
    assert_eq!(table.cell(0, "pareto_leak"), "true", "{csv}");
    assert_eq!(table.cell(0, "pareto_leak_gpu"), "true", "{csv}");
    // Each setting's passes were timed on the GPU (llvmpipe has timestamp queries).
    for row in 0..2 {
        for column in ["gpu_mask_ms", "gpu_composite_ms"] {
            assert!(table.number(row, column) > 0.0, "{column}: {csv}");
        }
    }
    let svg = std::fs::read_to_string(out.join("dr_speed_accuracy.svg")).expect("svg");
    assert!(svg.contains("Pareto front"));
    let png = image::open(out.join("dr_speed_accuracy.png")).expect("png");
    assert!(png.width() >= 800);
}

/// `avatarm bench gpu` at two small sizes, one and two cameras, with dilation and feathering
/// (every pass): a row per point and span, the floor measured in the same run, the chart.
#[test]
fn bench_gpu_writes_the_chart_and_the_table() {
    let out = out_dir("bench_gpu");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["bench", "gpu", "--out"])
        .arg(&out)
        .args([
            "--sizes",
            "160x120,320x240",
            "--cameras",
            "1,2",
            "--frames",
            "12",
            "--dilate",
            "2",
            "--feather",
            "1",
        ])
        .output()
        .expect("runs avatarm");
    let stdout = succeeded(&status);
    assert!(stdout.contains("erase/fl"), "{stdout}");
    let table = Table::read(&out.join("gpu_erase.csv"));
    let csv = &table.text;
    let row = |w: &str, cams: &str, span: &str| {
        (0..table.rows.len()).find(|&r| {
            table.cell(r, "width") == w
                && table.cell(r, "cameras") == cams
                && table.cell(r, "span") == span
        })
    };
    for (w, cams) in [("160", "1"), ("160", "2"), ("320", "1"), ("320", "2")] {
        for span in [
            "erase (all cameras)",
            "passes (all cameras)",
            "copy floor (all cameras)",
        ] {
            let r = row(w, cams, span).unwrap_or_else(|| panic!("{w} x{cams} {span}: {csv}"));
            assert!(table.number(r, "median_ms") > 0.0, "{csv}");
            assert!(table.number(r, "ratio_to_floor").is_finite(), "{csv}");
        }
    }
    // Each camera's own passes, by name.
    for span in [
        "camera 2: mask twin",
        "camera 2: feather rows",
        "camera 2: copy floor",
    ] {
        let r = row("320", "2", span).unwrap_or_else(|| panic!("{span}: {csv}"));
        assert!(table.number(r, "samples") >= 8.0, "{csv}");
    }
    assert!(row("320", "1", "dilate columns").is_some(), "{csv}");
    let svg = std::fs::read_to_string(out.join("gpu_erase.svg")).expect("svg");
    assert!(svg.contains("copy floor"));
    let png = image::open(out.join("gpu_erase.png")).expect("png");
    assert!(png.width() >= 800);
    // A size that has no pixels is refused by name.
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["bench", "gpu", "--sizes", "0x480", "--out"])
        .arg(&out)
        .output()
        .expect("runs avatarm");
    assert!(!status.status.success());
    assert!(String::from_utf8_lossy(&status.stderr).contains("0x480"));
}

/// `avatarm bench chess` on the chess scene cut to two moves, one trial, both delays: a CSV row
/// per move and case, the summaries as JSON (read back as their type), the chart; every move
/// lands, and with intent the real grasp comes sooner.
#[test]
fn bench_chess_writes_the_chart_the_table_and_the_summaries() {
    let out = out_dir("bench_chess");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/chess.toml");
    let text = std::fs::read_to_string(&path).expect("chess.toml");
    let moves = "moves = [\"e2e4\", \"e7e5\", \"g1f3\", \"b8c6\", \"d2d4\"]";
    assert!(text.contains(moves), "the scene's opening changed");
    let short = text.replace(moves, "moves = [\"e2e4\", \"e7e5\"]").replace(
        "\"../robots/",
        &format!("\"{}/assets/robots/", env!("CARGO_MANIFEST_DIR")),
    );
    std::fs::create_dir_all(&out).expect("out");
    let scene = out.join("chess_short.toml");
    std::fs::write(&scene, short).expect("scene");
    let run = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["bench", "chess"])
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .args(["--trials", "1", "--delay-ms", "0,100"])
        .output()
        .expect("runs avatarm");
    let stdout = succeeded(&run);
    assert!(
        stdout.contains("no intent") && stdout.contains("chess.png"),
        "{stdout}"
    );
    let table = Table::read(&out.join("chess.csv"));
    assert_eq!(table.rows.len(), 2 * 4, "{}", table.text);
    for row in 0..table.rows.len() {
        assert_eq!(table.cell(row, "correct"), "true", "{}", table.text);
        assert!(table.number(row, "place_error_mm") < 5.0, "{}", table.text);
    }
    let json = std::fs::read_to_string(out.join("chess.json")).expect("json");
    let report: avatarm_mapping::chess::ChessReport = serde_json::from_str(&json).expect("typed");
    assert_eq!(report.conditions.len(), 4);
    for delay in [0.0, 100.0] {
        let case = |intent: bool| {
            report
                .conditions
                .iter()
                .find(|c| c.intent == intent && c.delay_ms == delay)
                .expect("case")
                .summary
                .grasp_delay_ms
                .median
        };
        assert!(
            case(true) < case(false),
            "{delay} ms: {} vs {}",
            case(true),
            case(false)
        );
    }
    let svg = std::fs::read_to_string(out.join("chess.svg")).expect("svg");
    assert!(svg.contains("no intent") && svg.contains("goal 150"), "svg");
    assert!(out.join("chess.png").is_file());
}
