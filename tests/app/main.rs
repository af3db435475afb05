//! The app's integration tests, in one binary (Bevy is linked once): scripted scene replays
//! rendered for real (software Vulkan is enough), the command line and the preview
//! ([`replay`]), and footage and bags imported and replayed ([`footage`]). The real-time
//! two-site tests and XR are the `realtime` binary's: they need the machine to themselves.

#[path = "../support/mod.rs"]
mod support;

mod footage;
mod replay;
