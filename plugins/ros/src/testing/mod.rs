//! Test support (feature `testing`): a ROS master on a free port and the simulated Sawyer node
//! (`fake_sawyer.py` beside this file, rospy), each stopped when dropped. Used by this crate's
//! tests and by the app's; needs Debian's `python3-rosmaster` and `python3-rospy`
//! (`scripts/setup.sh`). Panics with the reason when one of them is missing or stops.

use std::io::{BufRead, BufReader};
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use avatarm_core::sim::arm::RobotInterface;
use serde_json::Value;

use crate::RosArm;

/// One ROS test at a time in a test binary: each starts its own master and robot node, and
/// on a 2-core machine their rates suffer when several run at once.
pub fn serial() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A ROS master on a free port, stopped when dropped.
pub struct Master {
    child: Child,
    /// `http://127.0.0.1:PORT`.
    pub uri: String,
}

impl Master {
    /// Starts `rosmaster --core` on a free port and waits until it listens.
    pub fn start() -> Self {
        Self::start_on(free_port())
    }

    /// Starts `rosmaster --core` on `port` (a restarted master: the same URI, no memory of
    /// the nodes that registered with the one before).
    pub fn start_on(port: u16) -> Self {
        let home = std::env::temp_dir().join(format!("avatarm_ros_home_{port}"));
        std::fs::create_dir_all(&home).expect("ROS_HOME");
        let child = Command::new("rosmaster")
            .args(["--core", "-p", &port.to_string()])
            .env("ROS_HOME", &home)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect(
                "rosmaster (Debian's python3-rosmaster; scripts/setup.sh installs it) must be on PATH",
            );
        wait_listening(port, "rosmaster did not listen");
        Self {
            child,
            uri: format!("http://127.0.0.1:{port}"),
        }
    }
}

impl Master {
    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.uri
            .rsplit(':')
            .next()
            .and_then(|p| p.parse().ok())
            .expect("port")
    }
}

impl Drop for Master {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The simulated Sawyer: its process and the last report it printed.
pub struct FakeSawyer {
    child: Child,
    report: Arc<Mutex<Option<Value>>>,
}

impl FakeSawyer {
    /// The node with its clock `offset_s` ahead of the wall clock, its arm at zero.
    pub fn start(master: &Master, offset_s: f64) -> Self {
        Self::start_at(master, offset_s, "")
    }

    /// The node with its arm at `start` (right_j0..right_j6, comma-separated; "" for zeros).
    pub fn start_at(master: &Master, offset_s: f64, start: &str) -> Self {
        Self::start_with(master, offset_s, start, &[])
    }

    /// [`FakeSawyer::start_at`] with more of the script's arguments (`--gripper-device`,
    /// `--rate`, `--disabled`).
    pub fn start_with(master: &Master, offset_s: f64, start: &str, more: &[&str]) -> Self {
        let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src/testing/fake_sawyer.py");
        let mut child = Command::new("/usr/bin/python3")
            .arg(&script)
            .args(["--offset", &offset_s.to_string(), "--start", start])
            .args(more)
            .env("ROS_MASTER_URI", &master.uri)
            .env("ROS_HOME", std::env::temp_dir())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("/usr/bin/python3 with rospy (python3-rospy)");
        let report = reports_of(&mut child);
        Self { child, report }
    }

    /// The node's newest report, waiting for one printed after now.
    pub fn report(&self) -> Value {
        newest_report(&self.report, 10, "the fake Sawyer stopped reporting")
    }

    /// Sends `sig` (`-USR1`: toggle the e-stop, `-USR2`: toggle enabled).
    pub fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &self.child.id().to_string()])
            .status()
            .expect("kill");
        assert!(ok.success());
    }
}

