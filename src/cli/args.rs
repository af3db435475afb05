//! What several commands share: the package path, the bundled scenes, the live hand and the
//! value parsers of their flags (errors name the flag or the text given).

use std::path::{Path, PathBuf};

use avatarm_core::robot::PackagePath;
use avatarm_scene::hand::HandChoice;
use avatarm_scene::spec::LeapMountKind;
use avatarm_scene::{Scene, SceneError};

use crate::AppError;

/// The package path for `package://` URIs: the `--package-path` folders, then
/// `ROS_PACKAGE_PATH`'s.
pub(crate) fn packages(dirs: Vec<PathBuf>) -> PackagePath {
    let mut p = PackagePath(dirs);
    if let Ok(env) = std::env::var("ROS_PACKAGE_PATH") {
        p.extend_from_env_list(&env);
    }
    p
}

/// A file shipped in `assets/FOLDER` (`scenes`, `robots`): from the working folder when run
/// from the repository, else from the source tree this binary was built from.
pub(crate) fn bundled(folder: &str, file: &str) -> PathBuf {
    let local = Path::new("assets").join(folder).join(file);
    if local.is_file() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets")
            .join(folder)
            .join(file)
    }
}

/// A scene shipped in `assets/scenes`.
pub(crate) fn bundled_scene(file: &str) -> PathBuf {
    bundled("scenes", file)
}

/// `--leap-mount`: a Leap device's mount, as the scene's `[leap] mount` names it.
pub(crate) fn leap_mount(text: &str) -> Result<LeapMountKind, AppError> {
    text.parse().map_err(|message| AppError::Value {
        text: text.to_owned(),
        message,
    })
}

/// `--mode`: the mapping's mode, `paper` or `closed_loop`.
pub(crate) fn mapping_mode(
    s: &str,
) -> Result<avatarm_core::teleop::mapping::MappingMode, AppError> {
    use avatarm_core::teleop::mapping::MappingMode;
    [MappingMode::Paper, MappingMode::ClosedLoop]
        .into_iter()
        .find(|m| m.name() == s)
        .ok_or_else(|| AppError::Value {
            text: s.to_owned(),
            message: "expected paper or closed_loop".to_owned(),
        })
}

/// `assets/scenes/default.toml`, the scene `avatarm run` opens without one.
pub(crate) fn default_scene() -> PathBuf {
    bundled_scene("default.toml")
}

/// `assets/scenes/pouring.toml`, the task the two-site commands and benches run without a scene.
pub(crate) fn pouring_scene() -> PathBuf {
    bundled_scene("pouring.toml")
}

/// The live hand for `avatarm run`: `--hand`, else the scene's `hand`, else the scripted hand
/// when the scene has a `[task]`; errors name the flag.
pub(crate) fn live_hand(
    scene: &Scene,
    flag: Option<&str>,
    xr: bool,
) -> Result<Option<HandChoice>, AppError> {
    let (text, from) = match (flag, &scene.file.hand) {
        (Some(f), _) => (f.to_owned(), "--hand"),
        (None, Some(h)) => (h.clone(), "hand (scene)"),
        (None, None) if scene.file.task.is_some() => ("scripted".to_owned(), "[task]"),
        (None, None) if scene.file.chess.is_some() => ("scripted".to_owned(), "[chess]"),
        (None, None) => return Ok(None),
    };
    if text == "none" {
        return Ok(None);
    }
    let refuse = |message: String| AppError::flag(from, message);
    let choice: HandChoice = text.parse().map_err(|e| match e {
        SceneError::Field { message, .. } => refuse(message),
        other => refuse(other.to_string()),
    })?;
    if scene.file.task.is_none() && scene.file.chess.is_none() {
        return Err(refuse(format!(
            "the scene '{}' has no [task] or [chess] to teleoperate (try \
             assets/scenes/pouring.toml or assets/scenes/chess.toml)",
            scene.file.name
        )));
    }
    match &choice {
        HandChoice::Xr if !xr => Err(refuse("xr needs XR mode (--xr)".into())),
        HandChoice::Xr if !cfg!(feature = "xr") => Err(refuse(
            "this avatarm was built without the xr feature (it is on by default)".into(),
        )),
        HandChoice::Leap if !cfg!(feature = "leap") => Err(refuse(
            "this avatarm was built without the leap feature; rebuild with `cargo build \
             --features leap` (needs the Ultraleap SDK, docs/hardware.md)"
                .into(),
        )),
        HandChoice::File(path) | HandChoice::LeapRecording { path, .. } if !path.is_file() => {
            Err(refuse(format!("{} does not exist", path.display())))
        }
        _ => Ok(Some(choice)),
    }
}

/// Numbers as they were given on the command line, comma-separated (for error messages).
pub(crate) fn list(v: &[impl std::fmt::Display]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// One `--fit` entry: `FIRST-LAST` frame indices (inclusive, FIRST ≤ LAST) or one index.
pub(crate) fn frame_range(s: &str) -> Result<(usize, usize), AppError> {
    let bad = || AppError::Value {
        text: s.to_owned(),
        message:
            "expected frame indices: FIRST-LAST or one index, comma-separated (e.g. 0-4 or 0,1,5)"
                .into(),
    };
    let index = |t: &str| t.trim().parse::<usize>().map_err(|_| bad());
    let (a, b) = match s.split_once('-') {
        Some((a, b)) => (index(a)?, index(b)?),
        None => (index(s)?, index(s)?),
    };
    if a <= b { Ok((a, b)) } else { Err(bad()) }
}

/// `WIDTHxHEIGHT`, both at least 1 and at most 8192.
pub(crate) fn frame_size(s: &str) -> Result<(u32, u32), AppError> {
    let bad = || AppError::Value {
        text: s.to_owned(),
        message: "expected WIDTHxHEIGHT in pixels, each 1 to 8192 (e.g. 1920x1080)".into(),
    };
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    );
    if (1..=8192).contains(&w) && (1..=8192).contains(&h) {
        Ok((w, h))
    } else {
        Err(bad())
    }
}

/// `--step-ms`: a time step in milliseconds, more than 0 and at most 250 (Bevy clamps a longer
/// update).
pub(crate) fn step_ms(s: &str) -> Result<f64, AppError> {
    let ms: f64 = s.parse().map_err(|_| AppError::Value {
        text: s.to_owned(),
        message: "expected a number of milliseconds".into(),
    })?;
    if ms.is_finite() && ms > 0.0 && ms <= 250.0 {
        Ok(ms)
    } else {
        Err(AppError::Value {
            text: s.to_owned(),
            message: "expected more than 0 and at most 250 ms (a longer step is clamped)".into(),
        })
    }
}
