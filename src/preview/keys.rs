//! The preview's keys: one list, shown on screen, in `avatarm run --help` and in the README (a
//! test checks that the README lists every key with its action).

/// The preview's keys and what each does.
pub const PREVIEW_KEYS: [(&str, &str); 9] = [
    (
        "V",
        "cycles the panel (interaction view, camera feed, mask)",
    ),
    ("C", "switches to the next camera"),
    ("E", "switches erasure on and off"),
    ("M", "tints the mask over the panel"),
    ("W", "draws the twin as a wireframe"),
    ("B", "captures the background from the live frame"),
    ("R", "re-centres the panel in the headset (XR)"),
    ("F12", "saves a screenshot"),
    ("Esc", "quits"),
];

/// The desktop hand's keys (`--hand desktop`) and what each does.
pub const DESKTOP_HAND_KEYS: [(&str, &str); 5] = [
    ("arrows or left-drag", "move the hand"),
    ("PgUp/PgDn or the wheel", "raise and lower it"),
    ("Space", "closes and opens it"),
    ("Z/X", "tilt it (pour)"),
    ("Home", "puts it (and a dropped twin) back at the start"),
];

/// A scripted key press, `N:KEY` (`--press`): rendered frame N (from 1) and one of
/// [`PREVIEW_KEYS`] (a letter in either case, `F12`, `Esc`). Errors name the text and what is
/// expected.
pub fn parse_press(text: &str) -> Result<(u32, bevy::input::keyboard::KeyCode), crate::AppError> {
    use bevy::input::keyboard::KeyCode;
    let keys = || PREVIEW_KEYS.map(|(k, _)| k).join(", ");
    let bad = |message: String| crate::AppError::Value {
        text: text.to_owned(),
        message,
    };
    let Some((frame, key)) = text.split_once(':') else {
        return Err(bad(format!(
            "expected N:KEY, N a frame from 1 and KEY one of {}",
            keys()
        )));
    };
    let frame = match frame.trim().parse::<u32>() {
        Ok(n) if n > 0 => n,
        _ => {
            return Err(bad(format!(
                "the frame '{frame}' is not a whole number from 1 (N:KEY)"
            )));
        }
    };
    let code = match key.trim().to_ascii_uppercase().as_str() {
        "V" => KeyCode::KeyV,
        "C" => KeyCode::KeyC,
        "E" => KeyCode::KeyE,
        "M" => KeyCode::KeyM,
        "W" => KeyCode::KeyW,
        "B" => KeyCode::KeyB,
        "R" => KeyCode::KeyR,
        "F12" => KeyCode::F12,
        "ESC" => KeyCode::Escape,
        _ => {
            return Err(bad(format!(
                "the key '{key}' is not one of the preview's: {} (N:KEY, either case)",
                keys()
            )));
        }
    };
    Ok((frame, code))
}

/// `keys` as one line: `V: cycles the panel (...), E: ...`.
pub fn line(keys: &[(&str, &str)]) -> String {
    keys.iter()
        .map(|(k, action)| format!("{k}: {action}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `keys` as lines of `per_line` entries, for the on-screen help.
pub fn lines(keys: &[(&str, &str)], per_line: usize) -> String {
    keys.chunks(per_line.max(1))
        .map(line)
        .collect::<Vec<_>>()
        .join("\n")
}

/// The keys as `avatarm run --help` shows them.
pub fn help() -> String {
    format!(
        "Keys: {}.\nDesktop hand (--hand desktop): {}.",
        line(&PREVIEW_KEYS),
        line(&DESKTOP_HAND_KEYS)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The README lists every key with its action, as `**KEY** action` (one sentence may wrap
    /// across lines).
    #[test]
    fn the_readme_lists_every_key() {
        let readme = include_str!("../../README.md");
        let flat = readme.split_whitespace().collect::<Vec<_>>().join(" ");
        for (key, action) in PREVIEW_KEYS.iter().chain(&DESKTOP_HAND_KEYS) {
            let entry = format!("**{key}** {action}");
            assert!(flat.contains(&entry), "README.md does not say '{entry}'");
        }
        let help = help();
        assert!(help.contains("V: cycles the panel") && help.contains("Home: puts it"));
    }

    /// Every preview key can be scripted with `--press`, in either case; bad text is refused
    /// naming it.
    #[test]
    fn every_preview_key_can_be_pressed_by_script() {
        for (key, _) in PREVIEW_KEYS {
            assert!(parse_press(&format!("3:{key}")).is_ok(), "{key}");
            assert!(
                parse_press(&format!("3:{}", key.to_lowercase())).is_ok(),
                "{key}"
            );
        }
        assert_eq!(
            parse_press("60:c").ok(),
            Some((60, bevy::input::keyboard::KeyCode::KeyC))
        );
        for (bad, what) in [
            ("60", "expected N:KEY"),
            ("0:C", "the frame '0'"),
            ("x:C", "the frame 'x'"),
            ("-1:C", "the frame '-1'"),
            ("60:Q", "the key 'Q'"),
        ] {
            let e = parse_press(bad).expect_err(bad).to_string();
            assert!(
                e.contains(&format!("'{bad}'")) && e.contains(what) && e.contains("N:KEY"),
                "{e}"
            );
        }
    }
}
