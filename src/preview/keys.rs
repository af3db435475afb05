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
}
