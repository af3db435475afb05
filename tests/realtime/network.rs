//! Two sites as two processes (`avatarm serve`, `avatarm join`) on this machine, their
//! traffic through the seeded impairment relay (`avatarm_net::impair`): the pouring task
//! under delay, a link cut mid-pour, the operator killed, and the video to an observer.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use avatarm::net::join::JoinReport;
use avatarm::net::serve::{ServeReport, StopEpisode};
use avatarm_net::impair::{Impairment, Relay};
use serde::de::DeserializeOwned;

use crate::serial;

pub(crate) fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("network")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the test's set-up");
    dir
}

pub(crate) fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("the test's set-up")
}

/// The scene both sites run unless a test says otherwise.
pub(crate) const POURING: &str = "assets/scenes/pouring.toml";

/// `avatarm serve` of the pouring scene on 127.0.0.1:`port`, logging into `dir`.
fn serve(dir: &Path, port: u16, duration_s: f64, extra: &[&str]) -> Child {
    serve_scene(dir, POURING, port, duration_s, extra)
}

/// `avatarm serve SCENE` on 127.0.0.1:`port`, logging into `dir`.
pub(crate) fn serve_scene(
    dir: &Path,
    scene: &str,
    port: u16,
    duration_s: f64,
    extra: &[&str],
) -> Child {
    let log = std::fs::File::create(dir.join("serve.log")).expect("the test's set-up");
    Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["serve", scene, "--listen"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--duration", &duration_s.to_string(), "--report"])
        .arg(dir.join("serve.json"))
        .args(extra)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("the test's set-up")
}

/// `avatarm join` to 127.0.0.1:`port`.
fn join(dir: &Path, name: &str, port: u16, extra: &[&str]) -> Child {
    join_scene(dir, name, POURING, port, extra)
}

/// `avatarm join --scene SCENE` to 127.0.0.1:`port`.
pub(crate) fn join_scene(dir: &Path, name: &str, scene: &str, port: u16, extra: &[&str]) -> Child {
    let log = std::fs::File::create(dir.join(format!("{name}.log"))).expect("the test's set-up");
    Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg("join")
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--scene", scene, "--report"])
        .arg(dir.join(format!("{name}.json")))
        .args(extra)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("the test's set-up")
}

/// Waits until the operator's log says it joined (at most 30 s).
fn wait_joined(dir: &Path) {
    wait_for_join(dir, "join", 30);
}

/// Waits until `dir/NAME.log` says it joined (at most `seconds`).
fn wait_for_join(dir: &Path, name: &str, seconds: u64) {
    let deadline = Instant::now() + Duration::from_secs(seconds);
    while !std::fs::read_to_string(dir.join(format!("{name}.log")))
        .unwrap_or_default()
        .contains("joined")
    {
        assert!(Instant::now() < deadline, "{name} never joined");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits for the process `name` (its log `dir/name.log`) to succeed; its report
/// (`dir/name.json`, a [`ServeReport`] or a [`JoinReport`]).
pub(crate) fn finish<T: DeserializeOwned>(mut child: Child, dir: &Path, name: &str) -> T {
    let status = child.wait().expect("the test's set-up");
    let log = std::fs::read_to_string(dir.join(format!("{name}.log"))).unwrap_or_default();
    assert!(status.success(), "{name} failed:\n{log}");
    report(dir, name)
}

/// The report `dir/name.json`, read as its type.
pub(crate) fn report<T: DeserializeOwned>(dir: &Path, name: &str) -> T {
    let path = dir.join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}\n{text}", path.display()))
}

/// The robot site (video off) and the operator through a TCP relay of `delay_s` one way.
fn pour_through(name: &str, delay_s: f64) -> (ServeReport, JoinReport) {
    let dir = out_dir(name);
    let port = free_port();
    let robot = serve(&dir, port, 14.0, &["--insecure-lan", "--video", "off"]);
    let relay = Relay::tcp(
        format!("127.0.0.1:{port}")
            .parse()
            .expect("the test's set-up"),
        Impairment {
            delay_s,
            jitter_s: delay_s * 0.1,
            seed: 3,
            ..Impairment::default()
        },
    )
    .expect("the test's set-up");
    let operator = join(&dir, "join", relay.local_addr().port(), &["--wait", "20"]);
    let j: JoinReport = finish(operator, &dir, "join");
    let s: ServeReport = finish(robot, &dir, "serve");
    (s, j)
}

#[test]
fn two_sites_pour_through_the_network_and_delay_costs_accuracy() {
    let _serial = serial();
    let (s0, j0) = pour_through("pour_0ms", 0.0);
    let (s1, j1) = pour_through("pour_100ms", 0.1);
    for (s, j) in [(&s0, &j0), (&s1, &j1)] {
        // The whole trial crossed: a target per control tick, joint states back.
        assert!(j.targets_sent >= 900, "{j:?}");
        assert!(s.targets_used >= 850, "{s:?}");
        assert!(j.joint_states >= 800, "{j:?}");
        assert_eq!(s.targets_refused, 0, "{s:?}");
        assert_eq!(s.nan_commands, 0, "{s:?}");
        // The real bottle was grasped and lifted through the network.
        assert!(s.trial.grasp_at_s.is_some(), "{s:?}");
        assert!(s.trial.real_lift_m > 0.05, "{s:?}");
    }
    // The operator's twin is the one-process trial's, to the bit: both step the same world
    // (`TrialParts::hand_app`). Before they did, a resource more in one of them changed
    // Rapier's contacts by micrometres, and two of the ten hands grasped differently.
    let scene = avatarm_scene::Scene::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/pouring.toml"),
        &avatarm_core::robot::PackagePath::default(),
    )
    .expect("the pouring scene");
    let (task, setup) = (
        scene.file.task.expect("a task"),
        scene.trial.expect("a set-up"),
    );
    let mode = avatarm_core::teleop::mapping::MappingMode::ClosedLoop;
    let one_process = avatarm_mapping::pouring::run_trial(&task, &setup, mode, 0)
        .expect("the trial runs")
        .result;
    for j in [&j0, &j1] {
        assert_eq!(j.twin_lift_m, one_process.twin_lift_m, "{j:?}");
    }
    // The round trip shows the relay's 2 x 100 ms.
    assert!(j1.clock_rtt_ms >= 200.0, "{j1:?}");
    assert!(j0.clock_rtt_ms < 50.0, "{j0:?}");
    // Delay costs accuracy: the real bottle lags its twin.
    let (e0, e1) = (
        s0.trial.pos_rmse_m.expect("trial.pos_rmse_m"),
        s1.trial.pos_rmse_m.expect("trial.pos_rmse_m"),
    );
    assert!(e0 < 0.02, "no delay: {e0} m");
    assert!(e1 > e0, "100 ms: {e1} m against {e0} m");
    // The target ages as the delay says (median, ms).
    assert!(s1.target_age_ms.median >= 100.0, "{s1:?}");
    assert!(s0.target_age_ms.median < 30.0, "{s0:?}");
}

#[test]
fn a_cut_link_stops_the_arm_and_the_session_resumes() {
    let _serial = serial();
    let dir = out_dir("cut");
    let port = free_port();
    let robot = serve(&dir, port, 14.0, &["--insecure-lan", "--video", "off"]);
    let relay = Relay::tcp(
        format!("127.0.0.1:{port}")
            .parse()
            .expect("the test's set-up"),
        Impairment::default(),
    )
    .expect("the test's set-up");
    let operator = join(&dir, "join", relay.local_addr().port(), &["--wait", "20"]);
    // Wait until targets flow, then cut mid-pour.
    wait_joined(&dir);
    std::thread::sleep(Duration::from_secs(4));
    relay.cut_for(Duration::from_secs(2));
    let j: JoinReport = finish(operator, &dir, "join");
    let s: ServeReport = finish(robot, &dir, "serve");
    // One stop for stale targets, about as long as the cut, ended by fresh targets.
    let cut: Vec<&StopEpisode> = s
        .stops
        .iter()
        .filter(|e| e.reason.contains("stale"))
        .collect();
    assert_eq!(cut.len(), 1, "{s:?}");
    let length = cut[0].length_s.expect("length_s");
    assert!(
        (1.4..3.0).contains(&length),
        "stopped {length} s for a 2 s cut: {s:?}"
    );
    // Neither process restarted: the operator joined once (and left at its end), and targets
    // flowed after the cut.
    assert_eq!(s.operator_joins, 1, "{s:?}");
    assert!(s.targets_used >= 850, "nothing lost: {s:?}");
    assert!(j.targets_sent >= 900, "{j:?}");
    assert_eq!(s.nan_commands, 0);
    // The relay held the cut's bytes without filling its queue: nothing pushed back.
    let held = relay
        .stats()
        .held_max
        .load(std::sync::atomic::Ordering::Relaxed);
    eprintln!("cut: the relay held at most {held} bytes in one direction");
    assert_eq!(
        relay
            .stats()
            .backpressure
            .load(std::sync::atomic::Ordering::Relaxed),
        0
    );
}

/// The robot site killed and started again on the same endpoint while the operator stays:
/// the operator says once that the robot site fell silent, once that it is heard again, and
/// once that it restarted (its clock jumped), estimates the offset again at once and commands
/// the new robot site; its report counts the silence and the restart and gives the new clock's
/// offset, not the first's.
#[test]
fn a_restarted_robot_site_is_said_and_its_new_clock_taken() {
    let _serial = serial();
    let dir = out_dir("restarted");
    let port = free_port();
    let mut first = serve(&dir, port, 60.0, &["--insecure-lan", "--video", "off"]);
    let operator = join(&dir, "join", port, &["--wait", "20", "--duration", "30"]);
    wait_joined(&dir);
    std::thread::sleep(Duration::from_secs(3));
    first.kill().expect("the test's set-up");
    let _ = first.wait();
    std::thread::sleep(Duration::from_secs(3));
    let second = serve(&dir, port, 30.0, &["--insecure-lan", "--video", "off"]);
    let j: JoinReport = finish(operator, &dir, "join");
    let s: ServeReport = finish(second, &dir, "serve");
    let log = std::fs::read_to_string(dir.join("join.log")).expect("the test's set-up");
    eprintln!(
        "{}",
        log.lines()
            .filter(|l| l.contains("robot site"))
            .collect::<Vec<_>>()
            .join("\n")
    );
    // Each silence said once and counted (a stall of the first robot site under load could
    // make one more before the kill), the restart once.
    assert!(j.robot_site_silences >= 1, "{j:?}");
    assert_eq!(j.robot_site_restarts, 1, "{j:?}");
    for (said, times) in [
        (
            "no word from the robot site for 1.0 s",
            j.robot_site_silences,
        ),
        ("the robot site is heard again after", j.robot_site_silences),
        ("the robot site restarted (its clock jumped by -", 1),
    ] {
        assert_eq!(log.matches(said).count() as u64, times, "{said}:\n{log}");
    }
    // The second robot site's clock started after the operator's: its offset is negative (the
    // first's was positive), as the report now says.
    assert!(j.clock_offset_s < 0.0, "{j:?}");
    // And the operator commanded it: its targets were used (those stamped with the first
    // clock's offset before the new estimate are refused, and counted).
    eprintln!(
        "restarted robot site: {} targets used, {} refused ({:?})",
        s.targets_used, s.targets_refused, s.refusals_by_kind
    );
    assert!(s.targets_used >= 300, "{s:?}");
    assert_eq!(s.nan_commands, 0, "{s:?}");
}

#[test]
fn the_operator_killed_the_arm_stops_and_holds() {
    let _serial = serial();
    let dir = out_dir("killed");
    let port = free_port();
    let robot = serve(&dir, port, 9.0, &["--insecure-lan", "--video", "off"]);
    let mut operator = join(&dir, "join", port, &["--wait", "20"]);
    wait_joined(&dir);
    std::thread::sleep(Duration::from_secs(3));
    operator.kill().expect("the test's set-up");
    let _ = operator.wait();
    let s: ServeReport = finish(robot, &dir, "serve");
    assert_eq!(s.operator_leaves, 1, "{s:?}");
    // The last stop is still on at the end: the arm holds.
    let last = s.stops.last().expect("a stop");
    assert!(last.length_s.is_none(), "{s:?}");
    let log = std::fs::read_to_string(dir.join("serve.log")).expect("the test's set-up");
    assert!(log.contains("the operator left; stopping the arm"), "{log}");
    assert_eq!(s.nan_commands, 0);
}

/// Waits (at most 120 s: the robot site's renderer starts first) until the robot site on
/// `port` publishes video; watches as an observer in this process.
fn wait_for_video(port: u16) {
    let config = avatarm_net::NetConfig {
        role: avatarm_net::Role::Observer,
        keys: avatarm_net::Keys::default(),
        listen: vec![],
        connect: vec![format!("tcp/127.0.0.1:{port}")],
        credentials: None,
        dictionary: None,
        operators: vec![],
        robot_sites: vec![],
        tls: None,
        insecure_lan: true,
    };
    let mut probe = avatarm_net::OperatorSite::join(&config, Duration::from_secs(60))
        .expect("the robot site answers");
    let deadline = Instant::now() + Duration::from_secs(120);
    while probe.poll().frames.is_empty() {
        assert!(Instant::now() < deadline, "no video within 120 s");
        std::thread::sleep(Duration::from_millis(50));
    }
    probe.close();
}

#[test]
fn h264_video_survives_loss_and_a_late_observer_gets_a_keyframe_on_request() {
    let _serial = serial();
    let dir = out_dir("h264");
    let (port, udp_port) = (free_port(), free_port());
    let udp = format!("udp/127.0.0.1:{udp_port}");
    // Periodic IDR frames every 10 min (and none on scene changes): every keyframe after the
    // first is a viewer's request. The robot site is killed at the end.
    let robot = serve(
        &dir,
        port,
        600.0,
        &[
            "--insecure-lan",
            "--listen",
            &udp,
            "--codec",
            "h264",
            "--bitrate",
            "1",
            "--keyframe-interval",
            "600",
        ],
    );
    wait_for_video(port);
    // An observer over UDP through 5 % loss: each lost frame spoils the frames after it until
    // the keyframe it asks for. (Over plain UDP Zenoh's handshake and declarations are
    // best-effort too: the seed loses none of the first fifty datagrams either way.)
    let relay = Relay::udp(
        format!("127.0.0.1:{udp_port}")
            .parse()
            .expect("the test's set-up"),
        Impairment {
            loss: 0.05,
            seed: 5,
            ..Impairment::default()
        },
    )
    .expect("the test's set-up");
    let lossy = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg("join")
        .arg(format!("udp/{}", relay.local_addr()))
        .args(["--watch", "--duration", "12", "--wait", "30", "--report"])
        .arg(dir.join("lossy.json"))
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("lossy.log")).expect("the test's set-up"))
        .spawn()
        .expect("the test's set-up");
    let lossy: JoinReport = finish(lossy, &dir, "lossy");
    // A late observer: it joins mid-stream, so its first frame refers to frames it never had.
    // Not at once: the lossy observer's last keyframe request, answered a moment after it
    // left, could otherwise be the late one's first frame (seen once: 90 ms apart).
    std::thread::sleep(Duration::from_secs(2));
    let late = join(
        &dir,
        "late",
        port,
        &["--watch", "--duration", "8", "--wait", "30"],
    );
    let late: JoinReport = finish(late, &dir, "late");
    let mut robot = robot;
    let _ = robot.kill();
    let _ = robot.wait();
    for (name, v) in [("lossy", &lossy), ("late", &late)] {
        assert_eq!(v.video.codec, "h264", "{name}: {v:?}");
        assert_eq!(v.video.refused, 0, "{name}: {v:?}");
        assert!(v.video.shown >= 5, "{name}: {v:?}");
    }
    assert!(late.video.keyframe_requests >= 1, "{late:?}");
    assert!(late.video.waiting_for_keyframe >= 1, "{late:?}");
    // Each loss was asked for again, and keyframes came; every frame received was shown, or
    // waited for a keyframe, or was dropped as stale.
    if lossy.video.lost > 0 {
        assert!(lossy.video.keyframe_requests >= 1, "{lossy:?}");
        assert!(lossy.video.keyframes >= 1, "{lossy:?}");
    }
    for v in [&lossy, &late] {
        let accounted =
            v.video.shown + v.video.waiting_for_keyframe + v.video.stale + v.video.refused;
        assert_eq!(accounted, v.video.frames, "{v:?}");
        assert!(v.video.waiting_for_keyframe * 2 < v.video.frames, "{v:?}");
    }
}

