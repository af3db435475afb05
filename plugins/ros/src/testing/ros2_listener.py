#!/usr/bin/env python3
"""A ROS 2 listener on DDS, written with PyPI's cyclonedds (not with anything of Avatarm's), as
rviz2 or `ros2 topic echo` would subscribe (reliable, volatile, keep last 10, ROS 2's DDS
names): PREFIX/erased/compressed and PREFIX/mask/compressed (sensor_msgs/msg/CompressedImage),
PREFIX/joint_commands (sensor_msgs/msg/JointState), PREFIX/safety (std_msgs/msg/String).
Prints a JSON report every 100 ms: t, and per topic the count and what the last message held
(an image's format, size in bytes and whether it starts as its format says; a command's names
and velocities; a safety line).

--rmw zenoh --router ENDPOINT: the same on rmw_zenoh (rmw_zenoh_peer.py: the topics keyed with
their types' REP-2016 hashes from rosbags' type store), its report adding per topic the samples
without rmw_zenoh's attachment (no_attachment).

Run it with PYTHONPATH=~/.cache/avatarm/python (scripts/setup.sh installs cyclonedds, rosbags and
eclipse-zenoh there).
"""

import argparse
import json
import time

MAGIC = {"jpeg": bytes([0xFF, 0xD8, 0xFF]), "png": b"\x89PNG"}

TOPICS = [
    ("erased/compressed", "sensor_msgs/msg/CompressedImage"),
    ("mask/compressed", "sensor_msgs/msg/CompressedImage"),
    ("joint_commands", "sensor_msgs/msg/JointState"),
    ("safety", "std_msgs/msg/String"),
]


def dds_readers(a):
    """name -> a function taking what arrived, on DDS (Cyclone DDS)."""
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    import ros2_types as t

    qos = t.default_qos()
    dp = DomainParticipant(a.domain)
    kinds = {
        "sensor_msgs/msg/CompressedImage": t.CompressedImage,
        "sensor_msgs/msg/JointState": t.JointState,
        "std_msgs/msg/String": t.String,
    }
    readers = {}
    for name, ros_type in TOPICS:
        reader = DataReader(
            dp, Topic(dp, "rt%s/%s" % (a.prefix, name), kinds[ros_type], qos=qos), qos=qos
        )
        # A writer gone comes as an instance-state sample without data.
        readers[name] = (
            lambda reader=reader, kind=kinds[ros_type]: [
                m for m in reader.take(N=100) if isinstance(m, kind)
            ],
            lambda: {},
        )
    return readers


def zenoh_readers(a):
    """name -> (a function taking what arrived, its counters), on rmw_zenoh."""
    import rmw_zenoh_peer as z

    node = z.Node(a.router, a.domain, "ros2_listener")
    readers = {}
    for name, ros_type in TOPICS:
        sub = node.subscription("%s/%s" % (a.prefix, name), ros_type)
        readers[name] = (
            sub.take,
            lambda sub=sub: {"no_attachment": sub.no_attachment, "undecodable": sub.undecodable},
        )
    readers["_node"] = node
    return readers


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--prefix", default="/avatarm")
    p.add_argument("--rmw", choices=["dds", "zenoh"], default="dds")
    p.add_argument("--router", default="tcp/127.0.0.1:7447", help="the Zenoh router (--rmw zenoh)")
    a = p.parse_args()
    readers = zenoh_readers(a) if a.rmw == "zenoh" else dds_readers(a)
    kinds = dict(TOPICS)
    report = {name: {"count": 0} for name in kinds}
    next_report = time.time()
    while True:
        for name, ros_type in TOPICS:
            take, counters = readers[name]
            r = report[name]
            r.update(counters())
            for m in take():
                r["count"] += 1
                if ros_type.endswith("CompressedImage"):
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
                elif ros_type.endswith("JointState"):
                    r.update(name=list(m.name), velocity=[float(v) for v in m.velocity])
                else:
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
