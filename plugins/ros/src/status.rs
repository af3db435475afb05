//! What the link has measured and the robot's state (enabled, stopped, its gripper), for the status
//! line and the report.

use crate::msgs::intera_core_msgs;

/// The gripper as its last `IODeviceStatus` says (Intera's signal names).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GripperState {
    /// The device commanded.
    pub device: String,
    /// `position_response_m`: the opening (m, 0 closed .. 0.041667 open).
    pub position_m: Option<f64>,
    /// `is_gripping`: the fingers stopped on something.
    pub gripping: Option<bool>,
    /// `is_calibrated`: an uncalibrated gripper does not move (calibrate it first).
    pub calibrated: Option<bool>,
    /// `has_error`.
    pub error: Option<bool>,
}

impl GripperState {
    /// Reads Intera's signals (each a JSON array of one value, e.g. `"[0.041]"`); signals
    /// that are missing or unreadable stay `None`.
    pub(crate) fn read(&mut self, signals: &[intera_core_msgs::IODataStatus]) {
        let value = |name: &str| {
            let s = signals.iter().find(|s| s.name == name)?;
            let v: serde_json::Value = serde_json::from_str(&s.data).ok()?;
            match v {
                serde_json::Value::Array(a) => a.into_iter().next(),
                v => Some(v),
            }
        };
        self.position_m = value("position_response_m")
            .and_then(|v| v.as_f64())
            .filter(|v| v.is_finite());
        self.gripping = value("is_gripping").and_then(|v| v.as_bool());
        self.calibrated = value("is_calibrated").and_then(|v| v.as_bool());
        self.error = value("has_error").and_then(|v| v.as_bool());
    }
}

/// Intera's robot state, as last received.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RobotState {
    /// Motors enabled.
    pub enabled: bool,
    /// E-stop asserted.
    pub stopped: bool,
    /// A component has an error.
    pub error: bool,
    /// Intera's `estop_button` (0 unpressed, 1 pressed, 2 unknown, 3 released).
    pub estop_button: u8,
    /// Intera's `estop_source` (0 none, 1 user, 2 unknown, 3 fault, 4 engine).
    pub estop_source: u8,
}

/// What the link has measured, for the status line and the report.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinkStatus {
    /// Connected to the master (ROS 1), or the node up on DDS or rmw_zenoh (ROS 2); topics up.
    pub connected: bool,
    /// A ROS 2 link's middleware and where it meets its peers, as
    /// [`crate::Ros2Transport::describe`] says it (e.g. `rmw_zenoh domain 0 (router
    /// tcp/localhost:7447)`); `None` for a ROS 1 link.
    pub ros2: Option<String>,
    /// Joint states received.
    pub joint_states: u64,
    /// Joint states refused (a missing arm joint, a NaN, sizes that do not match).
    pub bad_joint_states: u64,
    /// The last refusal.
    pub last_bad: Option<String>,
    /// Commands handed to the client.
    pub commands_sent: u64,
    /// Commands refused (link lost, robot disabled or stopped, not finite).
    pub commands_refused: u64,
    /// Times the link was lost.
    pub losses: u64,
    /// Times the client (re)connected.
    pub connects: u64,
    /// The robot's state, when it has one.
    pub robot: Option<RobotState>,
    /// Avatarm's clock (the app clock of [`RobotInterface::advance`]) minus the robot's (s),
    /// and the jitter of the estimate (s).
    pub clock_offset_s: Option<(f64, f64)>,
    /// The robot's clock minus this machine's system clock (s), less the smallest transport
    /// delay: what clock synchronisation (NTP, chrony) between the two machines leaves; and
    /// the jitter of the arrivals on the system clock (s): the network's and the two nodes'
    /// (the app clock's own unevenness is not in it).
    pub robot_minus_local_s: Option<(f64, f64)>,
    /// Joint states received over the last second (Hz), while the link is alive.
    pub joint_state_rate_hz: Option<f64>,
    /// The gripper, once its device is known.
    pub gripper: Option<GripperState>,
}

