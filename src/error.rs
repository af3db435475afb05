//! The app's one error type: each layer's error is wrapped, not flattened into text.

use std::path::PathBuf;

/// What can go wrong running Avatarm's commands.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    /// A scene that does not load.
    #[error(transparent)]
    Scene(Box<avatarm_scene::SceneError>),
    /// A robot description, mesh, joint vector or setting the core refused.
    #[error(transparent)]
    Core(Box<avatarm_core::Error>),
    /// The teleoperation loop or the pouring task could not be set up or run.
    #[error(transparent)]
    Mapping(Box<avatarm_mapping::MappingError>),
    /// A hand source could not be set up (a recording that cannot be read, a device).
    #[error(transparent)]
    Hand(Box<avatarm_hand::HandError>),
    /// A session recording that could not be written or read.
    #[error(transparent)]
    Record(Box<avatarm_record::RecordError>),
    /// A camera file (intrinsics, distortion, pose) that could not be used.
    #[error(transparent)]
    CameraFile(Box<avatarm_record::CameraFileError>),
    /// Footage or a bag that could not be imported, or a recording that could not be calibrated.
    #[error(transparent)]
    Footage(Box<avatarm_footage::FootageError>),
    /// A two-site session that could not be set up or was refused.
    #[error(transparent)]
    Net(Box<avatarm_net::NetError>),
    /// A command-line flag (or the scene field it stands for) with a value that cannot be used.
    #[error("{flag}: {message}")]
    Flag {
        /// The flag (`--hand`) or field (`hand (scene)`).
        flag: String,
        /// What is wrong.
        message: String,
    },
    /// A value given on the command line that cannot be used (clap names the flag around it).
    #[error("'{text}': {message}")]
    Value {
        /// The text given.
        text: String,
        /// What was expected.
        message: String,
    },
    /// The live teleoperation of the scene's `[task]` could not be set up.
    #[error("live teleoperation: {source} (--hand none runs the preview without it)")]
    Teleop {
        /// Why.
        source: Box<AppError>,
    },
    /// A file or folder that could not be read, written or created.
    #[error("{path}: cannot {action}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// `read`, `write`, `create`.
        action: &'static str,
        /// Why.
        source: std::io::Error,
    },
    /// An image file that could not be read or written.
    #[error("{path}: cannot {action} image: {source}")]
    Image {
        /// The file.
        path: PathBuf,
        /// `read` or `write`.
        action: &'static str,
        /// The image library's error.
        source: image::ImageError,
    },
    /// An image buffer whose size does not match its width and height.
    #[error("{what}: the buffer does not hold a {width}x{height} image")]
    ImageSize {
        /// Which image.
        what: String,
        /// Width (px).
        width: u32,
        /// Height (px).
        height: u32,
    },
    /// A report or table that could not be serialised.
    #[error("report: {0}")]
    Json(#[from] serde_json::Error),
    /// A chart that could not be drawn.
    #[error("chart {what}: {source}")]
    Chart {
        /// The chart's file or part.
        what: String,
        /// The drawing library's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// No font to draw a chart's text with.
    #[error(
        "no font for the chart's text: install fonts-dejavu-core (looked for {searched}) or set AVATARM_FONT to a .ttf file"
    )]
    NoFont {
        /// The files looked for.
        searched: String,
    },
    /// A command that did not finish or measured something wrong: the command (`replay`,
    /// `serve`, `bench gpu`, ...) and what.
    #[error("{command}: {message}")]
    Command {
        /// The command, as typed after `avatarm`.
        command: &'static str,
        /// What went wrong.
        message: String,
    },
    /// A recording (or a file of frames) whose content cannot be used: the file and what.
    #[error("{file}: {message}")]
    Recording {
        /// The recording's path, as given.
        file: String,
        /// What is wrong in it.
        message: String,
    },
    /// A bench setting that could not run.
    #[error("bench setting '{label}': {source}")]
    BenchSetting {
        /// The setting's label.
        label: String,
        /// Why.
        source: Box<AppError>,
    },
    /// `avatarm run` or `avatarm join --window` opens a window, and there is no display to
    /// open it on.
    #[error(
        "this command opens a window and there is no display (DISPLAY and WAYLAND_DISPLAY are \
         unset): run it in a desktop session or under `xvfb-run -a`; headless instead, replay \
         the scene with `avatarm replay SCENE --headless --out DIR`, or join without --window"
    )]
    NoDisplay,
    /// The two-site session (`avatarm join`) stopped.
    #[error("the session: {message}")]
    Session {
        /// What happened.
        message: String,
    },
    /// The desktop preview or the XR view stopped with an error (logged above it).
    #[error("the preview stopped with an error (see the log above)")]
    Preview,
}

impl AppError {
    /// An [`AppError::Flag`].
    pub fn flag(flag: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Flag {
            flag: flag.into(),
            message: message.into(),
        }
    }

    /// An [`AppError::Io`] for writing `path`.
    pub fn write(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            action: "write",
            source,
        }
    }

    /// An [`AppError::Image`] for writing the image at `path`.
    pub fn write_image(path: impl Into<PathBuf>, source: image::ImageError) -> Self {
        Self::Image {
            path: path.into(),
            action: "write",
            source,
        }
    }

    /// An [`AppError::Command`] of `command` (as typed after `avatarm`).
    pub fn command(command: &'static str, message: impl Into<String>) -> Self {
        Self::Command {
            command,
            message: message.into(),
        }
    }

    /// An [`AppError::Recording`] of the recording `file`.
    pub fn recording(file: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Recording {
            file: file.into(),
            message: message.into(),
        }
    }
}

/// Result with [`AppError`].
pub type Result<T, E = AppError> = std::result::Result<T, E>;

impl From<avatarm_footage::FootageError> for AppError {
    fn from(e: avatarm_footage::FootageError) -> Self {
        Self::Footage(Box::new(e))
    }
}

impl From<avatarm_scene::SceneError> for AppError {
    fn from(e: avatarm_scene::SceneError) -> Self {
        Self::Scene(Box::new(e))
    }
}

impl From<avatarm_core::Error> for AppError {
    fn from(e: avatarm_core::Error) -> Self {
        Self::Core(Box::new(e))
    }
}

impl From<avatarm_mapping::MappingError> for AppError {
    fn from(e: avatarm_mapping::MappingError) -> Self {
        Self::Mapping(Box::new(e))
    }
}

impl From<avatarm_hand::HandError> for AppError {
    fn from(e: avatarm_hand::HandError) -> Self {
        Self::Hand(Box::new(e))
    }
}

impl From<avatarm_record::RecordError> for AppError {
    fn from(e: avatarm_record::RecordError) -> Self {
        Self::Record(Box::new(e))
    }
}

impl From<avatarm_record::CameraFileError> for AppError {
    fn from(e: avatarm_record::CameraFileError) -> Self {
        Self::CameraFile(Box::new(e))
    }
}

impl From<avatarm_net::NetError> for AppError {
    fn from(e: avatarm_net::NetError) -> Self {
        Self::Net(Box::new(e))
    }
}
