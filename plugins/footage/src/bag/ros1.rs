//! ROS 1 bags (format 2.0): read by the `rosbag` crate, each connection's type checked by its
//! MD5 sum against the standard message's, each message decoded from ROS 1's serialisation
//! (the fields in order: little-endian numbers, strings and variable arrays behind a u32
//! length) by `roslibrust_serde_rosmsg`.

use std::collections::{BTreeMap, HashMap};

use rosbag::{ChunkRecord, IndexRecord, MessageRecord, RosBag};
use serde::Deserialize;
use serde::de::DeserializeOwned;

use super::assemble::Importer;
use super::messages::Stamped;
use super::{BagOptions, BagSummary, Dialect, MessageTypes, bag_error};
use crate::FootageError;

/// ROS 1's `time`.
#[derive(Deserialize)]
struct Time {
    secs: u32,
    nsecs: u32,
}

/// ROS 1's `std_msgs/Header`.
#[derive(Deserialize)]
pub(super) struct Header {
    _seq: u32,
    stamp: Time,
    frame_id: String,
}

impl Stamped for Header {
    fn stamp_ns(&self, received_ns: u64) -> u64 {
        let ns = u64::from(self.stamp.secs) * 1_000_000_000 + u64::from(self.stamp.nsecs);
        if ns == 0 { received_ns } else { ns }
    }

    fn frame_id(&self) -> &str {
        &self.frame_id
    }
}

/// ROS 1's serialisation.
pub(super) struct Ros1;

impl Dialect for Ros1 {
    type Header = Header;
    const TYPES: MessageTypes = MessageTypes {
        image: "sensor_msgs/Image",
        compressed: "sensor_msgs/CompressedImage",
        camera_info: "sensor_msgs/CameraInfo",
        joint_state: "sensor_msgs/JointState",
        tf: "tf2_msgs/TFMessage",
    };

    fn decode<T: DeserializeOwned>(data: &[u8]) -> Result<T, String> {
        roslibrust_serde_rosmsg::from_slice_known_length(data, data.len() as u32)
            .map_err(|e| e.to_string())
    }
}

/// The standard messages' MD5 sums (`rosmsg md5`), which a connection of their type must have.
const MD5: [(&str, &str); 5] = [
    ("sensor_msgs/Image", "060021388200f6f0f447d0fcd9c64743"),
    (
        "sensor_msgs/CompressedImage",
        "8f7a12909da2c9d3332d540a0977563f",
    ),
    ("sensor_msgs/CameraInfo", "c9a58c1b0b154e0e6da7578cb991d214"),
    ("sensor_msgs/JointState", "3066dcd76a6cfaef579bd0f34173e9fd"),
    ("tf2_msgs/TFMessage", "94810edda583a504dfda3829e70d7eec"),
];

/// One connection (a topic as one publisher recorded it).
struct Connection {
    topic: String,
    kind: String,
    md5: String,
}

/// Imports a ROS 1 bag (see [`super::import_bag`]).
pub(super) fn import(o: &BagOptions) -> Result<BagSummary, FootageError> {
    let path = &o.bag;
    let bag = RosBag::new(path)
        .map_err(|e| bag_error(path, format!("not a ROS 1 bag (format 2.0), or one never closed (`rosbag reindex` repairs that): {e}")))?;
    let mut connections: HashMap<u32, Connection> = HashMap::new();
    for record in bag.index_records() {
        if let IndexRecord::Connection(c) =
            record.map_err(|e| bag_error(path, format!("its index: {e}")))?
        {
            connections.insert(
                c.id,
                Connection {
                    topic: c.topic.to_owned(),
                    kind: c.tp.to_owned(),
                    md5: c.md5sum.iter().map(|b| format!("{b:02x}")).collect(),
                },
            );
        }
    }
    let mut topics: BTreeMap<String, String> = BTreeMap::new();
    for c in connections.values() {
        for (kind, md5) in MD5 {
            if c.kind == kind && c.md5 != md5 {
                return Err(bag_error(
                    path,
                    format!(
                        "{}: {} with MD5 sum {}, not the standard message's {md5}",
                        c.topic, c.kind, c.md5
                    ),
                ));
            }
        }
        topics.insert(c.topic.clone(), c.kind.clone());
    }
    let mut importer = Importer::<Ros1>::new(o, "ROS 1 bag", topics)?;
    for record in bag.chunk_records() {
        let ChunkRecord::Chunk(chunk) =
            record.map_err(|e| bag_error(path, format!("a chunk: {e}")))?
        else {
            continue;
        };
        for m in chunk.messages() {
            let MessageRecord::MessageData(m) =
                m.map_err(|e| bag_error(path, format!("a chunk's message: {e}")))?
            else {
                continue;
            };
            let Some(c) = connections.get(&m.conn_id) else {
                return Err(bag_error(
                    path,
                    format!(
                        "a message on connection {} that the index does not list",
                        m.conn_id
                    ),
                ));
            };
            importer.message(&c.topic, m.data, m.time)?;
        }
    }
    importer.finish()
}
