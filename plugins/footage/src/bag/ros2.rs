//! rosbag2 (ROS 2's bags): a folder with `metadata.yaml` (rosbag2's own description: its
//! storage, its files, their compression) or one storage file, read as:
//! - MCAP (`mcap`, the default storage since Iron) by the `mcap` crate, chunks uncompressed,
//!   zstd or lz4 (rosbag2's `compression_mode: storage` is MCAP's chunk compression);
//! - SQLite (`sqlite3`, Humble's default; tables `topics` and `messages`) by `rusqlite`, on
//!   the system's SQLite, opened read-only;
//! - with `compression_mode: file` (each storage file zstd-compressed whole, `.mcap.zstd`) or
//!   `message` (each message's bytes zstd-compressed), decompressed by the `zstd` crate.
//!
//! Each message is CDR (the OMG's Common Data Representation, version 1 as ROS 2's `rmw`
//! layers write it: a 4-byte encapsulation header, `00 01` for little-endian or `00 00` for
//! big-endian, then the fields aligned to their size from the header's end), decoded by
//! `cdr-encoding` (RustDDS's). A message that leaves more than its alignment's padding unread
//! is refused as not the standard message's layout.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use byteorder::{BigEndian, LittleEndian};
use serde::Deserialize;
use serde::de::DeserializeOwned;
use yaml_rust2::{Yaml, YamlLoader};

use super::assemble::Importer;
use super::messages::Stamped;
use super::{BagOptions, BagSummary, Dialect, MessageTypes, bag_error};
use crate::FootageError;

/// `builtin_interfaces/msg/Time`.
#[derive(Deserialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

/// ROS 2's `std_msgs/msg/Header`.
#[derive(Deserialize)]
pub(super) struct Header {
    stamp: Time,
    frame_id: String,
}

impl Stamped for Header {
    fn stamp_ns(&self, received_ns: u64) -> u64 {
        let Ok(sec) = u64::try_from(self.stamp.sec) else {
            return received_ns;
        };
        let ns = sec * 1_000_000_000 + u64::from(self.stamp.nanosec);
        if ns == 0 { received_ns } else { ns }
    }

    fn frame_id(&self) -> &str {
        &self.frame_id
    }
}

/// ROS 2's CDR.
pub(super) struct Ros2;

/// The most bytes a CDR message may leave unread: padding to its 8-byte alignment.
const MAX_PADDING: usize = 7;

impl Dialect for Ros2 {
    type Header = Header;
    const TYPES: MessageTypes = MessageTypes {
        image: "sensor_msgs/msg/Image",
        compressed: "sensor_msgs/msg/CompressedImage",
        camera_info: "sensor_msgs/msg/CameraInfo",
        joint_state: "sensor_msgs/msg/JointState",
        tf: "tf2_msgs/msg/TFMessage",
    };

    fn decode<T: DeserializeOwned>(data: &[u8]) -> Result<T, String> {
        let Some((header, body)) = data.split_first_chunk::<4>() else {
            return Err(format!(
                "{} bytes, shorter than CDR's 4-byte encapsulation header",
                data.len()
            ));
        };
        let (value, used) = match [header[0], header[1]] {
            [0, 1] => cdr_encoding::from_bytes::<T, LittleEndian>(body),
            [0, 0] => cdr_encoding::from_bytes::<T, BigEndian>(body),
            [0x28, 0xb5] if header[2..] == [0x2f, 0xfd] => {
                return Err(
                    "a zstd-compressed message (a bag recorded with compression_mode: message): give the bag's folder, whose metadata.yaml says so".into(),
                );
            }
            id => {
                return Err(format!(
                    "encapsulation {:02x}{:02x}, not plain CDR (0001 little-endian, 0000 big-endian)",
                    id[0], id[1]
                ));
            }
        }
        .map_err(|e| e.to_string())?;
        let left = body.len() - used;
        if left > MAX_PADDING {
            return Err(format!(
                "{left} of its {} bytes left over: not the standard message's layout",
                data.len()
            ));
        }
        Ok(value)
    }
}

/// A storage plugin's files.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Storage {
    Mcap,
    Sqlite,
}

/// How rosbag2 compressed the bag (`compression_format: zstd`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Compression {
    /// Uncompressed, or MCAP's own chunk compression (`compression_mode: storage`).
    None,
    /// Each storage file whole.
    File,
    /// Each message's bytes.
    Message,
}

