//! The crate's one error type.

/// What can go wrong setting up or running the teleoperation loop and the pouring trials.
#[derive(Debug, thiserror::Error)]
pub enum MappingError {
    /// A setting, a hand script or an IK solve of the core refused.
    #[error(transparent)]
    Core(Box<avatarm_core::Error>),
    /// The task or its set-up is not valid (errors name the `task.*` field).
    #[error(transparent)]
    Task(Box<avatarm_scene::SceneError>),
    /// The teleoperation loop's configuration is not consistent with the robot.
    #[error("teleoperation set-up: {message}")]
    Setup {
        /// What is wrong.
        message: String,
    },
    /// The arm could not be placed with its gripper around the object.
    #[error("placing the gripper around the bottle: {source}")]
    Grasp {
        /// The last IK failure.
        source: Box<avatarm_core::Error>,
    },
    /// A robot backend refused a command.
    #[error(transparent)]
    Robot(#[from] avatarm_core::sim::arm::RobotError),
    /// A trial's world lost a part it needs (the twin, the loop state) or measured nothing.
    #[error("trial: {message}")]
    Trial {
        /// What is missing.
        message: String,
    },
}

impl From<avatarm_core::Error> for MappingError {
    fn from(e: avatarm_core::Error) -> Self {
        Self::Core(Box::new(e))
    }
}

impl From<avatarm_scene::SceneError> for MappingError {
    fn from(e: avatarm_scene::SceneError) -> Self {
        Self::Task(Box::new(e))
    }
}
