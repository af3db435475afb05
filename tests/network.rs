//! Two sites as two processes (`avatarm serve`, `avatarm join`) on this machine, their
//! traffic through the seeded impairment relay (`avatarm_net::impair`): the pouring task
//! under delay, a link cut mid-pour, the operator killed, and the video to an observer.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use avatarm_net::impair::{Impairment, Relay};
use serde_json::Value;

fn out_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("network").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap()
}

/// `avatarm serve` of the pouring scene on 127.0.0.1:`port`, logging into `dir`.
fn serve(dir: &Path, port: u16, duration_s: f64, extra: &[&str]) -> Child {
    let log = std::fs::File::create(dir.join("serve.log")).unwrap();
    Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["serve", "assets/scenes/pouring.toml", "--listen"])
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--duration", &duration_s.to_string(), "--report"])
        .arg(dir.join("serve.json"))
        .args(extra)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap()
}

/// `avatarm join` to 127.0.0.1:`port`.
fn join(dir: &Path, name: &str, port: u16, extra: &[&str]) -> Child {
    let log = std::fs::File::create(dir.join(format!("{name}.log"))).unwrap();
    Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .arg("join")
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["--scene", "assets/scenes/pouring.toml", "--report"])
        .arg(dir.join(format!("{name}.json")))
        .args(extra)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap()
}

fn finish(mut child: Child, dir: &Path, name: &str) -> Value {
    let status = child.wait().unwrap();
    let log = std::fs::read_to_string(dir.join(format!("{name}.log"))).unwrap_or_default();
    assert!(status.success(), "{name} failed:\n{log}");
    let text = std::fs::read_to_string(dir.join(format!("{name}.json"))).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn f(v: &Value, path: &str) -> f64 {
    path.split('.')
        .fold(v, |v, k| &v[k])
        .as_f64()
        .unwrap_or_else(|| panic!("{path} in {v}"))
}

/// The robot site (video off) and the operator through a TCP relay of `delay_s` one way.
fn pour_through(name: &str, delay_s: f64) -> (Value, Value) {
    let dir = out_dir(name);
    let port = free_port();
    let robot = serve(&dir, port, 14.0, &["--insecure-lan", "--video", "off"]);
    let relay = Relay::tcp(
        format!("127.0.0.1:{port}").parse().unwrap(),
        Impairment {
            delay_s,
            jitter_s: delay_s * 0.1,
            seed: 3,
            ..Impairment::default()
        },
    )
    .unwrap();
    let operator = join(&dir, "join", relay.local_addr().port(), &["--wait", "20"]);
    let j = finish(operator, &dir, "join");
    let s = finish(robot, &dir, "serve");
    (s, j)
}

#[test]
fn two_sites_pour_through_the_network_and_delay_costs_accuracy() {
    let (s0, j0) = pour_through("pour_0ms", 0.0);
    let (s1, j1) = pour_through("pour_100ms", 0.1);
    for (s, j) in [(&s0, &j0), (&s1, &j1)] {
        // The whole trial crossed: a target per control tick, joint states back.
        assert!(f(j, "targets_sent") >= 900.0, "{j}");
        assert!(f(s, "targets_used") >= 850.0, "{s}");
        assert!(f(j, "joint_states") >= 800.0, "{j}");
        assert_eq!(f(s, "targets_refused"), 0.0, "{s}");
        assert_eq!(f(s, "nan_commands"), 0.0, "{s}");
        // The real bottle was grasped and lifted through the network.
        assert!(s["trial"]["grasp_at_s"].is_f64(), "{s}");
        assert!(f(s, "trial.real_lift_m") > 0.05, "{s}");
    }
    // The round trip shows the relay's 2 x 100 ms.
    assert!(f(&j1, "clock_rtt_ms") >= 200.0, "{j1}");
    assert!(f(&j0, "clock_rtt_ms") < 50.0, "{j0}");
    // Delay costs accuracy: the real bottle lags its twin.
    let (e0, e1) = (f(&s0, "trial.pos_rmse_m"), f(&s1, "trial.pos_rmse_m"));
    assert!(e0 < 0.02, "no delay: {e0} m");
    assert!(e1 > e0, "100 ms: {e1} m against {e0} m");
    // The target ages as the delay says (median, ms).
    assert!(f(&s1, "target_age_ms.median") >= 100.0, "{s1}");
    assert!(f(&s0, "target_age_ms.median") < 30.0, "{s0}");
}

#[test]
fn a_cut_link_stops_the_arm_and_the_session_resumes() {
    let dir = out_dir("cut");
    let port = free_port();
    let robot = serve(&dir, port, 14.0, &["--insecure-lan", "--video", "off"]);
    let relay = Relay::tcp(
        format!("127.0.0.1:{port}").parse().unwrap(),
        Impairment::default(),
    )
    .unwrap();
    let operator = join(&dir, "join", relay.local_addr().port(), &["--wait", "20"]);
    // Wait until targets flow (the operator's log says it joined), then cut mid-pour.
    let deadline = Instant::now() + Duration::from_secs(30);
    while !std::fs::read_to_string(dir.join("join.log"))
        .unwrap_or_default()
        .contains("joined")
    {
        assert!(Instant::now() < deadline, "the operator never joined");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(4));
    relay.cut_for(Duration::from_secs(2));
    let j = finish(operator, &dir, "join");
    let s = finish(robot, &dir, "serve");
    // One stop for stale targets, about as long as the cut, ended by fresh targets.
    let stops = s["stops"].as_array().unwrap();
    let cut: Vec<&Value> = stops
        .iter()
        .filter(|e| e["reason"].as_str().unwrap_or("").contains("stale"))
        .collect();
    assert_eq!(cut.len(), 1, "{s}");
    let length = f(cut[0], "length_s");
    assert!((1.4..3.0).contains(&length), "stopped {length} s for a 2 s cut: {s}");
    // Neither process restarted: the operator joined once (and left at its end), and targets
    // flowed after the cut.
    assert_eq!(f(&s, "operator_joins"), 1.0, "{s}");
    assert!(f(&s, "targets_used") >= 850.0, "nothing lost: {s}");
    assert!(f(&j, "targets_sent") >= 900.0, "{j}");
    assert_eq!(f(&s, "nan_commands"), 0.0);
}

#[test]
fn the_operator_killed_the_arm_stops_and_holds() {
    let dir = out_dir("killed");
    let port = free_port();
    let robot = serve(&dir, port, 9.0, &["--insecure-lan", "--video", "off"]);
    let mut operator = join(&dir, "join", port, &["--wait", "20"]);
    let deadline = Instant::now() + Duration::from_secs(30);
    while !std::fs::read_to_string(dir.join("join.log"))
        .unwrap_or_default()
        .contains("joined")
    {
        assert!(Instant::now() < deadline, "the operator never joined");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(3));
    operator.kill().unwrap();
    let _ = operator.wait();
    let s = finish(robot, &dir, "serve");
    assert_eq!(f(&s, "operator_leaves"), 1.0, "{s}");
    // The last stop is still on at the end: the arm holds.
    let last = s["stops"].as_array().unwrap().last().unwrap().clone();
    assert!(last["length_s"].is_null(), "{s}");
    let log = std::fs::read_to_string(dir.join("serve.log")).unwrap();
    assert!(log.contains("the operator left; stopping the arm"), "{log}");
    assert_eq!(f(&s, "nan_commands"), 0.0);
}
