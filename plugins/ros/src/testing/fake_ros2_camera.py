#!/usr/bin/env python3
"""A fake ROS 2 camera driver on DDS, written with PyPI's cyclonedds (not with anything of
Avatarm's), publishing as usb_cam or image_transport would: sensor_msgs/msg/Image (bgr8, a known
pattern: pixel (x, y) of frame i is B = i % 256, G = y % 256, R = x % 256) on --topic, or, where
--file is given, sensor_msgs/msg/CompressedImage carrying that file's bytes (a JPEG or PNG) on
--topic (by image_transport's convention ending in /compressed). Stamped with the wall clock
plus --offset s, at --fps, best effort (sensor data QoS). With --fx, a sensor_msgs/msg/CameraInfo
beside each frame on the image topic's camera_info (--width x --height, K from --fx/--fy/--cx/--cy,
plumb_bob with --d), as camera drivers publish it. Each --tf-static PARENT CHILD X Y Z QX QY QZ QW
is published once on /tf_static, latched (reliable, transient local), as tf2's static
broadcaster does. Prints one JSON line per second: {"t": wall time, "frames": published}.

Run it with PYTHONPATH=~/.cache/avatarm/python (scripts/setup.sh installs cyclonedds there).
"""

import argparse
import json
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from ros2_types import (
    CameraInfo,
    CompressedImage,
    Header,
    Image,
    Quaternion,
    RegionOfInterest,
    TFMessage,
    Transform,
    TransformStamped,
    Vector3,
    sensor_qos,
    stamp_of,
    static_qos,
)


def info_topic(image_topic):
    """image_transport's camera_info beside an image topic."""
    base = image_topic.rstrip("/")
    if base.endswith("/compressed"):
        base = base[: -len("/compressed")]
    return base.rsplit("/", 1)[0] + "/camera_info" if "/" in base else "camera_info"






def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--topic", required=True)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, default=48)
    p.add_argument("--file", default="")
    p.add_argument("--offset", type=float, default=0.0)
    p.add_argument("--fx", type=float, default=0.0)
    p.add_argument("--fy", type=float, default=0.0)
    p.add_argument("--cx", type=float, default=0.0)
    p.add_argument("--cy", type=float, default=0.0)
    p.add_argument("--d", type=float, nargs=5, default=[0.0] * 5)
    p.add_argument("--tf-static", nargs=9, action="append", default=[])
    a = p.parse_args()
    qos = sensor_qos()
    dp = DomainParticipant(a.domain)
    info_writer = None
    if a.fx > 0:
        info_writer = DataWriter(dp, Topic(dp, "rt" + info_topic(a.topic), CameraInfo, qos=qos), qos=qos)
    if a.tf_static:
        sq = static_qos()
        tf_writer = DataWriter(dp, Topic(dp, "rt/tf_static", TFMessage, qos=sq), qos=sq)
        transforms = []
        for parent, child, *v in a.tf_static:
            x, y, z, qx, qy, qz, qw = map(float, v)
            transforms.append(
                TransformStamped(
                    header=Header(stamp=stamp_of(time.time()), frame_id=parent),
                    child_frame_id=child,
                    transform=Transform(
                        translation=Vector3(x=x, y=y, z=z), rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)
                    ),
                )
            )
        tf_writer.write(TFMessage(transforms=transforms))
    name = "rt" + a.topic
    if a.file:
        writer = DataWriter(dp, Topic(dp, name, CompressedImage, qos=qos), qos=qos)
        raw = open(a.file, "rb").read()
        fmt = "png" if raw[:4] == b"\x89PNG" else "jpeg"
        payload = list(raw)
    else:
        writer = DataWriter(dp, Topic(dp, name, Image, qos=qos), qos=qos)
    frames = 0
    next_frame = time.time()
    next_report = next_frame
    while True:
        now = time.time()
        if now >= next_frame:
            header = Header(stamp=stamp_of(now + a.offset), frame_id="camera_optical_frame")
            if info_writer is not None:
                info_writer.write(
                    CameraInfo(
                        header=header,
                        height=a.height,
                        width=a.width,
                        distortion_model="plumb_bob",
                        d=list(a.d),
                        k=[a.fx, 0.0, a.cx, 0.0, a.fy, a.cy, 0.0, 0.0, 1.0],
                        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                        p=[a.fx, 0.0, a.cx, 0.0, 0.0, a.fy, a.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
                        binning_x=0,
                        binning_y=0,
                        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
                    )
                )
            if a.file:
                writer.write(CompressedImage(header=header, format=fmt, data=payload))
            else:
                w, h = a.width, a.height
                row = bytearray()
                for x in range(w):
                    row += bytes([frames % 256, 0, x % 256])
                data = bytearray()
                for y in range(h):
                    r = bytearray(row)
                    r[1::3] = bytes([y % 256]) * w
                    data += r
                writer.write(
                    Image(header=header, height=h, width=w, encoding="bgr8", is_bigendian=0, step=3 * w, data=list(data))
                )
            frames += 1
            next_frame += 1.0 / a.fps
            if next_frame < now:
                next_frame = now + 1.0 / a.fps
        if now >= next_report:
            print(json.dumps({"t": now, "frames": frames}), flush=True)
            next_report = now + 1.0
        time.sleep(0.001)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        pass
