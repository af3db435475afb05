//! The core's one error type. Every variant names the file, element or value at fault.

use std::path::PathBuf;

impl Error {
    /// An [`Error::GraspNotFinite`].
    pub fn grasp_not_finite(what: &'static str) -> Self {
        Self::GraspNotFinite { what }
    }
}

/// Result with the core's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What can go wrong when loading a robot, a mesh or a joint vector.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The URDF is not well-formed XML or does not follow the URDF schema.
    #[error("{origin}: malformed URDF: {message}")]
    MalformedUrdf {
        /// The file (or `<string>`).
        origin: String,
        /// What the parser reported, with line and column where known.
        message: String,
    },
    /// A `<joint>` has a type Avatarm does not model.
    #[error(
        "{origin}:{line}: joint '{joint}' has type '{kind}'; expected one of revolute, continuous, prismatic, fixed, floating, planar"
    )]
    UnknownJointType {
        /// The file.
        origin: String,
        /// 1-based line of the `<joint>` element.
        line: u32,
        /// The joint's name.
        joint: String,
        /// The type found.
        kind: String,
    },
    /// A joint's numbers make no sense (zero axis, NaN, lower > upper, ...).
    #[error("{origin}: joint '{joint}': {message}")]
    BadJoint {
        /// The file.
        origin: String,
        /// The joint's name.
        joint: String,
        /// What is wrong.
        message: String,
    },
    /// A joint names a link that does not exist.
    #[error("{origin}: joint '{joint}' names {role} link '{link}', which is not defined")]
    UnknownLink {
        /// The file.
        origin: String,
        /// The joint's name.
        joint: String,
        /// `parent` or `child`.
        role: &'static str,
        /// The missing link's name.
        link: String,
    },
    /// Two elements share a name.
    #[error("{origin}: two {element} elements are named '{name}'")]
    DuplicateName {
        /// The file.
        origin: String,
        /// `link` or `joint`.
        element: &'static str,
        /// The repeated name.
        name: String,
    },
    /// A link is the child of two joints, or the joints form a cycle: a URDF must be a tree.
    #[error("{origin}: the joints form a loop at link '{link}' ({detail}); a URDF must be a tree")]
    Loop {
        /// The file.
        origin: String,
        /// A link on the loop.
        link: String,
        /// Which joints close it.
        detail: String,
    },
    /// More than one link has no parent joint.
    #[error(
        "{origin}: {count} root links ({roots}); a URDF needs exactly one link that is no joint's child"
    )]
    SeveralRoots {
        /// The file.
        origin: String,
        /// How many.
        count: usize,
        /// Their names, comma separated.
        roots: String,
    },
    /// The URDF has no links at all.
    #[error("{origin}: the robot has no <link> elements")]
    NoLinks {
        /// The file.
        origin: String,
    },
    /// A `package://NAME/...` URI names a package that is not on the search path.
    #[error("{origin}: link '{link}': mesh '{uri}': {why}")]
    UnknownPackage {
        /// The file.
        origin: String,
        /// The link whose geometry names it.
        link: String,
        /// The URI as written.
        uri: String,
        /// The package name.
        package: String,
        /// Where it was looked for, and what to do ([`crate::robot::PackagePath::not_found`]).
        why: String,
    },
    /// A mesh URI resolves to a file that does not exist.
    #[error("{origin}: link '{link}': mesh '{uri}' resolves to {resolved}, which does not exist")]
    MissingMesh {
        /// The file.
        origin: String,
        /// The link whose geometry names it.
        link: String,
        /// The URI as written.
        uri: String,
        /// Where it was looked for.
        resolved: PathBuf,
    },
    /// A link's `<visual>` or `<collision>` geometry makes no sense (a mesh scale of 0 or not
    /// finite, a negative radius, ...).
    #[error("{origin}: link '{link}': {message}")]
    BadGeometry {
        /// The file.
        origin: String,
        /// The link.
        link: String,
        /// What is wrong.
        message: String,
    },
    /// A link's mesh could not be loaded.
    #[error("link '{link}': mesh '{uri}': {source}")]
    LinkMesh {
        /// The link.
        link: String,
        /// The URI as written in the URDF.
        uri: String,
        /// Why (names the resolved file).
        source: Box<Error>,
    },
    /// A value was given for a `<mimic>` joint, which follows its leader.
    #[error(
        "joint '{name}' is a mimic joint (it follows '{leader}'); give a value for '{leader}' instead"
    )]
    MimicJoint {
        /// The mimic joint.
        name: String,
        /// The joint it follows.
        leader: String,
    },
    /// A mesh URI uses a scheme other than relative paths, `file://` and `package://`.
    #[error(
        "{origin}: link '{link}': mesh '{uri}' uses an unsupported URI scheme; use a relative path, file:// or package://"
    )]
    UnsupportedUri {
        /// The file.
        origin: String,
        /// The link whose geometry names it.
        link: String,
        /// The URI as written.
        uri: String,
    },
    /// A mesh file's format is not one Avatarm loads.
    #[error(
        "{path}: mesh format '.{extension}' is not supported (STL, OBJ, Collada .dae, glTF and GLB are, in any letter case); convert it (e.g. `assimp export {stem}.{extension} {stem}.glb`, or Blender's glTF exporter) or point the link's <visual> at its collision mesh"
    )]
    UnsupportedMesh {
        /// The mesh file.
        path: PathBuf,
        /// Its extension.
        extension: String,
        /// Its file stem, for the suggested command.
        stem: String,
    },
    /// A mesh file could not be parsed.
    #[error("{path}: cannot load mesh: {message}")]
    BadMesh {
        /// The mesh file.
        path: PathBuf,
        /// What the parser reported.
        message: String,
    },
    /// A joint name that the robot does not have.
    #[error("unknown joint '{name}'; movable joints are: {known}")]
    UnknownJoint {
        /// The name given.
        name: String,
        /// The robot's movable joints, comma separated.
        known: String,
    },
    /// A link name that the robot does not have.
    #[error("unknown link '{name}'")]
    UnknownLinkName {
        /// The name given.
        name: String,
    },
    /// A joint vector of the wrong length.
    #[error("expected {expected} joint values (one per movable joint), got {got}")]
    JointCount {
        /// Movable joints of the robot.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A NaN or infinite value where a finite number is needed.
    #[error("{what}: value {value} is not finite")]
    NonFinite {
        /// Which value.
        what: String,
        /// The value.
        value: f64,
    },
    /// A text value that is not a number.
    #[error("{what}: '{text}' is not a number")]
    NotANumber {
        /// Which value.
        what: String,
        /// The text.
        text: String,
    },
    /// A camera with impossible intrinsics.
    #[error("camera intrinsics: {message}")]
    BadIntrinsics {
        /// What is wrong.
        message: String,
    },
    /// An image or pixel map of the wrong size or format.
    #[error("{what}: {message}")]
    BadImage {
        /// Which image.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A line of a hand recording (`.hand.jsonl`) that is not a valid frame record.
    #[error("line {line}: {source}")]
    HandRecordLine {
        /// 1-based line.
        line: usize,
        /// The JSON parser's error.
        source: serde_json::Error,
    },
    /// A hand frame that cannot be used: a joint with a zero-length orientation, a non-finite
    /// pose, the wrong joint count, time going back.
    #[error("{}{}{message}", .line.map(|n| format!("line {n}: ")).unwrap_or_default(), .joint.map(|j| format!("joint {j}: ")).unwrap_or_default())]
    BadHandFrame {
        /// 1-based line in a recording, when the frame came from one.
        line: Option<usize>,
        /// The joint at fault (an OpenXR hand joint name), when one is.
        joint: Option<&'static str>,
        /// What is wrong.
        message: String,
    },
    /// An input of the control tick that cannot be used (the caller stops the robot).
    #[error("control tick: {message}")]
    BadTickInput {
        /// What is wrong.
        message: String,
    },
    /// Inverse kinematics did not reach the target pose.
    #[error("IK: {message}")]
    Ik {
        /// Why, with the error left.
        message: String,
    },
    /// A grasp with no contacts.
    #[error("grasp: no contacts")]
    NoContacts,
    /// A NaN or infinite number in a grasp's input.
    #[error("grasp: {what} is not finite")]
    GraspNotFinite {
        /// Which input.
        what: &'static str,
    },
    /// A grasp's inputs whose sizes do not agree.
    #[error("grasp: {what}: expected {expected} values, got {got}")]
    GraspSize {
        /// Which input.
        what: &'static str,
        /// Expected count.
        expected: usize,
        /// Given count.
        got: usize,
    },
    /// A setting out of its range.
    #[error("{what}: {message}")]
    BadSetting {
        /// Where the setting came from.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// A recorded timeline that cannot be played: empty, stamps not finite or not increasing,
    /// samples of different sizes.
    #[error("{what}: {message}")]
    BadTimeline {
        /// Which timeline (the recording and the stream).
        what: String,
        /// What is wrong, naming the sample.
        message: String,
    },
}
