//! The robot site over a secure link (`quic/`; `tls/` refused) with credentials and access control:
//! who gets a session, what a refused peer is told, who may command, checked with the real
//! `serve` and `join` processes.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use avatarm::net::join::JoinReport;
use avatarm::net::serve::ServeReport;

use crate::network::{finish, free_port, out_dir, report};
use crate::serial;

/// A certificate authority and the robot site's certificate for localhost and 127.0.0.1,
/// made with the openssl command line (Debian's `openssl` package).
fn certificates(dir: &Path) {
    let sh = |args: &str| {
        let out = Command::new("sh")
            .arg("-c")
            .arg(args)
            .current_dir(dir)
            .output()
            .expect("needs the openssl command (apt install openssl)");
        assert!(
            out.status.success(),
            "{args}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    sh(
        "openssl req -x509 -newkey rsa:2048 -nodes -keyout ca.key -out ca.pem -days 2 -subj '/CN=avatarm test CA'",
    );
    sh("openssl req -newkey rsa:2048 -nodes -keyout site.key -out site.csr -subj '/CN=localhost'");
    std::fs::write(
        dir.join("ext.cnf"),
        "subjectAltName=DNS:localhost,IP:127.0.0.1\n",
    )
    .expect("the test's set-up");
    sh(
        "openssl x509 -req -in site.csr -CA ca.pem -CAkey ca.key -CAcreateserial -out site.pem -days 2 -extfile ext.cnf",
    );
}

/// TLS over TCP, Zenoh's `tls/` link, is refused by every command, naming why and what to use:
/// it killed this test's robot site (SIGILL in the link's sending task, eclipse-zenoh/zenoh#2557)
/// in 1 of 2 of its runs in a 10-run repeat of this binary.
#[test]
fn tls_over_tcp_is_refused_naming_its_fault_and_quic() {
    let dir = out_dir("tls_refused");
    certificates(&dir);
    std::fs::write(dir.join("users.txt"), "blair:pour-carefully\n").expect("the test's set-up");
    let port = free_port();
    let mut serve = serve_secure(&dir, &format!("tls/localhost:{port}"));
    let status = serve.wait().expect("the test's set-up");
    let log = std::fs::read_to_string(dir.join("serve.log")).unwrap_or_default();
    assert!(!status.success(), "{log}");
    for words in ["zenoh#2557", "quic/", "tunnel"] {
        assert!(log.contains(words), "{words}: {log}");
    }
    let out = Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args([
            "join",
            &format!("tls/localhost:{port}"),
            "--watch",
            "--wait",
            "1",
        ])
        .output()
        .expect("the test's set-up");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("zenoh#2557"), "{err}");
}

/// QUIC (TLS 1.3 inside QUIC, through quinn): the secure link recommended between real sites.
#[test]
fn over_quic_only_the_authenticated_operator_moves_the_robot() {
    secure_session("quic");
}

/// An authenticated non-operator that commands anyway, as a hostile peer would (past `join`'s
/// own refusal): opens an operator's session with `credentials` over `endpoint` (checked
/// against `ca`) and publishes valid targets for `seconds`. Returns how many it published.
fn impostor(endpoint: &str, credentials: (&str, &str), ca: &Path, seconds: f64) -> u64 {
    let config = avatarm_net::NetConfig {
        role: avatarm_net::Role::Operator,
        keys: avatarm_net::Keys::new("desk").expect("the test's set-up"),
        listen: vec![],
        connect: vec![endpoint.to_owned()],
        credentials: Some(avatarm_net::Credentials {
            user: credentials.0.into(),
            password: credentials.1.into(),
        }),
        dictionary: None,
        operators: vec![],
        robot_sites: vec![],
        tls: Some(avatarm_net::TlsFiles {
            root_ca: Some(ca.to_owned()),
            certificate: None,
            private_key: None,
        }),
        insecure_lan: false,
    };
    let site = avatarm_net::OperatorSite::join(&config, Duration::from_secs(10))
        .expect("an authenticated user gets a session");
    let target = avatarm_core::teleop::mapping::OperatorTarget {
        stamp_s: 0.0,
        target: nalgebra::Isometry3::translation(0.6, 0.0, 0.9),
        object_twist: nalgebra::Vector6::zeros(),
        twin_twist: nalgebra::Vector6::zeros(),
        squeeze_n: 2.0,
        rank: 6,
        contacts: 3,
        held: true,
    };
    let started = Instant::now();
    let mut sent = 0;
    while started.elapsed().as_secs_f64() < seconds {
        let now = site.robot_now_s();
        let t = avatarm_core::teleop::mapping::OperatorTarget {
            stamp_s: now,
            ..target
        };
        // Put, and the access control drops it at the robot site: no error here.
        site.publish_target(&avatarm_net::msg::TargetMsg::new(sent + 1, &t, now, true))
            .expect("a put is not refused locally");
        sent += 1;
        std::thread::sleep(Duration::from_millis(10));
    }
    site.close();
    sent
}

/// `avatarm serve` of the pouring scene for 36 s on `endpoint` with `dir`'s certificate and
/// users (`blair` the operator), logging into `dir`.
fn serve_secure(dir: &Path, endpoint: &str) -> std::process::Child {
    let path = |name: &str| dir.join(name);
    let log = std::fs::File::create(dir.join("serve.log")).expect("the test's set-up");
    Command::new(env!("CARGO_BIN_EXE_avatarm"))
        .args(["serve", "assets/scenes/pouring.toml", "--video", "off"])
        .args(["--listen", endpoint])
        .arg("--tls-cert")
        .arg(path("site.pem"))
        .arg("--tls-key")
        .arg(path("site.key"))
        .arg("--credentials")
        .arg(path("users.txt"))
        .args(["--operator", "blair", "--duration", "36", "--report"])
        .arg(path("serve.json"))
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("the test's set-up")
}