/// What to read: the storage files in order.
struct Layout {
    storage: Storage,
    compression: Compression,
    files: Vec<PathBuf>,
}

fn storage_of(path: &Path) -> Option<Storage> {
    let name = path.file_name()?.to_str()?.to_ascii_lowercase();
    let name = name.strip_suffix(".zstd").unwrap_or(&name);
    if name.ends_with(".mcap") {
        Some(Storage::Mcap)
    } else if name.ends_with(".db3") {
        Some(Storage::Sqlite)
    } else {
        None
    }
}

fn yaml_str<'y>(y: &'y Yaml, key: &str) -> Option<&'y str> {
    y[key].as_str()
}

/// The folder's `metadata.yaml`, or the one storage file given.
fn layout(path: &Path) -> Result<Layout, FootageError> {
    if !path.is_dir() {
        let storage = storage_of(path).ok_or_else(|| {
            bag_error(
                path,
                "not a bag: give a ROS 1 bag (.bag), a rosbag2 folder (with metadata.yaml) or a rosbag2 storage file (.mcap, .db3)",
            )
        })?;
        let zstd = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("zstd"));
        return Ok(Layout {
            storage,
            compression: if zstd {
                Compression::File
            } else {
                Compression::None
            },
            files: vec![path.to_owned()],
        });
    }
    let file = path.join("metadata.yaml");
    let text = std::fs::read_to_string(&file).map_err(|e| {
        bag_error(
            path,
            format!("not a rosbag2 folder: metadata.yaml: {e} (`ros2 bag reindex` writes it)"),
        )
    })?;
    let meta = |message: String| bag_error(&file, message);
    let docs = YamlLoader::load_from_str(&text).map_err(|e| meta(format!("not YAML: {e}")))?;
    let info = docs
        .first()
        .map(|d| &d["rosbag2_bagfile_information"])
        .filter(|i| !i.is_badvalue())
        .ok_or_else(|| meta("no rosbag2_bagfile_information".to_owned()))?;
    let storage = match yaml_str(info, "storage_identifier") {
        Some("mcap") => Storage::Mcap,
        Some("sqlite3") => Storage::Sqlite,
        other => {
            return Err(meta(format!(
                "storage_identifier {other:?} is not read (mcap, sqlite3): `ros2 bag convert` rewrites the bag as mcap"
            )));
        }
    };
    let format = yaml_str(info, "compression_format").unwrap_or_default();
    let mode = yaml_str(info, "compression_mode")
        .unwrap_or_default()
        .to_ascii_lowercase();
    let compression = match (format, mode.as_str()) {
        ("", _) | (_, "" | "none") => Compression::None,
        ("zstd", "file") => Compression::File,
        ("zstd", "message") => Compression::Message,
        ("zstd", "storage") => Compression::None,
        (f, m) => {
            return Err(meta(format!(
                "compression {f} (mode {m}) is not read (zstd by file, message or storage): `ros2 bag decompress` writes an uncompressed copy"
            )));
        }
    };
    let files: Vec<PathBuf> = info["relative_file_paths"]
        .as_vec()
        .map(|v| {
            v.iter()
                .filter_map(Yaml::as_str)
                .map(|f| path.join(f))
                .collect()
        })
        .unwrap_or_default();
    if files.is_empty() {
        return Err(meta("relative_file_paths lists no files".to_owned()));
    }
    Ok(Layout {
        storage,
        compression,
        files,
    })
}

/// One storage file's bytes, decompressed where rosbag2 compressed it whole.
fn read_file(file: &Path, compression: Compression) -> Result<Vec<u8>, FootageError> {
    let bytes = std::fs::read(file).map_err(|source| FootageError::Io {
        path: file.to_owned(),
        action: "read",
        source,
    })?;
    if compression == Compression::File {
        return zstd::decode_all(bytes.as_slice()).map_err(|e| {
            bag_error(
                file,
                format!("not zstd-compressed as metadata.yaml says: {e}"),
            )
        });
    }
    Ok(bytes)
}

/// Topic -> type, checked to be CDR.
type Topics = BTreeMap<String, String>;

fn mcap_error(file: &Path, e: &mcap::McapError) -> FootageError {
    bag_error(file, format!("not a readable MCAP file: {e}"))
}

