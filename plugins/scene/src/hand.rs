//! Which hand teleoperates a scene's `[task]`: `hand = "..."` in the scene, `--hand` on the
//! command line.

use std::path::PathBuf;
use std::str::FromStr;

use avatarm_core::teleop::hand::Handedness;

use crate::error::SceneError;

/// Where the live hand comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum HandChoice {
    /// The task's scripted hand (trial 0: grasp, lift, pour, raise).
    Scripted,
    /// Keys and mouse in the preview.
    Desktop,
    /// OpenXR hand tracking (needs XR mode).
    Xr,
    /// Leap Motion (feature `leap`).
    Leap,
    /// A recorded `.hand.jsonl` file (docs/hand.md).
    File(PathBuf),
    /// A Leap Motion recording (`.json` or `.json.gz`, Leap's protocol v6 as leapjs-playback
    /// records it), from a device placed as the scene's `[leap]` says
    /// ([`crate::spec::LeapSpec`]); `FILE#left` or `FILE#right` chooses the hand (default: the
    /// first one the recording shows).
    LeapRecording {
        /// The recording.
        path: PathBuf,
        /// The hand to play.
        hand: Option<Handedness>,
    },
}

impl FromStr for HandChoice {
    type Err = SceneError;

    /// `scripted`, `desktop` (or `mouse`), `xr` (or `openxr`), `leap`, a path ending in
    /// `.jsonl` (a recorded skeleton) or in `.json`/`.json.gz` (a Leap recording, optionally
    /// followed by `#left` or `#right`); anything else is a [`SceneError::Field`] on `hand`.
    fn from_str(s: &str) -> Result<Self, SceneError> {
        if let Some((path, hand)) = leap_recording(s) {
            return Ok(Self::LeapRecording {
                path: PathBuf::from(path),
                hand,
            });
        }
        Ok(match s {
            "scripted" => Self::Scripted,
            "desktop" | "mouse" => Self::Desktop,
            "xr" | "openxr" => Self::Xr,
            "leap" => Self::Leap,
            path if path.ends_with(".jsonl") => Self::File(PathBuf::from(path)),
            other => {
                return Err(SceneError::field(
                    "hand",
                    format!(
                        "'{other}': expected scripted, desktop, xr, leap, a .hand.jsonl file or a Leap recording (.json, .json.gz, optionally #left or #right)"
                    ),
                ));
            }
        })
    }
}

/// `PATH.json[.gz]` with an optional `#left` or `#right`: the path and the hand, or `None` when
/// the text is not a Leap recording's.
fn leap_recording(text: &str) -> Option<(&str, Option<Handedness>)> {
    let (path, hand) = match text.rsplit_once('#') {
        Some((path, "left")) => (path, Some(Handedness::Left)),
        Some((path, "right")) => (path, Some(Handedness::Right)),
        Some(_) => return None,
        None => (text, None),
    };
    (path.ends_with(".json") || path.ends_with(".json.gz")).then_some((path, hand))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_names_parse_and_unknown_ones_are_refused_by_name() {
        assert_eq!(
            "mouse".parse::<HandChoice>().ok(),
            Some(HandChoice::Desktop)
        );
        assert_eq!(
            "rec/a.hand.jsonl".parse::<HandChoice>().ok(),
            Some(HandChoice::File("rec/a.hand.jsonl".into()))
        );
        assert_eq!(
            "rec/grab.json.gz".parse::<HandChoice>().ok(),
            Some(HandChoice::LeapRecording {
                path: "rec/grab.json.gz".into(),
                hand: None
            })
        );
        assert_eq!(
            "rec/claps.json#left".parse::<HandChoice>().ok(),
            Some(HandChoice::LeapRecording {
                path: "rec/claps.json".into(),
                hand: Some(Handedness::Left)
            })
        );
        assert!("rec/claps.json#middle".parse::<HandChoice>().is_err());
        let err = "glove".parse::<HandChoice>().expect_err("unknown");
        assert_eq!(
            err.to_string(),
            "hand: 'glove': expected scripted, desktop, xr, leap, a .hand.jsonl file or a Leap recording (.json, .json.gz, optionally #left or #right)"
        );
    }
}
