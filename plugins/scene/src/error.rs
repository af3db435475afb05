//! The crate's one error type: every variant names the scene file (where there is one) and the
//! field at fault.

use std::path::PathBuf;

/// What can go wrong loading a scene or checking one of its parts.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: cannot read scene: {source}")]
    Io {
        /// The scene file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Not valid TOML, or a field of the wrong type, or an unknown field.
    #[error("{path}: {}", .source.to_string().trim_end())]
    Parse {
        /// The scene file.
        path: PathBuf,
        /// The parser's error (with line and column).
        source: toml::de::Error,
    },
    /// A field's value is not usable.
    #[error("{path}: {field}: {message}")]
    Invalid {
        /// The scene file.
        path: PathBuf,
        /// The field, dotted (`camera.intrinsics.fx`, `camera.pose.eye[2]`).
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A field whose value the core refused (an unknown joint or link, impossible intrinsics,
    /// a setting out of range); the core's error is the cause.
    #[error("{path}: {field}: {source}")]
    Value {
        /// The scene file.
        path: PathBuf,
        /// The field, dotted.
        field: String,
        /// The core's error.
        source: Box<avatarm_core::Error>,
    },
    /// As [`SceneError::Value`], for a part of a scene checked on its own (no file).
    #[error("{field}: {source}")]
    FieldValue {
        /// The field, dotted.
        field: String,
        /// The core's error.
        source: Box<avatarm_core::Error>,
    },
    /// The robot description failed to load.
    #[error("{path}: robot.urdf: {source}")]
    Robot {
        /// The scene file.
        path: PathBuf,
        /// Why.
        source: Box<avatarm_core::Error>,
    },
    /// A part of a scene checked on its own (a `[task]` built in code, a hand name from the
    /// command line): the field and what is wrong with it.
    #[error("{field}: {message}")]
    Field {
        /// The field, dotted (`task.mass_kg`).
        field: String,
        /// What is wrong.
        message: String,
    },
}

impl SceneError {
    /// A [`SceneError::FieldValue`]: the core refused the value of `field`.
    pub fn value(field: impl Into<String>, source: avatarm_core::Error) -> Self {
        Self::FieldValue {
            field: field.into(),
            source: Box::new(source),
        }
    }

    /// The dotted field at fault, where the error names one.
    pub fn field_name(&self) -> Option<&str> {
        match self {
            Self::Invalid { field, .. }
            | Self::Value { field, .. }
            | Self::Field { field, .. }
            | Self::FieldValue { field, .. } => Some(field),
            Self::Io { .. } | Self::Parse { .. } | Self::Robot { .. } => None,
        }
    }

    /// This error with its field renamed from under `from` to under `to` (`camera.fps` to
    /// `cameras[1] (alice).fps`); errors about other fields are returned as they are.
    pub fn with_field_prefix(mut self, from: &str, to: &str) -> Self {
        if let Self::Invalid { field, .. }
        | Self::Value { field, .. }
        | Self::Field { field, .. }
        | Self::FieldValue { field, .. } = &mut self
            && let Some(rest) = field.strip_prefix(from)
            && (rest.is_empty() || rest.starts_with('.') || rest.starts_with('['))
        {
            *field = format!("{to}{rest}");
        }
        self
    }

    /// A [`SceneError::Field`].
    pub fn field(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Field {
            field: field.into(),
            message: message.into(),
        }
    }

    /// This error placed in the scene file `path`: a [`SceneError::Field`] becomes
    /// [`SceneError::Invalid`], a [`SceneError::FieldValue`] [`SceneError::Value`]; the others
    /// already name their file.
    pub fn in_file(self, path: &std::path::Path) -> Self {
        match self {
            Self::Field { field, message } => Self::Invalid {
                path: path.to_owned(),
                field,
                message,
            },
            Self::FieldValue { field, source } => Self::Value {
                path: path.to_owned(),
                field,
                source,
            },
            other => other,
        }
    }
}

/// Result with [`SceneError`].
pub type Result<T, E = SceneError> = std::result::Result<T, E>;