/// The MCAP file's CDR channels, from its summary (the messages where it has none); the
/// others (`topic (encoding)`) into `skipped`.
fn mcap_topics(
    file: &Path,
    bytes: &[u8],
    topics: &mut Topics,
    skipped: &mut Vec<String>,
) -> Result<(), FootageError> {
    // (topic, message encoding, type) of each channel.
    let mut channels: BTreeMap<u16, (String, String, String)> = BTreeMap::new();
    let mut add = |c: &mcap::Channel<'_>| {
        let kind = c
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        channels
            .entry(c.id)
            .or_insert_with(|| (c.topic.clone(), c.message_encoding.clone(), kind));
    };
    match mcap::read::Summary::read(bytes).map_err(|e| mcap_error(file, &e))? {
        Some(summary) => summary.channels.values().for_each(|c| add(c)),
        None => {
            for m in mcap::MessageStream::new(bytes).map_err(|e| mcap_error(file, &e))? {
                add(&m.map_err(|e| mcap_error(file, &e))?.channel);
            }
        }
    }
    for (topic, encoding, kind) in channels.into_values() {
        if encoding == "cdr" {
            topics.insert(topic, kind);
        } else {
            skipped.push(format!("{topic} ({encoding})"));
        }
    }
    Ok(())
}

fn sqlite_error(file: &Path, e: &rusqlite::Error) -> FootageError {
    bag_error(file, format!("not a rosbag2 SQLite file: {e}"))
}

fn open_sqlite(file: &Path) -> Result<rusqlite::Connection, FootageError> {
    rusqlite::Connection::open_with_flags(file, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY)
        .map_err(|e| sqlite_error(file, &e))
}

/// The SQLite file's CDR topics: id -> (name, type); the others (`topic (format)`) into
/// `skipped`.
fn sqlite_topics(
    file: &Path,
    skipped: &mut Vec<String>,
) -> Result<BTreeMap<i64, (String, String)>, FootageError> {
    let db = open_sqlite(file)?;
    let fail = |e: rusqlite::Error| sqlite_error(file, &e);
    let mut query = db
        .prepare("SELECT id, name, type, serialization_format FROM topics")
        .map_err(fail)?;
    let rows = query
        .query_map([], |r| {
            Ok((
                r.get::<_, i64>(0)?,
                r.get::<_, String>(1)?,
                r.get::<_, String>(2)?,
                r.get::<_, String>(3)?,
            ))
        })
        .map_err(fail)?;
    let mut topics = BTreeMap::new();
    for row in rows {
        let (id, name, kind, format) = row.map_err(fail)?;
        if format == "cdr" {
            topics.insert(id, (name, kind));
        } else {
            skipped.push(format!("{name} ({format})"));
        }
    }
    Ok(topics)
}

/// Every message of the file in the order stored (MCAP) or of their stamps (SQLite), given to
/// the importer with its receive time (ns).
fn each_message(
    file: &Path,
    layout: &Layout,
    importer: &mut Importer<'_, Ros2>,
) -> Result<(), FootageError> {
    let unpack = |data: &[u8]| -> Result<Vec<u8>, FootageError> {
        zstd::decode_all(data).map_err(|e| {
            bag_error(
                file,
                format!("a message not zstd-compressed as metadata.yaml says: {e}"),
            )
        })
    };
    match layout.storage {
        Storage::Mcap => {
            let bytes = read_file(file, layout.compression)?;
            for m in mcap::MessageStream::new(&bytes).map_err(|e| mcap_error(file, &e))? {
                let m = m.map_err(|e| mcap_error(file, &e))?;
                if m.channel.message_encoding != "cdr" {
                    continue;
                }
                if layout.compression == Compression::Message {
                    importer.message(&m.channel.topic, &unpack(&m.data)?, m.log_time)?;
                } else {
                    importer.message(&m.channel.topic, &m.data, m.log_time)?;
                }
            }
        }
        Storage::Sqlite => {
            let topics = sqlite_topics(file, &mut Vec::new())?;
            let db = open_sqlite(file)?;
            let fail = |e: rusqlite::Error| sqlite_error(file, &e);
            let mut query = db
                .prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id")
                .map_err(fail)?;
            let mut rows = query.query([]).map_err(fail)?;
            while let Some(row) = rows.next().map_err(fail)? {
                let id: i64 = row.get(0).map_err(fail)?;
                let stamp: i64 = row.get(1).map_err(fail)?;
                let data =
                    row.get_ref(2).map_err(fail)?.as_blob().map_err(|e| {
                        bag_error(file, format!("a message's data is not bytes: {e}"))
                    })?;
                // A message of a topic that is not CDR (skipped and said) is left out.
                let Some((topic, _)) = topics.get(&id) else {
                    continue;
                };
                let stamp = u64::try_from(stamp).map_err(|_| {
                    bag_error(
                        file,
                        format!("{topic}: a message received at {stamp} ns, before the epoch"),
                    )
                })?;
                if layout.compression == Compression::Message {
                    importer.message(topic, &unpack(data)?, stamp)?;
                } else {
                    importer.message(topic, data, stamp)?;
                }
            }
        }
    }
    Ok(())
}