impl LinkStatus {
    /// One line for the preview's status line and the end of a run, e.g. `ROS link up, robot
    /// enabled, joint states 100 Hz, robot clock +0.4 ms (jitter 0.2 ms), gripper right_gripper
    /// 0.041 m`, or for a ROS 2 link `ROS 2 link up on DDS domain 0, joint states 100 Hz, ...`.
    /// States that stop commands come first, in capitals.
    pub fn line(&self) -> String {
        let mut parts = Vec::new();
        let (ros, on) = match &self.ros2 {
            Some(middleware) => ("ROS 2", format!(" on {middleware}")),
            None => ("ROS", String::new()),
        };
        match (self.connected, self.joint_state_rate_hz, &self.ros2) {
            (false, _, Some(middleware)) => {
                parts.push(format!("ROS 2 link DOWN (no node on {middleware})"));
            }
            (false, _, None) => {
                parts.push("ROS link DOWN (not connected to the master)".to_owned());
            }
            (true, None, _) => parts.push(format!("{ros} link DOWN (no joint states{on})")),
            (true, Some(_), _) => parts.push(format!("{ros} link up{on}")),
        }
        match self.robot {
            Some(r) if r.stopped => {
                parts.push(format!("robot E-STOPPED (source {})", r.estop_source));
            }
            Some(r) if !r.enabled => parts.push("robot DISABLED".to_owned()),
            Some(r) if r.error => parts.push("robot enabled with an ERROR".to_owned()),
            Some(_) => parts.push("robot enabled".to_owned()),
            None => {}
        }
        if let Some(hz) = self.joint_state_rate_hz {
            parts.push(format!("joint states {hz:.0} Hz"));
        }
        if let Some((d, jitter)) = self.robot_minus_local_s {
            parts.push(format!(
                "robot clock {:+.1} ms from this machine's (jitter {:.1} ms)",
                d * 1e3,
                jitter * 1e3
            ));
        }
        if let Some(g) = &self.gripper {
            let mut s = format!("gripper {}", g.device);
            if let Some(p) = g.position_m {
                s += &format!(" {p:.3} m");
            }
            if g.gripping == Some(true) {
                s += " gripping";
            }
            if g.calibrated == Some(false) {
                s += " NOT CALIBRATED";
            }
            if g.error == Some(true) {
                s += " ERROR";
            }
            parts.push(s);
        }
        if self.commands_refused > 0 {
            parts.push(format!("{} commands refused", self.commands_refused));
        }
        if self.losses > 0 {
            parts.push(format!("link lost {} times", self.losses));
        }
        parts.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::LinkStatus;

    /// Each link's words, down and up: a ROS 2 link names its middleware and where, ROS 1's
    /// says the master.
    #[test]
    fn the_line_names_the_link_and_its_middleware() {
        let line = |ros2: Option<&str>, connected: bool, rate: Option<f64>| {
            LinkStatus {
                ros2: ros2.map(str::to_owned),
                connected,
                joint_state_rate_hz: rate,
                ..LinkStatus::default()
            }
            .line()
        };
        let zenoh = Some("rmw_zenoh domain 3 (router tcp/10.0.0.2:7447)");
        assert_eq!(
            line(zenoh, false, None),
            "ROS 2 link DOWN (no node on rmw_zenoh domain 3 (router tcp/10.0.0.2:7447))"
        );
        assert_eq!(
            line(Some("DDS domain 0"), true, None),
            "ROS 2 link DOWN (no joint states on DDS domain 0)"
        );
        assert_eq!(
            line(Some("DDS domain 0"), true, Some(100.0)),
            "ROS 2 link up on DDS domain 0, joint states 100 Hz"
        );
        assert_eq!(
            line(None, false, None),
            "ROS link DOWN (not connected to the master)"
        );
        assert_eq!(line(None, true, None), "ROS link DOWN (no joint states)");
        assert_eq!(
            line(None, true, Some(99.6)),
            "ROS link up, joint states 100 Hz"
        );
    }
}
