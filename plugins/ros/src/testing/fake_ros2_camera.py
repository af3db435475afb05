#!/usr/bin/env python3
"""A fake ROS 2 camera driver on DDS, written with PyPI's cyclonedds (not with anything of
Avatarm's), publishing as usb_cam or image_transport would: sensor_msgs/msg/Image (bgr8, a known
pattern: pixel (x, y) of frame i is B = i % 256, G = y % 256, R = x % 256) on --topic, or, where
--file is given, sensor_msgs/msg/CompressedImage carrying that file's bytes (a JPEG or PNG) on
--topic (by image_transport's convention ending in /compressed). Stamped with the wall clock
plus --offset s, at --fps, best effort (sensor data QoS). Prints one JSON line per second:
{"t": wall time, "frames": published}.

Run it with PYTHONPATH=~/.cache/avatarm/python (scripts/setup.sh installs cyclonedds there).
"""

import argparse
import json
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from ros2_types import Header, Image, CompressedImage, sensor_qos, stamp_of






def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--topic", required=True)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, default=48)
    p.add_argument("--file", default="")
    p.add_argument("--offset", type=float, default=0.0)
    a = p.parse_args()
    qos = sensor_qos()
    dp = DomainParticipant(a.domain)
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