/// `avatarm join --window` (under Xvfb, on the software renderer): the operator's window shows
/// the robot site's video on the interaction layer's panel, with the hand and the bottle's twin
/// in front, while the session runs beside it (targets out, frames in) until the window closes
/// at its frames; the report counts what the window drew.
#[test]
fn the_operator_window_shows_the_received_video_with_the_hand_in_front() {
    let _serial = serial();
    let dir = out_dir("window");
    let port = free_port();
    let robot = serve(&dir, port, 600.0, &["--insecure-lan"]);
    wait_for_video(port);
    let shot = dir.join("window.png");
    let operator = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_avatarm"))
        .arg("join")
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--scene", "assets/scenes/pouring.toml", "--window"])
        .args(["--frames", "60", "--wait", "30", "--screenshot"])
        .arg(&shot)
        .arg("--report")
        .arg(dir.join("join.json"))
        .arg("--record")
        .arg(dir.join("join.mcap"))
        // No OpenXR runtime, even where a developer has one installed.
        .env("XR_RUNTIME_JSON", dir.join("no_runtime.json"))
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("join.log")).expect("the test's set-up"))
        .spawn()
        .expect("xvfb-run starts (scripts/setup.sh installs it)");
    let j: JoinReport = finish(operator, &dir, "join");
    let mut robot = robot;
    let _ = robot.kill();
    let _ = robot.wait();
    assert_eq!(j.role, "operator", "{j:?}");
    assert!(j.targets_sent >= 10, "{j:?}");
    assert!(j.video.shown >= 3, "{j:?}");
    // The window's own counts: every frame rendered, decoded frames uploaded to the panel,
    // the hand drawn around the twin in (nearly) every frame.
    let win = j.window.as_ref().expect("the window's report");
    assert!(win.frames >= 60, "{win:?}");
    assert!(win.video_frames >= 3, "{win:?}");
    assert!(win.hand_frames >= 50, "{win:?}");
    // The display stage's figures: one wait per frame put on the panel, one time per rendered
    // frame after the first, both finite and positive.
    assert_eq!(win.panel_wait_ms.n as u64, win.video_frames, "{win:?}");
    assert_eq!(win.frame_ms.n as u64, win.frames - 1, "{win:?}");
    for (key, value) in [
        ("panel_wait_ms", win.panel_wait_ms.median),
        ("frame_ms", win.frame_ms.median),
        ("fps", win.fps),
    ] {
        assert!(value > 0.0, "{key}: {win:?}");
    }
    // Each frame put on the panel stamped once more when the window's frame showing it was
    // presented (the render world, after the present; the last one may not be by the exit),
    // and glass to glass for each.
    let presented = win.display_ms.n as u64;
    assert!(
        presented + 1 >= win.video_frames && presented <= win.video_frames,
        "{win:?}"
    );
    assert_eq!(win.glass_to_glass_ms.n as u64, presented, "{win:?}");
    // `--record`: what the operator received, as a recording: every frame shown (one
    // camera), every joint state, the scene's camera, on the robot site's clock.
    let rec = avatarm_record::Recording::open(&dir.join("join.mcap")).expect("the recording");
    let recorded = j.recording.as_ref().expect("the recording's report");
    assert_eq!(recorded.refused, 0, "{j:?}");
    assert_eq!(rec.erased.len() as u64, j.video.shown, "{j:?}");
    assert_eq!(rec.erased.len() as u64, recorded.erased_frames, "{j:?}");
    assert_eq!(rec.joint_states.len() as u64, j.joint_states, "{j:?}");
    // The operator's own hand, each frame once, tracked with its 26 joints.
    assert!(rec.hands.len() >= 50, "{} hand frames", rec.hands.len());
    assert_eq!(rec.hands.len() as u64, recorded.hands, "{j:?}");
    assert!(rec.hands.windows(2).all(|w| w[0].stamp_ns < w[1].stamp_ns));
    assert!(rec.hands.iter().any(|h| h.tracked && h.poses.len() == 26));
    // Every target she sent, in order, on the robot's clock with the rest.
    assert_eq!(rec.targets.len() as u64, j.targets_sent, "{j:?}");
    assert_eq!(rec.targets.len() as u64, recorded.targets, "{j:?}");
    assert!(
        rec.targets
            .windows(2)
            .all(|w| w[0].stamp_ns < w[1].stamp_ns)
    );
    assert!(rec.targets.iter().any(|t| t.contacts > 0));
    assert!(rec.calibration.is_some());
    // The fixed camera's pose, once.
    assert!(!rec.camera_on_head() && rec.camera_at(0).is_some());
    assert!(rec.erased.windows(2).all(|w| w[0].stamp_ns < w[1].stamp_ns));
    let first = image::load_from_memory(&rec.erased[0].data).expect("a JPEG");
    assert_eq!((first.width(), first.height()), (640, 480));
    // The frames' and the joint states' stamps are on one clock: every frame was captured
    // between 5 s before the first joint state received (the video's own latency: software
    // rendering, coding) and the last one.
    let (first_js, last_js) = (
        rec.joint_states[0].stamp_ns,
        rec.joint_states[rec.joint_states.len() - 1].stamp_ns,
    );
    for frame in &rec.erased {
        assert!(
            (first_js.saturating_sub(5_000_000_000)..=last_js).contains(&frame.stamp_ns),
            "a frame at {} ns, joint states from {first_js} to {last_js} ns",
            frame.stamp_ns
        );
    }
    let img = image::open(&shot)
        .expect("the window's screenshot")
        .to_rgb8();
    assert_eq!(img.dimensions(), (1280, 720));
    // The panel shows the video (many colours), and the hand's skeleton is drawn over it in
    // its own colour (skin, or orange while it holds the bottle: `teleop::hand_colour`).
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() > 500, "{} colours", colours.len());
    let near = |p: &[u8; 3], c: [u8; 3]| p.iter().zip(c).all(|(&a, b)| a.abs_diff(b) <= 6);
    let hand = img
        .pixels()
        .filter(|p| near(&p.0, [242, 217, 178]) || near(&p.0, [255, 140, 51]))
        .count();
    assert!(hand >= 100, "{hand} hand-coloured pixels");
}

