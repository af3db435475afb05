//! PyPI's `mcap` reader on a recording (`scripts/setup.sh` installs it), shared by the test
//! binaries that write recordings.

use std::path::Path;
use std::process::Command;

/// Reads the file with PyPI's `mcap` reader; returns one line per channel:
/// `topic schema_name encoding count first_json_keys`.
pub fn python_read(path: &Path) -> String {
    let script = r#"
import json, sys
from collections import Counter, OrderedDict
from mcap.reader import make_reader
counts, keys, schemas = Counter(), OrderedDict(), {}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages():
        counts[channel.topic] += 1
        schemas[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
        keys.setdefault(channel.topic, sorted(json.loads(message.data)))
for topic in sorted(counts):
    name, enc, menc = schemas[topic]
    print(topic, name, enc, menc, counts[topic], ",".join(keys[topic]))
"#;
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(path)
        .env("PYTHONPATH", python_path())
        .output()
        .expect("python3");
    assert!(
        out.status.success(),
        "PyPI's mcap reader (scripts/setup.sh installs it): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Where `scripts/setup.sh` installs PyPI's packages for the tests (`mcap`, `rosbags`):
/// `~/.cache/avatarm/python`, for `PYTHONPATH`.
pub fn python_path() -> String {
    std::env::var("HOME")
        .map(|h| format!("{h}/.cache/avatarm/python"))
        .unwrap_or_default()
}