/// `avatarm serve` with credentials over `proto` (`quic`): refused without the
/// authority's certificate or a login (each error saying what to check), an observer's user
/// refused as an operator by `join` and its targets, published anyway, never used; the
/// operator's targets move the robot.
fn secure_session(proto: &str) {
    let _serial = serial();
    let dir = out_dir(proto);
    certificates(&dir);
    std::fs::write(
        dir.join("users.txt"),
        "blair:pour-carefully\nwatcher:just-looking\n",
    )
    .expect("the test's set-up");
    std::fs::write(dir.join("blair.txt"), "blair:pour-carefully\n").expect("the test's set-up");
    std::fs::write(dir.join("watcher.txt"), "watcher:just-looking\n").expect("the test's set-up");
    let port = free_port();
    let endpoint = format!("{proto}/localhost:{port}");
    let path = |name: &str| {
        dir.join(name)
            .to_str()
            .expect("the test's set-up")
            .to_owned()
    };
    let robot = serve_secure(&dir, &endpoint);
    let join_as = |name: &str, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_avatarm"))
            .args(["join", &endpoint, "--scene", "assets/scenes/pouring.toml"])
            .args(["--report", &path(&format!("{name}.json"))])
            .args(extra)
            .output()
            .expect("the test's set-up")
    };
    // Without the authority's certificate, or without credentials: refused.
    let out = join_as(
        "no_ca",
        &["--credentials", &path("blair.txt"), "--wait", "3"],
    );
    // Each refusal says what to check (Zenoh itself says only that it could not connect).
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "joined without the CA");
    assert!(
        err.contains("no --tls-ca") && err.contains("login of user 'blair'"),
        "{err}"
    );
    let out = join_as("no_user", &["--tls-ca", &path("ca.pem"), "--wait", "3"]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "joined without credentials");
    assert!(
        err.contains("requires a login: give --credentials") && err.contains("ca.pem"),
        "{err}"
    );
    // An observer's credentials playing an operator: refused at once, naming --watch (the
    // access control would deny its targets anyway: avatarm_net's
    // `only_the_dictionary_s_operator_can_command_the_robot`).
    let watcher = [
        "--tls-ca",
        &path("ca.pem"),
        "--credentials",
        &path("watcher.txt"),
        "--duration",
        "3",
        "--wait",
        "10",
    ];
    let out = join_as("watcher", &watcher);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "an observer joined as an operator");
    assert!(
        err.contains("user 'watcher' may not command")
            && err.contains("operators: blair")
            && err.contains("--watch"),
        "{err}"
    );
    // As an observer, it watches.
    let out = join_as("watcher", &[&watcher[..], &["--watch"]].concat());
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    // Commanding anyway, past join's refusal: its targets are put, and never delivered.
    let impostor_started = Instant::now();
    let impostor_sent = impostor(
        &endpoint,
        ("watcher", "just-looking"),
        &dir.join("ca.pem"),
        3.0,
    );
    let impostor_s = impostor_started.elapsed().as_secs_f64();
    assert!(impostor_sent > 100, "{impostor_sent} targets put");
    // The operator.
    let out = join_as(
        "blair",
        &[
            "--tls-ca",
            &path("ca.pem"),
            "--credentials",
            &path("blair.txt"),
            "--duration",
            "4",
            "--wait",
            "10",
        ],
    );
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let s: ServeReport = finish(robot, &dir, "serve");
    let watcher: JoinReport = report(&dir, "watcher");
    let blair: JoinReport = report(&dir, "blair");
    assert_eq!(watcher.role, "observer", "{watcher:?}");
    assert_eq!(watcher.targets_sent, 0, "{watcher:?}");
    assert!(watcher.joint_states > 0, "{watcher:?}");
    eprintln!(
        "{proto}: the impostor put {impostor_sent} targets in {impostor_s:.1} s; the robot site used {} (Blair sent {})",
        s.targets_used, blair.targets_sent
    );
    assert!(blair.targets_sent > 350, "{blair:?}");
    // Only the operator's targets reached the robot.
    let used = s.targets_used;
    assert!(used > 0 && used <= blair.targets_sent, "{s:?}");
    // An operator was present only inside Blair's window, never in the observer's, which
    // ended before hers began: every join the robot site saw (on its clock) lies between Blair's
    // clock's zero, before which her token cannot exist, and her exit (her session's length,
    // plus 2 s for her start-up queries and the close). Zenoh 1.10's TLS link can drop and
    // reconnect under load (eclipse-zenoh/zenoh#2557; docs/network.md), each time a leave and
    // a join of the same operator, so joins are not asserted to be one.
    let start = blair.clock_offset_s;
    let end = start + blair.duration_s + 2.0;
    assert!(
        watcher.clock_offset_s + watcher.duration_s < start,
        "the watcher's window overlaps Blair's: {watcher:?} {blair:?}"
    );
    let changes = &s.operator_changes;
    let joins = s.operator_joins;
    assert!(joins >= 1, "{s:?}");
    assert_eq!(s.operator_leaves, joins, "she left at the end: {s:?}");
    assert_eq!(changes.len() as u64, 2 * joins, "{s:?}");
    for (i, change) in changes.iter().enumerate() {
        assert_eq!(
            change.present,
            i % 2 == 0,
            "joins and leaves alternate, a join first: {s:?}"
        );
        let t = change.t_s;
        assert!(
            t >= start - 0.05 && t <= end,
            "an operator came or went outside Blair's window [{start}, {end}]: {s:?}"
        );
    }
}
