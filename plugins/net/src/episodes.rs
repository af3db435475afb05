//! Refusals told as episodes, so that a peer sending bad messages cannot flood the log: the
//! first refusal of an episode is said at once, the rest are counted and summed up every few
//! seconds while the episode lasts, and its end (no refusal for a while) is said with its count
//! and its kinds. What to log is returned as text; the caller logs it.

use std::collections::BTreeMap;

/// The most kinds an episode's log lines name (the others are counted as `other`).
pub const MAX_KINDS: usize = 8;

/// The most kinds [`RefusalEpisodes::by_kind`] keeps over a whole run (the others are counted
/// as `other`), so a peer sending ever new reasons cannot grow the report without bound.
pub const MAX_REPORT_KINDS: usize = 32;

/// Refusals grouped into episodes ([`RefusalEpisodes::refused`], [`RefusalEpisodes::tick`]).
#[derive(Debug, Clone)]
pub struct RefusalEpisodes {
    quiet_s: f64,
    summary_every_s: f64,
    current: Option<Episode>,
    episodes: u64,
    by_kind: BTreeMap<String, u64>,
}

#[derive(Debug, Clone)]
struct Episode {
    started_s: f64,
    last_s: f64,
    last_summary_s: f64,
    count: u64,
    since_summary: u64,
    kinds: BTreeMap<String, u64>,
}

/// A refusal's kind: its reason with every number as `N`, at most 80 characters, so that
/// `stamped 5.000 s ahead` and `stamped 7.250 s ahead` are one kind.
pub fn kind_of(reason: &str) -> String {
    let mut out = String::new();
    let mut in_number = false;
    for c in reason.chars() {
        if c.is_ascii_digit() || (in_number && matches!(c, '.' | 'e' | '-' | '+')) {
            if !in_number {
                out.push('N');
            }
            in_number = true;
        } else {
            in_number = false;
            out.push(c);
        }
        if out.chars().count() >= 80 {
            break;
        }
    }
    out
}

impl RefusalEpisodes {
    /// Episodes that end after `quiet_s` without a refusal, summed up every `summary_every_s`
    /// (s) while they last.
    pub fn new(quiet_s: f64, summary_every_s: f64) -> Self {
        Self {
            quiet_s,
            summary_every_s,
            current: None,
            episodes: 0,
            by_kind: BTreeMap::new(),
        }
    }

    /// A refusal at `now_s` (s) for `reason`: the line to log when it starts an episode.
    pub fn refused(&mut self, now_s: f64, reason: &str) -> Option<String> {
        let kind = kind_of(reason);
        let known = self.by_kind.len() < MAX_REPORT_KINDS || self.by_kind.contains_key(&kind);
        *self
            .by_kind
            .entry(if known { kind.clone() } else { "other".into() })
            .or_default() += 1;
        match &mut self.current {
            Some(e) => {
                e.count += 1;
                e.since_summary += 1;
                e.last_s = now_s;
                let known = e.kinds.len() < MAX_KINDS || e.kinds.contains_key(&kind);
                *e.kinds
                    .entry(if known { kind } else { "other".into() })
                    .or_default() += 1;
                None
            }
            None => {
                self.episodes += 1;
                self.current = Some(Episode {
                    started_s: now_s,
                    last_s: now_s,
                    last_summary_s: now_s,
                    count: 1,
                    since_summary: 0,
                    kinds: BTreeMap::from([(kind, 1)]),
                });
                Some(format!(
                    "{reason} (refusals are logged once per episode, with a summary every {:.0} s)",
                    self.summary_every_s
                ))
            }
        }
    }

    /// Called often (each control tick) with the time: the summary of the refusals since the
    /// last one while an episode lasts, or the episode's end with its count and kinds.
    pub fn tick(&mut self, now_s: f64) -> Option<String> {
        let e = self.current.as_mut()?;
        if now_s - e.last_s >= self.quiet_s {
            let line = format!(
                "refusals ended: {} in {:.1} s ({})",
                e.count,
                e.last_s - e.started_s,
                kinds(&e.kinds)
            );
            self.current = None;
            return Some(line);
        }
        if now_s - e.last_summary_s >= self.summary_every_s && e.since_summary > 0 {
            let line = format!(
                "{} more refused in the last {:.1} s ({} since {:.1} s ago: {})",
                e.since_summary,
                now_s - e.last_summary_s,
                e.count,
                now_s - e.started_s,
                kinds(&e.kinds)
            );
            e.last_summary_s = now_s;
            e.since_summary = 0;
            return Some(line);
        }
        None
    }

    /// Whether an episode is under way.
    pub fn active(&self) -> bool {
        self.current.is_some()
    }

    /// Episodes so far.
    pub fn episodes(&self) -> u64 {
        self.episodes
    }

    /// Refusals so far by kind ([`kind_of`]).
    pub fn by_kind(&self) -> &BTreeMap<String, u64> {
        &self.by_kind
    }
}

fn kinds(kinds: &BTreeMap<String, u64>) -> String {
    kinds
        .iter()
        .map(|(k, n)| format!("{n}x {k}"))
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peer alternating bad and good targets for 25 s at 20 a second: one line to start the
    /// episode, one summary every 5 s, one at its end; every refusal counted by kind.
    #[test]
    fn a_flood_of_refusals_is_a_few_lines() {
        let mut e = RefusalEpisodes::new(2.0, 5.0);
        let mut lines = Vec::new();
        let mut t = 0.0;
        while t < 25.0 {
            let reason = format!("target refused: stamped {:.3} s ahead", 5.0 + t);
            lines.extend(e.refused(t, &reason));
            lines.extend(e.tick(t));
            t += 0.05;
        }
        while t < 30.0 {
            lines.extend(e.tick(t));
            t += 0.05;
        }
        assert!(lines.len() <= 7, "{lines:#?}");
        assert!(lines[0].contains("stamped 5.000 s ahead"), "{}", lines[0]);
        assert!(
            lines
                .last()
                .is_some_and(|l| l.starts_with("refusals ended: 500 in")),
            "{lines:#?}"
        );
        assert_eq!(e.episodes(), 1);
        assert!(!e.active());
        assert_eq!(
            e.by_kind().get("target refused: stamped N s ahead"),
            Some(&500)
        );
        // A new refusal after the quiet time starts a new episode, said at once.
        assert!(e.refused(40.0, "not finite").is_some());
        assert_eq!(e.episodes(), 2);
    }

    /// A peer sending ever new reasons: the report keeps MAX_REPORT_KINDS by name and counts the
    /// rest as `other`; every refusal is counted.
    #[test]
    fn the_kinds_kept_are_bounded() {
        let mut e = RefusalEpisodes::new(2.0, 5.0);
        let letters = |i: usize| {
            format!(
                "reason {}{}",
                char::from(b'a' + (i / 26) as u8),
                char::from(b'a' + (i % 26) as u8)
            )
        };
        for i in 0..100 {
            e.refused(0.01 * i as f64, &letters(i));
        }
        assert_eq!(e.by_kind().len(), MAX_REPORT_KINDS + 1);
        assert_eq!(e.by_kind().values().sum::<u64>(), 100);
        assert_eq!(
            e.by_kind().get("other"),
            Some(&(100 - MAX_REPORT_KINDS as u64))
        );
    }

    #[test]
    fn numbers_do_not_make_kinds() {
        assert_eq!(kind_of("x 1.5e-3 and -2"), "x N and -N");
        assert_eq!(kind_of("no numbers"), "no numbers");
    }
}
