#!/usr/bin/env python3
"""A ROS 2 listener on DDS, written with PyPI's cyclonedds (not with anything of Avatarm's), as
rviz2 or `ros2 topic echo` would subscribe (reliable, volatile, keep last 10, ROS 2's DDS
names): PREFIX/erased/compressed and PREFIX/mask/compressed (sensor_msgs/msg/CompressedImage),
PREFIX/joint_commands (sensor_msgs/msg/JointState), PREFIX/safety (std_msgs/msg/String).
Prints a JSON report every 100 ms: t, and per topic the count and what the last message held
(an image's format, size in bytes and whether it starts as its format says; a command's names
and velocities; a safety line).

Run it with PYTHONPATH=~/.cache/avatarm/python (scripts/setup.sh installs cyclonedds there).
"""

import argparse
import json
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from ros2_types import CompressedImage, JointState, String, default_qos







MAGIC = {"jpeg": bytes([0xFF, 0xD8, 0xFF]), "png": b"\x89PNG"}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--prefix", default="/avatarm")
    a = p.parse_args()
    qos = default_qos()
    dp = DomainParticipant(a.domain)
    readers = {
        name: DataReader(dp, Topic(dp, "rt%s/%s" % (a.prefix, name), kind, qos=qos), qos=qos)
        for name, kind in [
            ("erased/compressed", CompressedImage),
            ("mask/compressed", CompressedImage),
            ("joint_commands", JointState),
            ("safety", String),
        ]
    }
    report = {name: {"count": 0} for name in readers}
    next_report = time.time()
    while True:
        for name, reader in readers.items():
            for m in reader.take(N=100):
                if not hasattr(m, "header") and not hasattr(m, "data"):
                    continue
                r = report[name]
                r["count"] += 1
                if isinstance(m, CompressedImage):
                    data = bytes(m.data)
                    r.update(
                        format=m.format,
                        bytes=len(data),
                        magic=data.startswith(MAGIC.get(m.format, b"?")),
                        stamp=m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                        frame_id=m.header.frame_id,
                    )
                    # The last 200 stamps as [sec, nanosec], to pair a frame's messages.
                    stamps = r.setdefault("stamps", [])
                    stamps.append([m.header.stamp.sec, m.header.stamp.nanosec])
                    del stamps[:-200]
                elif isinstance(m, JointState):
                    r.update(name=list(m.name), velocity=list(m.velocity))
                elif isinstance(m, String):
                    r.update(data=m.data)
        now = time.time()
        if now >= next_report:
            print(json.dumps(dict(report, t=now)), flush=True)
            next_report = now + 0.1
        time.sleep(0.002)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        pass