/// A recording of Alice's head turning `degrees` to her left over `seconds` about her eye,
/// from where `scene`'s head starts (90 poses a second), as `run --record` writes head poses.
fn head_turning(path: &Path, scene: &str, degrees: f64, seconds: f64) {
    let scene = avatarm_scene::Scene::load_view(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join(scene),
        &avatarm_core::robot::PackagePath::default(),
        Some("alice"),
    )
    .expect("the scene");
    let rig = scene.head.as_ref().expect("a camera on a head");
    let start = rig.motion.pose_at(0.0);
    let base_from_world = scene.robot_base().inverse();
    let mut w = avatarm_record::RecordingWriter::create(path).expect("the test's set-up");
    let n = (seconds * 90.0) as u64;
    for i in 0..=n {
        let s = i as f64 / n as f64;
        let turn = nalgebra::UnitQuaternion::from_axis_angle(
            &nalgebra::Vector3::z_axis(),
            (degrees * s).to_radians(),
        );
        let world_from_head =
            nalgebra::Isometry3::from_parts(start.translation, turn * start.rotation);
        w.head_pose(&avatarm_record::HeadPose {
            stamp_ns: 1_000_000_000 + i * 1_000_000_000 / 90,
            base_from_head: base_from_world * world_from_head,
        })
        .expect("the test's set-up");
    }
    w.finish().expect("the test's set-up");
}

