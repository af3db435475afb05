//! What the operator's site knows of the robot site beyond its streams: who may command it
//! (its `robot/info`), and when it falls silent, is heard again or restarted (its clock
//! jumped), each said once and counted in the report; a robot site restarted as another (its
//! scene, operators or cameras) ends the session.

use super::*;

/// No status (10 a second) nor joint state for this long: the robot site is silent, said once.
pub const ROBOT_SITE_SILENT: Duration = Duration::from_secs(1);

/// An operator's user must be one of the robot site's operators (none named: no access
/// control); else the error names `--watch`, at once, instead of a session of refused targets.
pub(super) fn may_command(
    options: &JoinOptions,
    info: &avatarm_net::msg::RobotInfo,
) -> Result<(), AppError> {
    if options.watch || info.operators.is_empty() {
        return Ok(());
    }
    let user = options.net.credentials.as_ref().map(|c| c.user.as_str());
    if user.is_some_and(|u| info.operators.iter().any(|o| o == u)) {
        return Ok(());
    }
    Err(AppError::flag(
        "--watch",
        format!(
            "{} may not command the robot site '{}' (its operators: {}): join with --watch to observe, or log in as one of them",
            user.map_or_else(
                || "this site (no --credentials)".to_owned(),
                |u| format!("user '{u}'")
            ),
            options.net.keys.site(),
            info.operators.join(", ")
        ),
    ))
}

impl Collect {
    /// Says once when the robot site falls silent and when it is heard again (then the clock
    /// offset is estimated again at once), and once for each restart the clock's jumps show;
    /// counts both in the report.
    pub(super) fn watch_robot_site(&mut self, site: &OperatorSite, heard: bool) {
        let now = Instant::now();
        if heard {
            if self.silent
                && let Some(last) = self.last_word
            {
                info!(
                    "the robot site is heard again after {:.1} s of silence",
                    (now - last).as_secs_f64()
                );
                site.refresh_offset_soon();
            }
            self.silent = false;
            self.last_word = Some(now);
        } else if !self.silent && self.last_word.is_some_and(|t| now - t > ROBOT_SITE_SILENT) {
            self.silent = true;
            self.report.robot_site_silences += 1;
            warn!(
                "no word from the robot site for {:.1} s (its status comes 10 times a second): a cut link, or the robot site stopped; the robot's own timeouts stop the arm",
                ROBOT_SITE_SILENT.as_secs_f64()
            );
        }
        let clock = site.robot_clock();
        if clock.restarts > self.report.robot_site_restarts {
            self.report.robot_site_restarts = clock.restarts;
            info!(
                "the robot site restarted (its clock jumped by {:+.3} s): clock offset now {:+.3} ms (round trip {:.2} ms)",
                clock.last_jump_s,
                clock.sample.offset_s * 1e3,
                clock.sample.rtt_s * 1e3
            );
            self.changed_site = changed_site(site);
        }
    }
}

/// A restarted robot site that is not the one joined (another scene, protocol or operators),
/// or that does not say: why the session must end; `None` when it is the same.
fn changed_site(site: &OperatorSite) -> Option<String> {
    let first = site.info();
    match site.ask_info(Duration::from_secs(2)) {
        Ok(Some(now))
            if now.scene_hash == first.scene_hash
                && now.operators == first.operators
                && now.cameras == first.cameras =>
        {
            None
        }
        Ok(Some(now)) => Some(format!(
            "the robot site restarted as another: scene '{}' (fingerprint {}), operators [{}], cameras [{}]; joined to '{}' ({}), [{}], [{}]: join it again",
            now.scene,
            now.scene_hash,
            now.operators.join(", "),
            now.cameras.join(", "),
            first.scene,
            first.scene_hash,
            first.operators.join(", "),
            first.cameras.join(", ")
        )),
        Ok(None) => Some(
            "the robot site restarted and did not say who it is (its info within 2 s): join it again"
                .into(),
        ),
        Err(e) => Some(format!("the robot site restarted: {e}")),
    }
}

impl Collect {
    /// The session must end: the window closed, or the robot site restarted as another.
    pub(super) fn closed(&self) -> bool {
        self.changed_site.is_some()
            || self
                .view
                .as_ref()
                .is_some_and(|v| v.closed.load(Ordering::Relaxed))
    }
}
