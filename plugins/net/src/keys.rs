//! The session's key space (`docs/network.md`): everything under `avatarm/<site>/`.
//!
//! | key | from | what |
//! |---|---|---|
//! | `robot/info` | robot site (queryable) | [`crate::msg::RobotInfo`]: versions, scene, cameras |
//! | `robot/clock` | robot site (queryable) | its clock now, for the operator's offset |
//! | `robot/joint_states` | robot site | [`crate::msg::JointStatesMsg`] at the control rate |
//! | `robot/status` | robot site | [`crate::msg::RobotStatusMsg`] |
//! | `camera/<name>/erased` | robot site | the erased video ([`crate::msg::FrameHeader`] attached) |
//! | `camera/<name>/keyframe` | robot site (queryable) | a viewer asks for an H.264 IDR frame |
//! | `camera/<name>/head` | the head camera's wearer | [`crate::msg::HeadPoseMsg`]: the head it rides on |
//! | `operator/target` | operator | [`crate::msg::TargetMsg`] each control tick |
//! | `operator/hand` | operator | [`crate::msg::HandMsg`] for observers |
//! | `operator/alive` | operator (liveliness token) | present while the operator is |

/// The key space of one session (one robot site).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    site: String,
}

impl Keys {
    /// The keys of site `site` (a single key chunk: letters, digits, `-` and `_`). Errors name
    /// the bad name.
    pub fn new(site: &str) -> Result<Self, crate::NetError> {
        let ok = !site.is_empty()
            && site.len() <= 64
            && site
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if ok {
            Ok(Self { site: site.into() })
        } else {
            Err(crate::NetError::Config {
                what: "--site".into(),
                message: format!("'{site}' must be 1-64 letters, digits, '-' or '_'"),
            })
        }
    }

    /// The site's name.
    pub fn site(&self) -> &str {
        &self.site
    }

    fn key(&self, rest: &str) -> String {
        format!("avatarm/{}/{rest}", self.site)
    }

    /// Everything of the session.
    pub fn session_space(&self) -> String {
        self.key("**")
    }
    /// The robot site's keys.
    pub fn robot_space(&self) -> String {
        self.key("robot/**")
    }
    /// The cameras' keys.
    pub fn camera_space(&self) -> String {
        self.key("camera/**")
    }
    /// The operator's keys.
    pub fn operator_space(&self) -> String {
        self.key("operator/**")
    }
    /// The robot site's info (queryable).
    pub fn info(&self) -> String {
        self.key("robot/info")
    }
    /// The robot site's clock (queryable).
    pub fn clock(&self) -> String {
        self.key("robot/clock")
    }
    /// Joint states.
    pub fn joint_states(&self) -> String {
        self.key("robot/joint_states")
    }
    /// The robot site's status.
    pub fn status(&self) -> String {
        self.key("robot/status")
    }
    /// Camera `name`'s erased video.
    pub fn erased(&self, camera: &str) -> String {
        self.key(&format!("camera/{camera}/erased"))
    }
    /// Every camera's erased video.
    pub fn all_erased(&self) -> String {
        self.key("camera/*/erased")
    }
    /// Camera `name`'s keyframe requests (queryable).
    pub fn keyframe(&self, camera: &str) -> String {
        self.key(&format!("camera/{camera}/keyframe"))
    }
    /// Every camera's keyframe requests.
    pub fn all_keyframes(&self) -> String {
        self.key("camera/*/keyframe")
    }
    /// Camera `name`'s head (the wearer's headset).
    pub fn head(&self, camera: &str) -> String {
        self.key(&format!("camera/{camera}/head"))
    }
    /// Every camera's head.
    pub fn all_heads(&self) -> String {
        self.key("camera/*/head")
    }
    /// The operator's targets.
    pub fn target(&self) -> String {
        self.key("operator/target")
    }
    /// The operator's hand.
    pub fn hand(&self) -> String {
        self.key("operator/hand")
    }
    /// The operator's liveliness token.
    pub fn alive(&self) -> String {
        self.key("operator/alive")
    }
}

impl Default for Keys {
    fn default() -> Self {
        Self {
            site: "desk".into(),
        }
    }
}
