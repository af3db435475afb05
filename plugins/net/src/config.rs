//! A site's Zenoh configuration: endpoints, authentication, TLS and access control, built
//! from a few settings with safe defaults ([`NetConfig::zenoh`]).
//!
//! - No multicast scouting and no gossip: sites find each other only through the endpoints
//!   given (two sessions on one network never join by accident).
//! - The robot site listens, or connects to a router (then nothing listens at the robot
//!   site). Whatever listens refuses to do so without a credentials dictionary unless
//!   [`NetConfig::insecure_lan`] is set.
//! - With credentials, Zenoh's access control lets only the dictionary's operators
//!   ([`NetConfig::operators`]) put on the operator's keys and declare its liveliness token:
//!   an observer's or a stranger's target never reaches the robot's loop.
//! - A router with a dictionary also lets only its robot sites ([`NetConfig::robot_sites`],
//!   users that connect to it) publish on the robot's keys: none of its other users can feed
//!   viewers false joint states or video. Zenoh's `usrpwd` authenticates the side that
//!   connects, so the robot site connects to the router and logs in; a router that connects
//!   out cannot tell who is at the other end, and is refused with a dictionary.

use std::path::PathBuf;

use crate::NetError;
use crate::keys::Keys;

/// What a process is in the session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Alice's desk: the robot and the cameras (`avatarm serve`); a Zenoh peer that listens.
    RobotSite,
    /// Blair: the hand and the targets (`avatarm join`); a Zenoh client.
    Operator,
    /// An observer (`avatarm join --watch`); a Zenoh client.
    Observer,
    /// A router between the sites that fans the video out (`avatarm router`).
    Router,
}

/// A user name and password this side presents (Zenoh's `usrpwd` authentication).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Credentials {
    /// User name.
    pub user: String,
    /// Password.
    pub password: String,
}

impl Credentials {
    /// Reads `user:password` from the first line of `path`.
    pub fn from_file(path: &std::path::Path) -> Result<Self, NetError> {
        let text = std::fs::read_to_string(path).map_err(|e| NetError::Config {
            what: path.display().to_string(),
            message: format!("cannot read the credentials: {e}"),
        })?;
        let line = text.lines().next().unwrap_or("").trim();
        match line.split_once(':') {
            Some((user, password)) if !user.is_empty() && !password.is_empty() => Ok(Self {
                user: user.into(),
                password: password.into(),
            }),
            _ => Err(NetError::Config {
                what: path.display().to_string(),
                message: "the first line must be user:password".into(),
            }),
        }
    }
}

/// TLS files (PEM). The listening side needs its certificate and key; the connecting side
/// needs the authority's certificate to check the listener's.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TlsFiles {
    /// The certificate authority's certificate.
    pub root_ca: Option<PathBuf>,
    /// This side's certificate (listening side).
    pub certificate: Option<PathBuf>,
    /// This side's private key (listening side).
    pub private_key: Option<PathBuf>,
}

/// An endpoint whose link is encrypted and authenticated by certificates: QUIC (`quic/`, TLS 1.3
/// inside QUIC, through quinn; Zenoh's `transport.link.tls` certificate files).
pub fn secure(endpoint: &str) -> bool {
    endpoint.starts_with("quic/")
}

/// Why `tls/` (Zenoh's TLS over TCP) is refused: its link reads and writes one rustls stream
/// from two tasks at once, and the process dies of it under load (SIGILL in the link's sending
/// task: eclipse-zenoh/zenoh#2557, zenoh 1.10.2; docs/network.md).
pub const TLS_REFUSED: &str = "Zenoh's tls/ link crashes its process under load (it reads and \
    writes one TLS stream from two tasks: eclipse-zenoh/zenoh#2557, docs/network.md): use \
    quic/ with the same certificate flags, or tcp/ inside a tunnel you trust (WireGuard, SSH) \
    where UDP is blocked";

/// A site's network settings.
#[derive(Debug, Clone, PartialEq)]
pub struct NetConfig {
    /// What this process is.
    pub role: Role,
    /// The session's key space.
    pub keys: Keys,
    /// Endpoints to listen on (`tcp/0.0.0.0:7447`, `udp/...`, `quic/...`).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// What this side presents.
    pub credentials: Option<Credentials>,
    /// The listening side's dictionary of `user:password` lines (who may connect).
    pub dictionary: Option<PathBuf>,
    /// User names (in the dictionary) allowed to command the robot.
    pub operators: Vec<String>,
    /// A router's robot sites: user names (in its dictionary) of the robot sites that connect
    /// to it, the only ones allowed to publish on the robot's keys through it.
    pub robot_sites: Vec<String>,
    /// TLS files.
    pub tls: Option<TlsFiles>,
    /// Listen without authentication (a trusted LAN or a test).
    pub insecure_lan: bool,
}

fn json(s: &str) -> String {
    serde_json::Value::String(s.to_owned()).to_string()
}

