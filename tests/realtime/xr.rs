//! XR against a real OpenXR runtime: run when `XR_RUNTIME_JSON` names one, skipped (saying so)
//! otherwise. No runtime is installed on the CI machines; a developer points these tests at
//! one, e.g. Monado built with its null compositor (docs/quest2.md, "Testing XR without a
//! headset"):
//!
//! ```text
//! XR_RUNTIME_JSON=/path/to/monado/build/openxr_monado-dev.json cargo test --test realtime xr::
//! ```
//!
//! The tests run `avatarm run --xr` under Xvfb and read its `XR summary` line. For the head
//! and the hands they drive Monado's *remote* driver (an HMD and two controllers with
//! simulated hand tracking, set over a TCP socket): they select it for the runtime they start
//! (`P_OVERRIDE_ACTIVE_CONFIG=remote`, its port in a config under their own
//! `XDG_CONFIG_HOME`) and ask for the null compositor (`XRT_COMPOSITOR_NULL=1`). A runtime
//! without that driver ignores these variables; then the head and hand tests say they were
//! skipped.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use avatarm::net::join::JoinReport;
use avatarm_core::shared_data::say_skipped;

use crate::support::output;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The runtime the developer gave, or `None` after saying that the test is skipped.
fn runtime(test: &str) -> Option<PathBuf> {
    match std::env::var_os("XR_RUNTIME_JSON").map(PathBuf::from) {
        Some(p) if p.is_file() => Some(p),
        Some(p) => {
            let why = format!("XR_RUNTIME_JSON={} is not a file", p.display());
            say_skipped(test, &why);
            None
        }
        None => {
            say_skipped(
                test,
                &"no OpenXR runtime (set XR_RUNTIME_JSON to a runtime's manifest, e.g. Monado's \
                  null compositor; see the top of tests/realtime/xr.rs)",
            );
            None
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// A robot site killed however the test ends.
struct Killed(std::process::Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Monado's remote driver, from the test's side: the hub (in the runtime) listens on `port`,
/// sends its reset and latest states (`struct r_remote_data`, 280 bytes each), then reads
/// ours. Offsets of `r_remote_data` (src/xrt/drivers/remote/r_interface.h): the header (u64)
/// at 0, the HMD's pose (quaternion x y z w, then position x y z; f32) at 8, the left and
/// right controllers at 36 and 156, each: pose, linear and angular velocity, `hand_curl[5]`
/// at +52, ..., `hand_tracking_active` at +104 and `active` at +105.
struct RemoteDriver {
    sent: Arc<AtomicU64>,
    connected: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

const REMOTE_DATA_BYTES: usize = 280;

impl RemoteDriver {
    /// Connects (retrying for `wait`) and streams, at 100 Hz: the HMD at 1.6 m turning about
    /// the vertical from 0 to `yaw_deg` over `turn` (then holding), and both hands tracked at
    /// half a metre ahead, their fingers curling and opening once a second.
    fn start(port: u16, wait: Duration, yaw_deg: f32, turn: Duration) -> Self {
        let sent = Arc::new(AtomicU64::new(0));
        let connected = Arc::new(AtomicBool::new(false));
        let stop = Arc::new(AtomicBool::new(false));
        let (s, c, st) = (sent.clone(), connected.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let deadline = Instant::now() + wait;
            let mut stream = loop {
                if st.load(Ordering::Relaxed) || Instant::now() > deadline {
                    return;
                }
                match TcpStream::connect(("127.0.0.1", port)) {
                    Ok(s) => break s,
                    Err(_) => std::thread::sleep(Duration::from_millis(200)),
                }
            };
            let mut states = vec![0u8; 2 * REMOTE_DATA_BYTES];
            if stream.read_exact(&mut states).is_err() {
                return;
            }
            c.store(true, Ordering::Relaxed);
            let template = states[REMOTE_DATA_BYTES..].to_vec();
            let started = Instant::now();
            while !st.load(Ordering::Relaxed) {
                let t = started.elapsed().as_secs_f32();
                let yaw = (yaw_deg * (t / turn.as_secs_f32()).min(1.0)).to_radians();
                let mut d = template.clone();
                let put = |d: &mut [u8], at: usize, values: &[f32]| {
                    for (i, v) in values.iter().enumerate() {
                        d[at + 4 * i..at + 4 * i + 4].copy_from_slice(&v.to_le_bytes());
                    }
                };
                put(
                    &mut d,
                    8,
                    &[
                        0.0,
                        (yaw / 2.0).sin(),
                        0.0,
                        (yaw / 2.0).cos(),
                        0.0,
                        1.6,
                        0.0,
                    ],
                );
                let curl = 0.5 + 0.5 * (t * std::f32::consts::TAU).sin();
                for (at, x) in [(36, -0.2f32), (156, 0.2)] {
                    put(&mut d, at, &[0.0, 0.0, 0.0, 1.0, x, 1.3, -0.5]);
                    put(&mut d, at + 52, &[curl; 5]);
                    d[at + 104] = 1;
                    d[at + 105] = 1;
                }
                if stream.write_all(&d).is_err() {
                    return;
                }
                s.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(10));
            }
        });
        Self {
            sent,
            connected,
            stop,
            thread: Some(thread),
        }
    }
}

impl RemoteDriver {
    /// Whether the runtime opened Monado's remote driver; if not, says that `test`'s `part`
    /// (what the driver moves) was skipped.
    fn drove(&self, test: &str, part: &str) -> bool {
        let connected = self.connected.load(Ordering::Relaxed);
        if !connected {
            say_skipped(
                &format!("{test} ({part})"),
                &"the runtime did not open Monado's remote driver, which this test moves it with",
            );
        }
        connected
    }
}

impl Drop for RemoteDriver {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// `avatarm run ARGS --xr` under Xvfb against `runtime`, with Monado's null compositor and
/// remote driver (on `port`) asked for; returns the log after checking that it succeeded
/// without a panic.
fn run_xr(runtime: &Path, port: u16, name: &str, args: &[&str]) -> String {
    let mut all = vec!["run"];
    all.extend_from_slice(args);
    avatarm_xr(runtime, port, name, &all)
}

/// `avatarm ARGS --xr` as [`run_xr`] runs `avatarm run`.
fn avatarm_xr(runtime: &Path, port: u16, name: &str, args: &[&str]) -> String {
    let config = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("xr_{name}"));
    std::fs::create_dir_all(config.join("monado")).expect("the test's folder");
    std::fs::write(
        config.join("monado/config_v0.json"),
        format!(r#"{{ "active": "remote", "remote": {{ "version": 0, "port": {port} }} }}"#),
    )
    .expect("the runtime's config");
    let run = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_avatarm"))
        .args(args)
        .arg("--xr")
        .env("XR_RUNTIME_JSON", runtime)
        .env("XRT_COMPOSITOR_NULL", "1")
        .env("P_OVERRIDE_ACTIVE_CONFIG", "remote")
        .env("XDG_CONFIG_HOME", &config)
        .current_dir(root())
        .output()
        .expect("xvfb-run starts (scripts/setup.sh installs it)");
    let log = output::printed(&run);
    assert!(
        run.status.success(),
        "avatarm run {args:?} --xr failed:\n{log}"
    );
    assert!(!log.contains("panicked"), "{log}");
    log
}

/// The numbers in the `XR summary` line, in order.
fn summary(log: &str) -> (String, Vec<f64>) {
    let line = log
        .lines()
        .find_map(|l| l.split_once("XR summary: ").map(|(_, r)| r.to_owned()))
        .unwrap_or_else(|| panic!("no XR summary:\n{log}"));
    eprintln!("XR summary: {line}");
    let numbers = line
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter_map(|w| w.parse().ok())
        .collect();
    (line, numbers)
}

/// A session reaches focus, the interaction panel is placed and frames are submitted to the
/// runtime, with the desktop preview beside it.
#[test]
fn an_xr_session_reaches_focus_and_submits_frames() {
    let _serial = crate::serial();
    let Some(runtime) = runtime("an_xr_session_reaches_focus_and_submits_frames") else {
        return;
    };
    let port = free_port();
    let _driver = RemoteDriver::start(port, Duration::from_secs(120), 0.0, Duration::from_secs(1));
    let log = run_xr(
        &runtime,
        port,
        "session",
        &["assets/scenes/pouring.toml", "--frames", "60"],
    );
    assert!(log.contains("entered XR state FOCUSED"), "{log}");
    assert!(log.contains("XR: session running (session 1)"), "{log}");
    assert!(!log.contains("XR: no OpenXR runtime"), "{log}");
    let (line, n) = summary(&log);
    // "XR summary: S sessions, U updates while the session ran (a frame each), H hand frames ..."
    assert_eq!(n[0], 1.0, "{line}");
    assert!(n[1] >= 30.0, "{line}");
}

/// The runtime's tracked hands (26 joints each, here Monado's simulated hands on its remote
/// controllers) drive the hand source: the followed hand's frames reach the live task.
#[test]
fn tracked_hands_drive_the_hand_source() {
    let _serial = crate::serial();
    let Some(runtime) = runtime("tracked_hands_drive_the_hand_source") else {
        return;
    };
    let port = free_port();
    let driver = RemoteDriver::start(port, Duration::from_secs(120), 0.0, Duration::from_secs(1));
    let log = run_xr(
        &runtime,
        port,
        "hands",
        &[
            "assets/scenes/pouring.toml",
            "--hand",
            "xr",
            "--frames",
            "90",
        ],
    );
    if !driver.drove("tracked_hands_drive_the_hand_source", "the hands") {
        return;
    }
    assert!(driver.sent.load(Ordering::Relaxed) > 0);
    assert!(
        log.contains("with the OpenXR hand tracking"),
        "the live task uses the XR hand:\n{log}"
    );
    let (line, n) = summary(&log);
    // Every update with a session running takes a frame of the followed (right) hand.
    assert!(n[2] >= 30.0, "{line}");
    assert!(n[2] <= n[1], "{line}");
}

/// A camera on a head rides on the headset: the head turns up to 20 degrees about the
/// vertical (Monado's remote HMD), the scene's head turns with it from where the scene put it,
/// and the mask is drawn from the headset's head at each frame's capture.
#[test]
fn the_headsets_head_pose_drives_the_head_camera() {
    let _serial = crate::serial();
    let Some(runtime) = runtime("the_headsets_head_pose_drives_the_head_camera") else {
        return;
    };
    let port = free_port();
    let driver = RemoteDriver::start(port, Duration::from_secs(120), 20.0, Duration::from_secs(8));
    let log = run_xr(
        &runtime,
        port,
        "head",
        &[
            "assets/scenes/pouring_alice.toml",
            "--hand",
            "none",
            "--frames",
            "150",
        ],
    );
    if !driver.drove("the_headsets_head_pose_drives_the_head_camera", "the head") {
        return;
    }
    // "...; head: P poses from the headset, turned A deg since the first, the last frame's
    // mask camera B deg and C mm off the headset's head at its capture"
    let (line, n) = summary(&log);
    assert!(line.contains("poses from the headset"), "{line}");
    let (poses, head_deg, off_deg, off_mm) = (n[3], n[4], n[5], n[6]);
    assert!(poses >= 30.0, "{line}");
    // It turned with the headset, and no further: the first pose comes once the session
    // runs, maybe after the turn began, and a fast machine may finish its frames before the
    // turn does (llvmpipe here: 18.6-19.2 degrees).
    assert!((2.0..=20.5).contains(&head_deg), "{line}");
    // The mask's camera is the headset's head at the frame's capture (through the simulated
    // tracker: 0.02 degrees and 0.2 mm of noise), times the mount.
    assert!(off_deg < 0.2 && off_mm < 2.0, "{line}");
}

/// Blair's site in XR (`join --xr --hand xr`, issue 21's operator site): her session reaches
/// focus, her tracked hand drives the operator's side, and its targets reach the robot site.
#[test]
fn the_operators_site_runs_in_xr_and_its_tracked_hand_sends_targets() {
    let _serial = crate::serial();
    let Some(runtime) = runtime("the_operators_site_runs_in_xr_and_its_tracked_hand_sends_targets")
    else {
        return;
    };
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("xr_join");
    std::fs::create_dir_all(&out).expect("the test's folder");
    let net = format!("tcp/127.0.0.1:{}", free_port());
    let serve_report = out.join("serve.json");
    let _serve = Killed(
        Command::new(env!("CARGO_BIN_EXE_avatarm"))
            .args(["serve", "assets/scenes/pouring.toml", "--insecure-lan"])
            .args(["--video", "off", "--listen", &net, "--duration", "240"])
            .arg("--report")
            .arg(&serve_report)
            .current_dir(root())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("the robot site starts"),
    );
    let port = free_port();
    let driver = RemoteDriver::start(port, Duration::from_secs(120), 0.0, Duration::from_secs(1));
    let join_report = out.join("join.json");
    let log = avatarm_xr(
        &runtime,
        port,
        "join",
        &[
            "join",
            &net,
            "--hand",
            "xr",
            "--frames",
            "90",
            "--duration",
            "200",
            "--wait",
            "60",
            "--report",
            join_report.to_str().expect("a path"),
        ],
    );
    assert!(log.contains("entered XR state FOCUSED"), "{log}");
    let (line, n) = summary(&log);
    assert_eq!(n[0], 1.0, "{line}");
    // The session part has passed.
    if !driver.drove(
        "the_operators_site_runs_in_xr_and_its_tracked_hand_sends_targets",
        "the hand",
    ) {
        return;
    }
    assert!(n[2] >= 30.0, "{line}");
    let report: JoinReport = serde_json::from_str(
        &std::fs::read_to_string(&join_report).expect("the operator's report"),
    )
    .expect("JSON");
    eprintln!("join report: targets_sent {}", report.targets_sent);
    assert!(report.targets_sent > 10, "{report:?}");
}

/// Alice's headset at her own site (`join --watch --view alice --xr`, issue 22's two-site
/// session): her head goes to the robot site, which erases her head camera at it, and the
/// frames she receives come from where her head was (they turn with the headset).
#[test]
fn alice_s_headset_sends_her_head_to_the_robot_site_which_erases_her_camera_at_it() {
    let _serial = crate::serial();
    let test = "alice_s_headset_sends_her_head_to_the_robot_site_which_erases_her_camera_at_it";
    let Some(runtime) = runtime(test) else {
        return;
    };
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("xr_alice");
    std::fs::create_dir_all(&out).expect("the test's folder");
    let net = format!("tcp/127.0.0.1:{}", free_port());
    let _serve = Killed(
        Command::new(env!("CARGO_BIN_EXE_avatarm"))
            .args([
                "serve",
                "assets/scenes/pouring_two_views.toml",
                "--insecure-lan",
            ])
            .args(["--view", "alice", "--listen", &net, "--duration", "240"])
            .current_dir(root())
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(out.join("serve.log")).expect("the test's folder"))
            .spawn()
            .expect("the robot site starts"),
    );
    let port = free_port();
    let driver = RemoteDriver::start(port, Duration::from_secs(120), 20.0, Duration::from_secs(8));
    let report = out.join("join.json");
    let log = avatarm_xr(
        &runtime,
        port,
        "alice",
        &[
            "join",
            &net,
            "--scene",
            "assets/scenes/pouring_two_views.toml",
            "--view",
            "alice",
            "--watch",
            "--frames",
            "150",
            "--wait",
            "60",
            "--report",
            report.to_str().expect("a path"),
        ],
    );
    assert!(log.contains("entered XR state FOCUSED"), "{log}");
    if !driver.drove(test, "the head") {
        return;
    }
    let report: JoinReport =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("Alice's report"))
            .expect("JSON");
    eprintln!("head: {:?}, video: {:?}", report.head, report.video);
    let head = report.head.as_ref().expect("the head's report");
    assert_eq!(head.source, "headset", "{report:?}");
    assert!(head.sent >= 30, "{report:?}");
    // The headset turned up to 20 degrees (the first pose may come after the turn began),
    // and the frames' cameras with it.
    assert!((2.0..=20.5).contains(&head.turned_deg), "{report:?}");
    assert!(report.video.camera_turned_deg >= 2.0, "{report:?}");
    // Issue 44: the frames the headset showed end at the runtime's predicted display time
    // for them (Monado grants XR_KHR_convert_timespec_time), counted apart from the window's.
    let window = report.window.as_ref().expect("the window's report");
    let on_headset = &window.headset_glass_to_glass_ms;
    eprintln!(
        "glass to glass: all {:?}, on the headset {on_headset:?}",
        window.glass_to_glass_ms
    );
    assert!(
        on_headset.n > 0 && on_headset.n <= window.glass_to_glass_ms.n,
        "{window:?}"
    );
    assert!(on_headset.median > 0.0, "{window:?}");
    let (line, _) = summary(&log);
    assert!(
        line.contains("video frames stamped at the headset's predicted display"),
        "{line}"
    );
}