/// Imports a rosbag2 (see [`super::import_bag`]).
pub(super) fn import(o: &BagOptions) -> Result<BagSummary, FootageError> {
    let layout = layout(&o.bag)?;
    if layout.storage == Storage::Sqlite && layout.compression == Compression::File {
        return Err(bag_error(
            &o.bag,
            "a SQLite storage compressed whole is not read: `ros2 bag decompress` writes an uncompressed copy",
        ));
    }
    let mut topics = Topics::new();
    let mut skipped = Vec::new();
    for file in &layout.files {
        match layout.storage {
            Storage::Mcap => {
                let bytes = read_file(file, layout.compression)?;
                mcap_topics(file, &bytes, &mut topics, &mut skipped)?;
            }
            Storage::Sqlite => {
                topics.extend(sqlite_topics(file, &mut skipped)?.into_values());
            }
        }
    }
    if topics.is_empty() && !skipped.is_empty() {
        return Err(bag_error(
            &o.bag,
            format!(
                "no topic is CDR ({}): not a rosbag2 (an Avatarm recording replays with --recording)",
                skipped.join(", ")
            ),
        ));
    }
    let format = match layout.storage {
        Storage::Mcap => "rosbag2 (mcap)",
        Storage::Sqlite => "rosbag2 (sqlite3)",
    };
    let mut importer = Importer::<Ros2>::new(o, format, topics)?;
    for file in &layout.files {
        each_message(file, &layout, &mut importer)?;
    }
    let mut summary = importer.finish()?;
    if !skipped.is_empty() {
        summary.notes.push(format!(
            "topics not in CDR, left out: {}",
            skipped.join(", ")
        ));
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Header (stamp 5 s + 7 ns, frame "cam") in CDR after the encapsulation `id`.
    fn header(id: [u8; 2], big_endian: bool) -> Vec<u8> {
        let mut b = vec![id[0], id[1], 0, 0];
        let word = |v: u32| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        b.extend(word(5));
        b.extend(word(7));
        // The string's length counts its terminating NUL.
        b.extend(word(4));
        b.extend(b"cam\0");
        b
    }

    #[test]
    fn cdr_is_read_in_both_byte_orders() {
        for (id, big) in [([0, 1], false), ([0, 0], true)] {
            let h: Header = Ros2::decode(&header(id, big)).expect("decodes");
            assert_eq!((h.stamp_ns(99), h.frame_id()), (5_000_000_007, "cam"));
        }
    }

    #[test]
    fn what_is_not_plain_cdr_or_not_the_layout_is_refused() {
        let e = Ros2::decode::<Header>(&header([0, 3], false)).err();
        assert!(e.is_some_and(|e| e.contains("encapsulation 0003")));
        let e = Ros2::decode::<Header>(&[0, 1]).err();
        assert!(e.is_some_and(|e| e.contains("shorter than CDR's 4-byte")));
        // A ROS 1 layout (a seq before the stamp) reads past its end or leaves bytes over.
        let mut longer = header([0, 1], false);
        longer.extend([0u8; 16]);
        let e = Ros2::decode::<Header>(&longer).err();
        assert!(e.is_some_and(|e| e.contains("16 of its 36 bytes left over")));
        let mut cut = header([0, 1], false);
        cut.truncate(14);
        assert!(Ros2::decode::<Header>(&cut).is_err());
    }

    #[test]
    fn a_stamp_before_the_epoch_or_zero_is_the_receive_time() {
        for sec in [-1, 0] {
            let h = Header {
                stamp: Time { sec, nanosec: 0 },
                frame_id: String::new(),
            };
            assert_eq!(h.stamp_ns(42), 42);
        }
    }
}
