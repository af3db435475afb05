//! The desktop hand: keys and mouse move and close it.

use super::*;

/// The desktop hand's state: wrist pose (virtual scene), grip, and its start.
#[derive(Resource, Debug, Clone)]
pub struct DesktopHand {
    pub(super) inbox: HandInbox,
    pub(super) start: Isometry3<f64>,
    pub(super) wrist: Isometry3<f64>,
    pub(super) grip: f64,
    pub(super) closing: bool,
}

/// Keys and mouse move the desktop hand (virtual scene; speeds are the hand's, before the
/// mapping's scale). Home puts the hand, open, and the twin (when the hand does not hold it,
/// e.g. knocked over) back at the start.
pub(crate) fn drive_desktop_hand(
    live: Res<LiveTask>,
    held: Res<HeldObject>,
    mut twin: Query<(&mut Transform, &mut Velocity), With<GraspTarget>>,
    controls: DesktopControls,
    time: Res<Time<Real>>,
    fixed: Res<Time<Fixed>>,
    mut hand: ResMut<DesktopHand>,
) {
    let home = hand.step(
        &controls.input(),
        time.delta_secs_f64(),
        fixed.elapsed_secs_f64(),
    );
    if home
        && held.held.is_none()
        && let Ok((mut t, mut v)) = twin.single_mut()
    {
        *t = live.twin_start;
        *v = Velocity::zero();
    }
}

/// The keyboard and mouse a system reads for the desktop hand ([`DesktopControls::input`]).
#[derive(bevy::ecs::system::SystemParam)]
pub(crate) struct DesktopControls<'w> {
    pub(super) keys: Res<'w, ButtonInput<KeyCode>>,
    pub(super) buttons: Res<'w, ButtonInput<MouseButton>>,
    pub(super) motion: Res<'w, AccumulatedMouseMotion>,
    pub(super) scroll: Res<'w, AccumulatedMouseScroll>,
}

impl DesktopControls<'_> {
    /// This update's input.
    pub(crate) fn input(&self) -> DesktopInput<'_> {
        DesktopInput {
            keys: &self.keys,
            buttons: &self.buttons,
            mouse: self.motion.delta,
            scroll: self.scroll.delta.y,
        }
    }
}

/// One update's keys and mouse for the desktop hand.
pub(crate) struct DesktopInput<'a> {
    /// The keyboard.
    pub keys: &'a ButtonInput<KeyCode>,
    /// The mouse buttons.
    pub buttons: &'a ButtonInput<MouseButton>,
    /// The mouse's motion this update (pixels).
    pub mouse: Vec2,
    /// The wheel's vertical scroll this update (lines).
    pub scroll: f32,
}

impl DesktopHand {
    /// The desktop hand at `start` (wrist pose, virtual scene), open.
    pub(crate) fn new(start: Isometry3<f64>) -> Self {
        Self {
            inbox: HandInbox::new("desktop hand"),
            start,
            wrist: start,
            grip: 0.0,
            closing: false,
        }
    }

    /// The hand source its frames go to.
    pub(crate) fn inbox(&self) -> &HandInbox {
        &self.inbox
    }

    /// Moves the hand by one update's `input` over `dt_s` (capped at 0.1 s) and pushes its
    /// skeleton, stamped `t_s` (the hand app's clock), to [`DesktopHand::inbox`]. Returns
    /// whether Home was pressed: the hand went back to the start, open.
    pub(crate) fn step(&mut self, input: &DesktopInput<'_>, dt_s: f64, t_s: f64) -> bool {
        let dt = dt_s.clamp(0.0, 0.1);
        let speed = 0.15;
        let mut step = Vector3::zeros();
        for (key, dir) in [
            (KeyCode::ArrowUp, Vector3::x()),
            (KeyCode::ArrowDown, -Vector3::x()),
            (KeyCode::ArrowLeft, Vector3::y()),
            (KeyCode::ArrowRight, -Vector3::y()),
            (KeyCode::PageUp, Vector3::z()),
            (KeyCode::PageDown, -Vector3::z()),
        ] {
            if input.keys.pressed(key) {
                step += dir * speed * dt;
            }
        }
        if input.buttons.pressed(MouseButton::Left) {
            // 1 mm per pixel; screen right is the scene's -y, screen up its +x (the preview
            // looks along the table).
            let d = input.mouse;
            step += Vector3::new(-f64::from(d.y), -f64::from(d.x), 0.0) * 0.001;
        }
        step.z += f64::from(input.scroll) * 0.01;
        let mut roll = 0.0;
        if input.keys.pressed(KeyCode::KeyZ) {
            roll -= 1.2 * dt;
        }
        if input.keys.pressed(KeyCode::KeyX) {
            roll += 1.2 * dt;
        }
        if input.keys.just_pressed(KeyCode::Space) {
            self.closing = !self.closing;
        }
        let home = input.keys.just_pressed(KeyCode::Home);
        if home {
            self.wrist = self.start;
            self.closing = false;
            self.grip = 0.0;
        }
        self.wrist.translation.vector += step;
        // Tilt about the hand's own forward axis, as one pours.
        let forward = self.wrist.rotation * Vector3::x_axis();
        self.wrist.rotation = UnitQuaternion::from_axis_angle(&forward, roll) * self.wrist.rotation;
        let target = if self.closing { 1.0 } else { 0.0 };
        self.grip += (target - self.grip).clamp(-2.0 * dt, 2.0 * dt);
        self.inbox.push(HandFrame {
            t_s,
            hand: Handedness::Right,
            tracked: true,
            joints: skeleton(&self.wrist, self.grip, Handedness::Right),
        });
        home
    }
}
