//! Render layers shared by every Avatarm plugin.

/// The simulated room's props and objects, seen by the "real" camera.
pub const ROOM: usize = 0;
/// The app's robot twin in its own colours (preview, overlays).
pub const TWIN: usize = 1;
/// The simulated room's robot, as the real camera sees it.
pub const SIM_ROBOT: usize = 2;
/// Ground truth: the simulated robot in white and everything that can hide it in black.
pub const SIM_SILHOUETTE: usize = 3;
/// Panels and overlays of the desktop preview and XR view.
pub const INTERACTION: usize = 4;
/// The mask twin: the robot in white at the joint state of the frame being erased, and the
/// occluders in black, drawn flat ([`crate::flat`]) by the mask's view alone.
pub const MASK_TWIN: usize = 5;
/// What the headset's eye cameras see in XR mode: the interaction panel and the tracked hands.
pub const XR_PANEL: usize = 8;
