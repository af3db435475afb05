//! Blair's hand drawn on the real object through a camera on Alice's head: the anchor of each
//! update and how far it moved the hand.

use super::*;

/// Alice's view (the camera looked through rides on a head) while the hand holds the object:
/// the object's twin and the hand are drawn on the real object as the frame on the panel shows
/// it, not where the physics twin is, so the hand holds the bottle Alice sees even while the
/// arm lags the twin or the video is older than the hand. This update's anchor, and what the
/// run measured of it.
#[derive(Resource, Debug, Default)]
pub struct HandAnchor {
    /// This update's anchor: the physics twin mapped into the real world, and the real object
    /// as the panel's frame shows it (both the object's centre frame, real world, m); `None`
    /// when the hand is not drawn on the real object.
    pub now: Option<(Isometry3<f64>, Isometry3<f64>)>,
    /// Updates anchored.
    pub frames: u64,
    /// Per anchored update: how far the anchor moved the twin and the hand (twin to real
    /// object, mm), at most [`Spread::MAX_SAMPLES`].
    pub correction_mm: Vec<f64>,
    /// Per anchored update where the robot is simulated: how far the drawn object is from
    /// where the real object truly was when the panel's frame was captured (mm; the frame
    /// shows it there), at most [`Spread::MAX_SAMPLES`].
    pub error_mm: Vec<f64>,
    /// The simulated real object's true pose after each control tick (robot clock, s),
    /// oldest first, the last [`HandAnchor::TRUTH_S`].
    pub(super) truths: std::collections::VecDeque<(f64, Isometry3<f64>)>,
}

impl HandAnchor {
    /// How long the true poses are kept (s): longer than any frame's age on the panel.
    pub const TRUTH_S: f64 = 2.0;

    /// Keeps the simulated real object's true pose `pose` at robot time `t_s`.
    pub(super) fn record_truth(&mut self, t_s: f64, pose: Isometry3<f64>) {
        if self.truths.back().is_some_and(|&(last, _)| t_s <= last) {
            return;
        }
        self.truths.push_back((t_s, pose));
        while self
            .truths
            .front()
            .is_some_and(|&(t, _)| t < t_s - Self::TRUTH_S)
        {
            self.truths.pop_front();
        }
    }

    /// The true pose at `t_s`: the newest kept at or before it (the simulated room shows the
    /// object where the last control tick put it), `None` outside what is kept.
    pub(super) fn truth_at(&self, t_s: f64) -> Option<Isometry3<f64>> {
        let first = self.truths.front()?.0;
        if t_s < first {
            return None;
        }
        self.truths
            .iter()
            .rev()
            .find(|&&(t, _)| t <= t_s + 1e-9)
            .map(|&(_, pose)| pose)
    }

    /// This update: anchored from `twin` (the physics twin mapped into the real world) onto
    /// `real` (the real object as the frame captured at `capture_s` shows it), or not (`None`).
    pub(super) fn update(
        &mut self,
        anchor: Option<(Isometry3<f64>, Isometry3<f64>)>,
        capture_s: Option<f64>,
    ) {
        self.now = anchor;
        let (Some((_, real)), Some(moved)) = (anchor, self.moved_mm()) else {
            return;
        };
        self.frames += 1;
        Spread::push(&mut self.correction_mm, moved);
        if let Some(truth) = capture_s.and_then(|t| self.truth_at(t)) {
            Spread::push(&mut self.error_mm, apart_mm(&real, &truth));
        }
    }

    /// How far this update's anchor moves the twin and the hand (mm); `None` when not anchored.
    pub fn moved_mm(&self) -> Option<f64> {
        self.now.map(|(twin, real)| apart_mm(&twin, &real))
    }

    /// For the end of a run: the updates anchored, how far the anchor moved the hand, and
    /// (simulation) how far the drawn object was from the real one in the frame; empty when
    /// nothing was anchored.
    pub fn summary(&self) -> String {
        if self.frames == 0 {
            return String::new();
        }
        let spread = |v: &[f64]| {
            let s = Spread::of(v);
            format!("median {:.1} mm, max {:.1} mm", s.median, s.max)
        };
        let truth = if self.error_mm.is_empty() {
            String::new()
        } else {
            format!(
                ", drawn off the real object in the frame {}",
                spread(&self.error_mm)
            )
        };
        format!(
            "; hand on the real object in {} updates (moved from the twin {}{truth})",
            self.frames,
            spread(&self.correction_mm)
        )
    }
}

/// The distance between two poses' origins (m apart, in mm).
pub(super) fn apart_mm(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    1e3 * (a.translation.vector - b.translation.vector).norm()
}

/// Alice's view: whether the camera looked through now rides on a head (the held object's
/// twin and the hand are drawn on the real object as the robot carries it).
pub(super) fn anchored(scene: &crate::SceneResource) -> bool {
    scene.0.head.is_some()
}

/// This update's [`HandAnchor`]: in Alice's view while the hand holds the object, the physics
/// twin mapped into the real world and the real object as the panel's frame shows it.
pub(super) fn anchor_to_real_object(
    teleop: Res<Teleop>,
    held: Res<HeldObject>,
    (history, erase, scene): (
        Res<JointHistory>,
        Res<EraseState>,
        Res<crate::SceneResource>,
    ),
    twin: Query<&Transform, With<GraspTarget>>,
    mut anchor: ResMut<HandAnchor>,
) {
    let now = match twin.single() {
        Ok(t) if anchored(&scene) && held.held.is_some() => {
            object_on_panel(&teleop, &history, &erase)
                .map(|real| (teleop.v2r().pose(&transform_to_iso(t)), real))
        }
        _ => None,
    };
    anchor.update(now, erase.frame_capture_s);
}