fn list(items: &[String]) -> String {
    serde_json::Value::from(items.to_vec()).to_string()
}

impl NetConfig {
    /// Checks the settings: endpoints present, a listener only with a dictionary (or
    /// `insecure_lan`), TLS files that exist. The error names the setting.
    pub fn validate(&self) -> Result<(), NetError> {
        let bad = |what: &str, message: String| {
            Err(NetError::Config {
                what: what.into(),
                message,
            })
        };
        let listens = !self.listen.is_empty();
        match self.role {
            Role::Router if !listens => {
                return bad("--listen", "a router needs an endpoint to listen on".into());
            }
            Role::RobotSite if !listens && self.connect.is_empty() => {
                return bad(
                    "--listen",
                    "a robot site listens (--listen) or connects to a router (--connect)".into(),
                );
            }
            Role::RobotSite if listens && !self.connect.is_empty() && !self.insecure_lan => {
                return bad(
                    "--connect",
                    "a robot site that listens cannot also connect to a router (who sends \
                     through that link is not authenticated): choose one, or --insecure-lan"
                        .into(),
                );
            }
            Role::Operator | Role::Observer if self.connect.is_empty() => {
                return bad("ENDPOINT", "an endpoint to connect to is needed".into());
            }
            _ => {}
        }
        // A robot site that only connects takes whatever its router sends as its operators':
        // it must know that router (TLS, checked against the authority's certificate).
        if self.role == Role::RobotSite && !listens && !self.insecure_lan {
            let checked = self.tls.as_ref().is_some_and(|t| t.root_ca.is_some());
            if !self.connect.iter().all(|e| secure(e)) || !checked {
                return bad(
                    "--connect",
                    "a robot site that connects to a router obeys it: connect over quic/ \
                     with --tls-ca (the router's authority), or --insecure-lan on a network you \
                     trust"
                        .into(),
                );
            }
        }
        if self.role != Role::Router && !self.robot_sites.is_empty() {
            return bad(
                "--robot-site",
                "only a router takes robot-site users (a robot site publishes its own keys)".into(),
            );
        }
        for e in self.listen.iter().chain(&self.connect) {
            if e.starts_with("tls/") {
                return bad("endpoint", format!("'{e}': {TLS_REFUSED}"));
            }
            if e.parse::<zenoh::config::EndPoint>().is_err()
                || !["tcp/", "udp/", "quic/"].iter().any(|p| e.starts_with(p))
            {
                return bad(
                    "endpoint",
                    format!("'{e}' is not tcp/HOST:PORT, udp/HOST:PORT or quic/HOST:PORT"),
                );
            }
        }
        if listens && self.dictionary.is_none() && !self.insecure_lan {
            return bad(
                "--credentials",
                "refusing to listen without authentication: give a dictionary of user:password \
                 lines (--credentials FILE), or --insecure-lan on a network you trust"
                    .into(),
            );
        }
        if let Some(d) = &self.dictionary {
            let text = match std::fs::read_to_string(d) {
                Ok(text) => text,
                Err(e) => return bad("--credentials", format!("{}: {e}", d.display())),
            };
            let users: Vec<&str> = text
                .lines()
                .filter_map(|l| l.split_once(':').map(|(u, _)| u.trim()))
                .collect();
            for (flag, names) in [
                ("--operator", &self.operators),
                ("--robot-site", &self.robot_sites),
            ] {
                if let Some(name) = names.iter().find(|n| !users.contains(&n.as_str())) {
                    return bad(flag, format!("'{name}' is not a user of {}", d.display()));
                }
            }
            if let Some(name) = users.iter().find(|u| u.is_empty() || **u == "-") {
                return bad(
                    "--credentials",
                    format!("'{name}' is not a usable user name in {}", d.display()),
                );
            }
            if self.role == Role::Router {
                if self.operators.is_empty() {
                    return bad(
                        "--operator",
                        "a router with a dictionary needs the user(s) who may command \
                         (--operator USER)"
                            .into(),
                    );
                }
                if self.robot_sites.is_empty() {
                    return bad(
                        "--robot-site",
                        "a router with a dictionary needs the user its robot site logs in as \
                         (the robot site connects to it: serve --connect)"
                            .into(),
                    );
                }
                if !self.connect.is_empty() {
                    return bad(
                        "--connect",
                        "a router with a dictionary does not connect out: what comes back on a \
                         link it opened is not authenticated; let the robot site connect to it \
                         (serve --connect) and log in as a --robot-site user"
                            .into(),
                    );
                }
            }
        } else if !self.robot_sites.is_empty() {
            return bad(
                "--robot-site",
                "names a user of the router's dictionary: give --credentials".into(),
            );
        }
        if let Some(tls) = &self.tls {
            for (name, p) in [
                ("--tls-ca", &tls.root_ca),
                ("--tls-cert", &tls.certificate),
                ("--tls-key", &tls.private_key),
            ] {
                if let Some(p) = p
                    && !p.is_file()
                {
                    return bad(name, format!("{} is not a file", p.display()));
                }
            }
            let tls_listen = self.listen.iter().any(|e| secure(e));
            if tls_listen && (tls.certificate.is_none() || tls.private_key.is_none()) {
                return bad(
                    "--tls-cert",
                    "a QUIC or TLS listener needs --tls-cert and --tls-key".into(),
                );
            }
        }
        Ok(())
    }