/// Both cameras through the network at once: the robot site erases Blair's fixed camera and
/// Alice's head camera, each in an app of its own fed the same joint states, and publishes
/// each under its name; each viewer receives the one it looks through. Alice's viewer sends
/// her head (here a recorded head turning 25 degrees; in XR the headset's), and the robot site
/// erases her camera at it. Each frame carries the camera pose its mask was drawn from, so
/// that a viewer places the hand and the twins in front of it: Alice's frames' cameras turn
/// with her head; Blair's do not move.
#[test]
fn the_robot_site_serves_both_cameras_at_alice_s_head_each_frame_with_its_pose() {
    let _serial = serial();
    let scene = "assets/scenes/pouring_two_views.toml";
    let dir = out_dir("both_views");
    let head = dir.join("head.mcap");
    // The scene's own head turns by 4 degrees at most: 25 is hers, sent.
    head_turning(&head, scene, 25.0, 4.0);
    let port = free_port();
    // No --view: every camera of the scene. It stops by itself after the viewers (each waits
    // for it at most 30 s, then watches 12 s: two apps share the software renderer's 2 cores,
    // at well under a frame a second each while they start).
    let robot = serve_scene(&dir, scene, port, 45.0, &["--insecure-lan"]);
    let record = dir.join("alice.mcap");
    let watch = |view: &str| {
        let mut args = vec![
            "--watch",
            "--view",
            view,
            "--wait",
            "30",
            "--duration",
            "12",
        ];
        if view == "alice" {
            args.extend(["--record", record.to_str().expect("a UTF-8 path")]);
            args.extend(["--head", head.to_str().expect("a UTF-8 path")]);
        }
        join_scene(&dir, view, scene, port, &args)
    };
    let (alice, blair) = (watch("alice"), watch("blair"));
    let alice: JoinReport = finish(alice, &dir, "alice");
    let blair: JoinReport = finish(blair, &dir, "blair");
    let site: ServeReport = finish(robot, &dir, "serve");
    let cameras = &site.video_cameras;
    assert_eq!(cameras[0].camera, "blair", "{cameras:?}");
    assert_eq!(cameras[1].camera, "alice", "{cameras:?}");
    assert!(
        cameras[0].frames >= 10 && cameras[1].frames >= 10,
        "{cameras:?}"
    );
    // Alice's head went to the robot site, which drew her frames' masks from it.
    let sent = alice.head.as_ref().expect("Alice's head's report");
    assert!(sent.sent >= 100, "{alice:?}");
    assert!((sent.turned_deg - 25.0).abs() < 0.5, "{alice:?}");
    assert!(cameras[1].head_poses >= 100, "{cameras:?}");
    assert_eq!(cameras[1].head_refused, 0, "{cameras:?}");
    assert_eq!(cameras[0].head_poses, 0, "{cameras:?}");
    assert!(alice.video.shown >= 5, "{alice:?}");
    assert!(alice.video.camera_turned_deg >= 10.0, "{alice:?}");
    // At most the head's turn and the scripted head's before the first pose arrived.
    assert!(alice.video.camera_turned_deg <= 30.0, "{alice:?}");
    // Alice's recording keeps each frame's camera: a camera on a head, a pose at each
    // frame's capture.
    let rec = avatarm_record::Recording::open(&record).expect("the recording");
    let recorded = alice.recording.as_ref().expect("the recording's report");
    assert_eq!(recorded.refused, 0, "{alice:?}");
    assert!(rec.camera_on_head() && rec.erased.len() >= 5);
    let axes: Vec<_> = rec
        .erased
        .iter()
        .map(|e| {
            rec.camera_at(e.stamp_ns)
                .expect("a pose at each frame")
                .rotation
        })
        .collect();
    let turned = axes
        .iter()
        .map(|r| r.angle_to(&axes[0]))
        .fold(0.0, f64::max);
    let received = alice.video.camera_turned_deg;
    assert!(turned.to_degrees() >= 10.0, "{turned} rad, {alice:?}");
    assert!(
        turned.to_degrees() <= received + 0.01,
        "{turned} rad, {alice:?}"
    );
    assert!(blair.video.shown >= 5, "{blair:?}");
    assert!(blair.video.camera_moved_mm < 1e-6, "{blair:?}");
    assert!(blair.video.camera_turned_deg < 1e-6, "{blair:?}");
    // The site said it serves both.
    let log = std::fs::read_to_string(dir.join("serve.log")).expect("the robot site's log");
    assert!(log.contains("video of blair, alice"), "{log}");
    // Naming a camera twice is refused by flag, before anything runs.
    let twice = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["serve", scene, "--insecure-lan", "--view", "alice,alice"])
        .args(["--listen", "tcp/127.0.0.1:1"])
        .output()
        .expect("the test's set-up");
    let err = String::from_utf8_lossy(&twice.stderr);
    assert!(
        !twice.status.success() && err.contains("--view") && err.contains("'alice'"),
        "{err}"
    );
    // A head for a fixed camera is refused by flag.
    let fixed = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args([
            "join",
            "tcp/127.0.0.1:1",
            "--scene",
            scene,
            "--view",
            "blair",
        ])
        .args(["--watch", "--head", head.to_str().expect("a UTF-8 path")])
        .output()
        .expect("the test's set-up");
    let err = String::from_utf8_lossy(&fixed.stderr);
    assert!(
        !fixed.status.success() && err.contains("--head") && err.contains("'blair'"),
        "{err}"
    );
}