impl Drop for FakeSawyer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A fake ros2_control arm on DDS (`fake_ros2_arm.py` beside this file, PyPI's cyclonedds,
/// which `scripts/setup.sh` installs into `~/.cache/avatarm/python`): its process and the last
/// report it printed.
pub struct FakeRos2Arm {
    child: Child,
    report: Arc<Mutex<Option<Value>>>,
}

impl FakeRos2Arm {
    /// The arm on DDS domain `domain` with `joints` (its controller's order) and more of the
    /// script's arguments (`--mode position`, `--offset S`, `--controller NAME`; `--rmw zenoh
    /// --router ENDPOINT` for rmw_zenoh).
    pub fn start(domain: u16, joints: &[&str], more: &[&str]) -> Self {
        let (child, report) = ros2_peer(
            "fake_ros2_arm.py",
            &[&["--joints", &joints.join(",")][..], more].concat(),
            domain,
        );
        Self { child, report }
    }

    /// The arm's newest report, waiting for one printed after now.
    pub fn report(&self) -> Value {
        newest_report(
            &self.report,
            20,
            "the fake ROS 2 arm stopped reporting (are PyPI's cyclonedds, rosbags and eclipse-zenoh installed? scripts/setup.sh)",
        )
    }

    /// Kills the arm's process (a vanished robot node).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for FakeRos2Arm {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A Zenoh router on a free port of this machine (`rmw_zenoh_peer.py router`, PyPI's
/// eclipse-zenoh: what `ros2 run rmw_zenoh_cpp rmw_zenohd` is to nodes on rmw_zenoh), stopped
/// when dropped.
pub struct ZenohRouter {
    child: Child,
    /// `tcp/127.0.0.1:PORT`.
    pub endpoint: String,
}

impl ZenohRouter {
    /// Starts the router and waits until it listens.
    pub fn start() -> Self {
        let port = free_port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let child = Command::new("python3")
            .arg(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src/testing/rmw_zenoh_peer.py"))
            .args(["router", "--listen", &endpoint])
            .env("PYTHONPATH", python_path())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("python3 runs");
        wait_listening(
            port,
            "the Zenoh router did not listen (is PyPI's eclipse-zenoh installed? scripts/setup.sh)",
        );
        Self { child, endpoint }
    }
}

impl Drop for ZenohRouter {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A TCP port of this machine free now.
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// Waits (at most 20 s, else panics with `silent`) until something listens on `port`.
fn wait_listening(port: u16, silent: &str) {
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(started.elapsed() < Duration::from_secs(20), "{silent}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Where the ROS 2 test peers' PyPI packages are (`scripts/setup.sh` installs them).
fn python_path() -> String {
    std::env::var("HOME")
        .map(|h| format!("{h}/.cache/avatarm/python"))
        .unwrap_or_default()
}

/// The domain of a ROS 2 test: `AVATARM_TEST_DDS_DOMAIN` (default 60) plus `offset`
/// (each test its own: a test binary runs its tests in one process, the DDS participants of
/// several on one domain would see each other's robots), so that two runs on one network can
/// keep apart.
pub fn test_domain(offset: u16) -> u16 {
    std::env::var("AVATARM_TEST_DDS_DOMAIN")
        .ok()
        .and_then(|d| d.parse::<u16>().ok())
        .filter(|d| *d <= 200)
        .unwrap_or(60)
        + offset
}

/// A ROS 2 peer (a script beside this file, run with PyPI's packages of
/// `~/.cache/avatarm/python`) on DDS domain `domain` with `args`: its process and its reports.
fn ros2_peer(script: &str, args: &[&str], domain: u16) -> (Child, Arc<Mutex<Option<Value>>>) {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("src/testing")
        .join(script);
    let mut child = Command::new("python3")
        .arg(&script)
        .args(["--domain", &domain.to_string()])
        .args(args)
        .env("PYTHONPATH", python_path())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("python3 runs");
    let report = reports_of(&mut child);
    (child, report)
}

/// A fake ROS 2 camera driver on DDS (`fake_ros2_camera.py` beside this file, PyPI's
/// cyclonedds): raw `Image` frames of a known pattern, or a file's bytes as
/// `CompressedImage`.
pub struct FakeRos2Camera {
    child: Child,
    report: Arc<Mutex<Option<Value>>>,
}

impl FakeRos2Camera {
    /// The camera on DDS domain `domain` publishing on `topic`, with more of the script's
    /// arguments (`--file PATH`, `--fps N`, `--width W --height H`).
    pub fn start(domain: u16, topic: &str, more: &[&str]) -> Self {
        let (child, report) = ros2_peer(
            "fake_ros2_camera.py",
            &[&["--topic", topic][..], more].concat(),
            domain,
        );
        Self { child, report }
    }

    /// The camera's newest report (`frames` published), waiting for one printed after now.
    pub fn report(&self) -> Value {
        newest_report(&self.report, 5, "the fake ROS 2 camera stopped reporting")
    }
}

impl Drop for FakeRos2Camera {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A ROS 2 listener on DDS (`ros2_listener.py` beside this file, PyPI's cyclonedds) of what
/// Avatarm publishes under a prefix: the erased video, the mask, the commands, the safety
/// events.
pub struct Ros2Listener {
    child: Child,
    report: Arc<Mutex<Option<Value>>>,
}

impl Ros2Listener {
    /// The listener on DDS domain `domain` of the topics under `prefix` (e.g. `/avatarm`).
    pub fn start(domain: u16, prefix: &str) -> Self {
        Self::start_with(domain, prefix, &[])
    }

    /// [`Ros2Listener::start`] with more of the script's arguments (`--rmw zenoh --router
    /// ENDPOINT` for rmw_zenoh).
    pub fn start_with(domain: u16, prefix: &str, more: &[&str]) -> Self {
        let (child, report) = ros2_peer(
            "ros2_listener.py",
            &[&["--prefix", prefix][..], more].concat(),
            domain,
        );
        Self { child, report }
    }

    /// The listener's newest report (per topic: `count` and the last message's content),
    /// waiting for one printed after now.
    pub fn report(&self) -> Value {
        newest_report(&self.report, 10, "the ROS 2 listener stopped reporting")
    }
}

impl Drop for Ros2Listener {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The JSON reports a fake robot prints on its stdout, the newest kept, read on a thread.
fn reports_of(child: &mut Child) -> Arc<Mutex<Option<Value>>> {
    let report = Arc::new(Mutex::new(None));
    let out = child.stdout.take().expect("stdout");
    let sink = report.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if let Ok(v) = serde_json::from_str::<Value>(&line) {
                *sink.lock().expect("report") = Some(v);
            }
        }
    });
    report
}

/// The newest report printed after now (its `t` later), waiting at most `within_s`; panics
/// with `silent` past that.
fn newest_report(report: &Mutex<Option<Value>>, within_s: u64, silent: &str) -> Value {
    let asked = wall_s();
    let started = Instant::now();
    loop {
        if let Some(v) = report.lock().expect("report").clone()
            && v["t"].as_f64().is_some_and(|t| t > asked)
        {
            return v;
        }
        assert!(
            started.elapsed() < Duration::from_secs(within_s),
            "{silent}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The wall clock (s since the Unix epoch): the tests' app clock.
pub fn wall_s() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock")
        .as_secs_f64()
}

/// Pumps the link until a joint state and the robot's state have arrived.
pub fn wait_alive(arm: &mut RosArm) {
    let started = Instant::now();
    while !(arm.alive() && arm.status().robot.is_some()) {
        assert!(
            started.elapsed() < Duration::from_secs(15),
            "no joint state from the robot: {:?}",
            arm.status()
        );
        arm.advance(wall_s());
        arm.receive();
        std::thread::sleep(Duration::from_millis(10));
    }
}