    /// The Zenoh configuration (JSON5 built from the settings, then parsed by Zenoh).
    pub fn zenoh(&self) -> Result<zenoh::Config, NetError> {
        self.validate()?;
        let mode = match self.role {
            Role::RobotSite => "peer",
            Role::Operator | Role::Observer => "client",
            Role::Router => "router",
        };
        let mut auth = Vec::new();
        if let Some(c) = &self.credentials {
            auth.push(format!(
                "user: {}, password: {}",
                json(&c.user),
                json(&c.password)
            ));
        }
        if let Some(d) = &self.dictionary {
            auth.push(format!(
                "dictionary_file: {}",
                json(&d.display().to_string())
            ));
        }
        let mut tls = Vec::new();
        if let Some(t) = &self.tls {
            for (key, p) in [
                ("root_ca_certificate", &t.root_ca),
                ("listen_certificate", &t.certificate),
                ("listen_private_key", &t.private_key),
            ] {
                if let Some(p) = p {
                    tls.push(format!("{key}: {}", json(&p.display().to_string())));
                }
            }
        }
        let acl = if self.dictionary.is_some() {
            self.access_control()
        } else {
            String::new()
        };
        let text = format!(
            "{{ mode: {mode}, \
               listen: {{ endpoints: {listen} }}, \
               connect: {{ endpoints: {connect} }}, \
               scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }}, \
               transport: {{ auth: {{ usrpwd: {{ {auth} }} }}, link: {{ tls: {{ {tls} }} }} }}, \
               {acl} }}",
            mode = json(mode),
            listen = list(&self.listen),
            connect = list(&self.connect),
            auth = auth.join(", "),
            tls = tls.join(", "),
        );
        zenoh::Config::from_json5(&text).map_err(|e| NetError::Config {
            what: "zenoh configuration".into(),
            message: e.to_string(),
        })
    }

    /// Access control: denied unless allowed; everyone authenticated may read the session;
    /// only [`NetConfig::operators`] may put on the operator's keys and the cameras' heads, or
    /// declare the operator's token. At
    /// the robot site its own keys only go out; at a router they come in only from
    /// [`NetConfig::robot_sites`] and go out to anyone.
    fn access_control(&self) -> String {
        let k = &self.keys;
        let all = r#"["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable", "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]"#;
        let read = r#"["declare_subscriber", "query", "liveliness_query", "declare_liveliness_subscriber"]"#;
        let robot = list(&[k.robot_space(), k.camera_space()]);
        let session = list(&[k.session_space()]);
        // The operators' keys, and the head a camera rides on: its wearer is trusted as an
        // operator is (the pose only steers that camera's mask, never the arm).
        let operator = list(&[k.operator_space(), k.all_heads()]);
        // A subject and its policy only for users named: nobody else gets those rules.
        let mut subjects = vec![r#"{ id: "anyone" }"#.to_owned()];
        let mut policies = vec![
            r#"{ rules: ["robot_out", "read", "forward_operator"], subjects: ["anyone"] }"#
                .to_owned(),
        ];
        for (id, rule, users) in [
            ("operators", "command", &self.operators),
            ("robot_sites", "robot_in", &self.robot_sites),
        ] {
            if !users.is_empty() {
                subjects.push(format!(r#"{{ id: "{id}", usernames: {} }}"#, list(users)));
                policies.push(format!(r#"{{ rules: ["{rule}"], subjects: ["{id}"] }}"#));
            }
        }
        let (subjects, policies) = (subjects.join(", "), policies.join(", "));
        format!(
            r#"access_control: {{
                enabled: true,
                default_permission: "deny",
                rules: [
                  {{ id: "robot_out", messages: {all}, flows: ["egress"], permission: "allow", key_exprs: {robot} }},
                  {{ id: "robot_in", messages: {all}, flows: ["ingress"], permission: "allow", key_exprs: {robot} }},
                  {{ id: "read", messages: {read}, flows: ["egress", "ingress"], permission: "allow", key_exprs: {session} }},
                  {{ id: "forward_operator", messages: ["put", "delete", "liveliness_token"], flows: ["egress"], permission: "allow", key_exprs: {operator} }},
                  {{ id: "command", messages: ["put", "delete", "liveliness_token"], flows: ["ingress"], permission: "allow", key_exprs: {operator} }},
                ],
                subjects: [ {subjects} ],
                policies: [ {policies} ],
              }},"#
        )
    }
}