/// Alice watches through her head camera while Blair pours (`join --watch --view alice
/// --window`): the hand that holds the bottle is drawn carried with the real bottle as each
/// frame shows it (the robot site reports it), so it keeps its grip on the bottle Alice sees
/// while the video is older than Blair's hand and the arm lags her twin.
#[test]
fn alice_watching_sees_the_operator_s_hand_on_the_bottle_the_arm_carries() {
    let _serial = serial();
    let scene = "assets/scenes/pouring_two_views.toml";
    let dir = out_dir("alice_watching");
    let port = free_port();
    let robot = serve_scene(
        &dir,
        scene,
        port,
        600.0,
        &["--insecure-lan", "--view", "alice"],
    );
    wait_for_video(port);
    let watcher = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x720x24"])
        .arg(env!("CARGO_BIN_EXE_avatarm"))
        .arg("join")
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--scene", scene, "--view", "alice", "--watch", "--window"])
        .args(["--frames", "400", "--wait", "30", "--report"])
        .arg(dir.join("watch.json"))
        .env("XR_RUNTIME_JSON", dir.join("no_runtime.json"))
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("watch.log")).expect("the test's set-up"))
        .spawn()
        .expect("xvfb-run starts (scripts/setup.sh installs it)");
    wait_for_join(&dir, "watch", 60);
    let operator = join_scene(
        &dir,
        "join",
        scene,
        port,
        &["--view", "alice", "--wait", "30"],
    );
    let j: JoinReport = finish(operator, &dir, "join");
    let w: JoinReport = finish(watcher, &dir, "watch");
    let mut robot = robot;
    let _ = robot.kill();
    let _ = robot.wait();
    assert!(j.targets_sent >= 100, "{j:?}");
    let report = w.window.as_ref().expect("the window's report");
    assert!(report.anchored_hand_frames >= 20, "{report:?}");
    // The hand was moved from Blair's twin to the real bottle the frame shows: by centimetres
    // while the bottle moves (the video's age, the arm's lag), never by more than the desk
    // (one object, one frame of reference).
    let moved = report.anchor_correction_mm.max;
    assert!(moved >= 10.0, "{report:?}");
    assert!(moved <= 500.0, "{report:?}");
}

