//! `avatarm run --camera-recording FILE.mcap` without a live task: the recording's robot drives
//! the app's twin (and the room's arm), as the robot site's loop does at `serve`; with a task,
//! the recording's robot is the trial's ([`crate::teleop::TrialLink::Given`]).

use avatarm_core::sim::arm::RobotInterface;
use avatarm_core::sim::recorded::RecordedArm;
use avatarm_sim::{SimRobotState, SimRoomConfig};
use avatarm_twin::JointStateMessage;
use bevy::prelude::*;

use crate::AppTwin;

/// Drives the app's twin from a recording's robot ([`RecordedArm`]), its joint states on the
/// app's clock; the simulated room neither steps nor reports its own arm then.
pub struct RecordedRobotPlugin(pub RecordedArm);

/// The recording's robot.
#[derive(Resource)]
struct RecordedRobot(RecordedArm);

impl Plugin for RecordedRobotPlugin {
    fn build(&self, app: &mut App) {
        if let Some(mut room) = app.world_mut().get_resource_mut::<SimRoomConfig>() {
            room.external_drive = true;
        }
        app.insert_resource(RecordedRobot(self.0.clone()))
            .add_systems(
                Update,
                drive_twin.before(avatarm_erase::EraseSystems::Prepare),
            );
    }
}

/// The states released since the last update into the twin and the room's arm.
fn drive_twin(
    mut arm: ResMut<RecordedRobot>,
    time: Res<Time<Fixed>>,
    twin: Option<Res<AppTwin>>,
    room: Res<SimRoomConfig>,
    mut robot: ResMut<SimRobotState>,
    mut states: MessageWriter<JointStateMessage>,
) {
    arm.0.advance(avatarm_video::app_clock(&time));
    let released = arm.0.receive();
    let Some(last) = released.last() else { return };
    robot.0.place_at(&last.positions, last.stamp_s);
    if let Some(twin) = twin {
        twin.send(&mut states, &room.model, &released, 0.0);
    }
}
