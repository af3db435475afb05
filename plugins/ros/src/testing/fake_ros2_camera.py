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

--rmw zenoh --router ENDPOINT: the same driver on rmw_zenoh (rmw_zenoh_peer.py: the topics keyed
with their types' REP-2016 hashes, /tf_static from Zenoh's advanced publisher that keeps it for
late subscribers, as rmw_zenoh's transient local does).

Run it with PYTHONPATH=~/.cache/avatarm/python (scripts/setup.sh installs cyclonedds, rosbags and
eclipse-zenoh there).
"""

import argparse
import json
import time


class DdsDriver:
    """Messages and writers on DDS (Cyclone DDS)."""

    def __init__(self, a):
        from cyclonedds.domain import DomainParticipant

        import ros2_types as t

        self.t = t
        self.dp = DomainParticipant(a.domain)

    def __getattr__(self, name):
        # The message classes (Header, Image, ...).
        return getattr(self.t, name)

    def stamp(self, s):
        return self.t.stamp_of(s)

    def f64(self, values):
        return list(values)

    def u8(self, data):
        return list(data)

    def writer(self, topic, ros_type, latched=False):
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        kind = getattr(self.t, ros_type.rsplit("/", 1)[1])
        qos = self.t.static_qos() if latched else self.t.sensor_qos()
        w = DataWriter(self.dp, Topic(self.dp, "rt" + topic, kind, qos=qos), qos=qos)
        return w.write


class ZenohDriver:
    """Messages (rosbags' Jazzy types) and publishers on rmw_zenoh."""

    PACKAGES = {
        "Header": "std_msgs/msg/Header",
        "Image": "sensor_msgs/msg/Image",
        "CompressedImage": "sensor_msgs/msg/CompressedImage",
        "CameraInfo": "sensor_msgs/msg/CameraInfo",
        "RegionOfInterest": "sensor_msgs/msg/RegionOfInterest",
        "TFMessage": "tf2_msgs/msg/TFMessage",
        "TransformStamped": "geometry_msgs/msg/TransformStamped",
        "Transform": "geometry_msgs/msg/Transform",
        "Vector3": "geometry_msgs/msg/Vector3",
        "Quaternion": "geometry_msgs/msg/Quaternion",
    }

    def __init__(self, a):
        import numpy as np

        import rmw_zenoh_peer as z

        self.np = np
        self.z = z
        self.types = z.TYPES.types
        self.node = z.Node(a.router, a.domain, "fake_ros2_camera")

    def __getattr__(self, name):
        return self.types[self.PACKAGES[name]]

    def stamp(self, s):
        return self.z.ros_time(s)

    def f64(self, values):
        return self.z.float64s(values)

    def u8(self, data):
        return self.np.frombuffer(bytes(data), dtype=self.np.uint8)

    def writer(self, topic, ros_type, latched=False):
        return self.node.publisher(topic, ros_type, latched=latched).publish


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
    p.add_argument("--rmw", choices=["dds", "zenoh"], default="dds")
    p.add_argument("--router", default="tcp/127.0.0.1:7447", help="the Zenoh router (--rmw zenoh)")
    a = p.parse_args()
    T = ZenohDriver(a) if a.rmw == "zenoh" else DdsDriver(a)
    write_info = None
    if a.fx > 0:
        write_info = T.writer(info_topic(a.topic), "sensor_msgs/msg/CameraInfo")
    if a.tf_static:
        write_tf = T.writer("/tf_static", "tf2_msgs/msg/TFMessage", latched=True)
        transforms = []
        for parent, child, *v in a.tf_static:
            x, y, z, qx, qy, qz, qw = map(float, v)
            transforms.append(
                T.TransformStamped(
                    header=T.Header(stamp=T.stamp(time.time()), frame_id=parent),
                    child_frame_id=child,
                    transform=T.Transform(
                        translation=T.Vector3(x=x, y=y, z=z),
                        rotation=T.Quaternion(x=qx, y=qy, z=qz, w=qw),
                    ),
                )
            )
        write_tf(T.TFMessage(transforms=transforms))
    if a.file:
        write = T.writer(a.topic, "sensor_msgs/msg/CompressedImage")
        raw = open(a.file, "rb").read()
        fmt = "png" if raw[:4] == b"\x89PNG" else "jpeg"
        payload = T.u8(raw)
    else:
        write = T.writer(a.topic, "sensor_msgs/msg/Image")
    frames = 0
    next_frame = time.time()
    next_report = next_frame
    while True:
        now = time.time()
        if now >= next_frame:
            header = T.Header(stamp=T.stamp(now + a.offset), frame_id="camera_optical_frame")
            if write_info is not None:
                write_info(
                    T.CameraInfo(
                        header=header,
                        height=a.height,
                        width=a.width,
                        distortion_model="plumb_bob",
                        d=T.f64(a.d),
                        k=T.f64([a.fx, 0.0, a.cx, 0.0, a.fy, a.cy, 0.0, 0.0, 1.0]),
                        r=T.f64([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
                        p=T.f64([a.fx, 0.0, a.cx, 0.0, 0.0, a.fy, a.cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
                        binning_x=0,
                        binning_y=0,
                        roi=T.RegionOfInterest(
                            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
                        ),
                    )
                )
            if a.file:
                write(T.CompressedImage(header=header, format=fmt, data=payload))
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
                write(
                    T.Image(
                        header=header,
                        height=h,
                        width=w,
                        encoding="bgr8",
                        is_bigendian=0,
                        step=3 * w,
                        data=T.u8(data),
                    )
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