/// `avatarm serve --ros2-publish`: while an operator pours, the robot site publishes its erased
/// frames (the network's JPEG), their masks (PNG), the commands and the safety events on ROS 2; a listener written
/// with Cyclone DDS (`avatarm_ros::testing::Ros2Listener`, as rviz2 subscribes) receives and
/// decodes them.
#[cfg(feature = "ros")]
#[test]
fn the_robot_site_publishes_on_ros2() {
    let _serial = serial();
    let dir = out_dir("serve_ros2_publish");
    let port = free_port();
    let domain = avatarm_ros::testing::test_domain(10);
    let listener = avatarm_ros::testing::Ros2Listener::start(domain, "/avatarm");
    let log = std::fs::File::create(dir.join("serve.log")).expect("the test's set-up");
    let robot = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["serve", POURING, "--listen"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--duration", "10", "--report"])
        .arg(dir.join("serve.json"))
        .args(["--insecure-lan", "--ros2-publish"])
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("the test's set-up");
    // The operator leaves after 5 s: the robot site stops the arm (a safety event).
    let operator = join(&dir, "join", port, &["--wait", "20", "--duration", "5"]);
    let _: JoinReport = finish(operator, &dir, "join");
    let s: ServeReport = finish(robot, &dir, "serve");
    let r = listener.report();
    eprintln!(
        "the ROS 2 listener after serve: erased {}, masks {}, commands {}, safety {} (the last: {}); serve published {} frames",
        r["erased/compressed"]["count"],
        r["mask/compressed"]["count"],
        r["joint_commands"]["count"],
        r["safety"]["count"],
        r["safety"]["data"],
        s.video_frames
    );
    let count = |topic: &str| r[topic]["count"].as_u64().unwrap_or(0);
    assert!(count("erased/compressed") > 0, "{r}");
    assert_eq!(r["erased/compressed"]["magic"], true, "{r}");
    // The erased frames' masks, as PNG, stamped as their frames (to the nanosecond: an exact
    // time synchroniser pairs them). A mask or a frame may be dropped (newest first), never
    // most of them.
    assert!(count("mask/compressed") > 0, "{r}");
    assert_eq!(r["mask/compressed"]["format"], "png", "{r}");
    assert_eq!(r["mask/compressed"]["magic"], true, "{r}");
    let stamps = |topic: &str| -> Vec<serde_json::Value> {
        r[topic]["stamps"].as_array().cloned().unwrap_or_default()
    };
    let (erased, masks) = (stamps("erased/compressed"), stamps("mask/compressed"));
    let paired = masks.iter().filter(|m| erased.contains(m)).count();
    eprintln!(
        "masks stamped as an erased frame: {paired} of {}",
        masks.len()
    );
    assert!(2 * paired > masks.len(), "{paired} of {}: {r}", masks.len());
    assert!(count("joint_commands") > 100, "{r}");
    assert!(
        r["joint_commands"]["name"]
            .as_array()
            .is_some_and(|n| n.iter().any(|j| j == "right_j0")),
        "{r}"
    );
    // At least the stop when the operator left.
    assert!(count("safety") > 0, "{r}");
    assert!(
        r["safety"]["data"]
            .as_str()
            .is_some_and(|t| t.contains("robot site: ")),
        "{r}"
    );
}
