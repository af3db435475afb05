#!/usr/bin/python3
"""A simulated Rethink Sawyer on ROS 1, speaking Intera's topics, for Avatarm's link tests.

Run with Debian's /usr/bin/python3 (rospy). The Intera message types are generated at run time
from the .msg files of Avatarm's ROS crate (plugins/ros/msg), so the node and Avatarm disagree
if a definition is wrong; sensor_msgs and std_msgs are Debian's own.

What it does, as the real robot does:
  - publishes /robot/joint_states (sensor_msgs/JointState, head_pan, right_j0..right_j6 and
    torso_t0) at --rate Hz, stamped with its own clock: wall time + --offset seconds;
  - publishes /robot/state (intera_core_msgs/RobotAssemblyState) at 10 Hz;
  - takes /robot/limb/right/joint_command (intera_core_msgs/JointCommand) in velocity mode,
    integrates the velocities within the Sawyer's velocity and position limits, and holds
    position when no command came for the command timeout
    (/robot/limb/right/joint_command_timeout, std_msgs/Float64, default 0.2 s);
  - ignores every command while disabled or stopped, and counts them;
  - sets its joint-state rate from /robot/joint_state_publish_rate (std_msgs/UInt16);
  - names its gripper device (--gripper-device, default right_gripper) in the latched
    /io/end_effector/config (IONodeConfiguration), takes the device's command
    (IOComponentCommand, op "set", JSON args with signals.position_m), moves the fingers there
    at 0.1 m/s and reports them on the device's state (IODeviceStatus, Intera's signals
    position_response_m, is_gripping, is_calibrated, has_error) at 10 Hz.
With --ros-control velocity|position it is instead an arm under ros_control: joint states on
/joint_states, and a joint group velocity or position controller on /arm_controller/command
(std_msgs/Float64MultiArray, one value per --controller-joints joint, in that order); the
velocity controller keeps its last command for ever (as ros_control's does), the position
controller moves each joint to its target at the joint's speed limit.
Signals: SIGUSR1 toggles the e-stop (stopped), SIGUSR2 toggles enabled.
Every 0.25 s (and at exit) it prints one JSON line of what it saw to stdout.
"""

import argparse
import json
import os
import signal
import statistics
import sys
import threading
import time

import genpy.dynamic
import rospy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, UInt16

HERE = os.path.dirname(os.path.abspath(__file__))
MSG = os.path.join(HERE, "..", "..", "msg")

# Sawyer limits (rad, rad/s), from sawyer_description's URDF.
LIMITS = {
    "right_j0": (-3.0503, 3.0503, 1.74),
    "right_j1": (-3.8095, 2.2736, 1.328),
    "right_j2": (-3.0426, 3.0426, 1.957),
    "right_j3": (-3.0439, 3.0439, 1.957),
    "right_j4": (-2.9761, 2.9761, 3.485),
    "right_j5": (-2.9761, 2.9761, 3.485),
    "right_j6": (-4.7124, 4.7124, 4.545),
}
NAMES = ["head_pan"] + sorted(LIMITS) + ["torso_t0"]


def intera_types():
    """The Intera message classes, generated from Avatarm's own definitions."""
    sep = "\n" + "=" * 80 + "\n"

    def text(package, name):
        return open(os.path.join(MSG, package, "msg", name + ".msg")).read()

    # Each type with the definitions it embeds, as a ROS 1 connection carries them.
    depends = {
        "JointCommand": [("std_msgs", "Header")],
        "RobotAssemblyState": [],
        "IOComponentCommand": [],
        "IODeviceStatus": [
            ("intera_core_msgs", "IOComponentStatus"),
            ("intera_core_msgs", "IOStatus"),
            ("intera_core_msgs", "IODataStatus"),
        ],
        "IONodeConfiguration": [("intera_core_msgs", "IOComponentConfiguration")],
    }
    out = {}
    for name, deps in depends.items():
        full = "intera_core_msgs/" + name
        definition = text("intera_core_msgs", name)
        for package, dep in deps:
            definition += sep + "MSG: %s/%s\n" % (package, dep) + text(package, dep)
        classes = genpy.dynamic.generate_dynamic(full, definition)
        out[name] = classes[full]
        for package, dep in deps:
            out.setdefault(dep, classes["%s/%s" % (package, dep)])
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--offset", type=float, default=0.0, help="robot clock minus wall clock (s)")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--start", type=str, default="", help="right_j0..j6 start values, comma-separated")
    ap.add_argument("--disabled", action="store_true")
    ap.add_argument("--gripper-device", type=str, default="right_gripper")
    ap.add_argument("--ros-control", choices=["velocity", "position"], default=None)
    ap.add_argument("--controller-joints", type=str, default=",".join(reversed(sorted(LIMITS))))
    args = ap.parse_args()

    types = intera_types()
    rospy.init_node("fake_sawyer", disable_signals=True)
    lock = threading.Lock()
    q = {n: 0.0 for n in NAMES}
    if args.start:
        for n, v in zip(sorted(LIMITS), args.start.split(",")):
            q[n] = float(v)
    state = {
        "enabled": not args.disabled,
        "stopped": False,
        "velocity": {n: 0.0 for n in LIMITS},
        "last_command": None,
        # Not Intera's 0.2 s: the tests check that Avatarm sets it.
        "timeout_s": 0.5,
        "speed_ratio": None,
        "commands": 0,
        "ignored": 0,
        "ignored_max_speed": 0.0,
        "bad": 0,
        "latency_ms": [],
        # Intervals between consecutive joint commands (ms), gaps of a second or more (a new
        # stream) left out: a command stream's evenness.
        "gaps_ms": [],
        "holds": 0,
        # When the arm last held for want of a fresh command (wall clock, s), and its fastest
        # joint's speed (rad/s) the moment before.
        "held_at": None,
        "speed_at_hold": None,
        "gripper_m": None,
        "gripper_target_m": 0.041667,
        "gripper_at_m": 0.041667,
        "gripper_commands": 0,
        "rate_hz": args.rate,
        "target": None,
        "md5": types["JointCommand"]._md5sum,
    }

    def note_gap(now):
        # Under the lock.
        last = state["last_command"]
        if last is not None and now - last < 1.0:
            state["gaps_ms"].append((now - last) * 1e3)
            del state["gaps_ms"][:-20000]

    def on_command(m):
        now = time.time()
        with lock:
            if not state["enabled"] or state["stopped"]:
                state["ignored"] += 1
                speeds = [abs(v) for v in m.velocity] or [0.0]
                state["ignored_max_speed"] = max(state["ignored_max_speed"], max(speeds))
                return
            if m.mode != 2 or len(m.names) != len(m.velocity):
                state["bad"] += 1
                return
            vel = dict(zip(m.names, m.velocity))
            if any(v != v or abs(v) == float("inf") for v in vel.values()) or any(
                n not in LIMITS for n in vel
            ):
                state["bad"] += 1
                return
            for n, v in vel.items():
                state["velocity"][n] = v
            note_gap(now)
            state["last_command"] = now
            state["commands"] += 1
            stamp = m.header.stamp.to_sec()
            state["latency_ms"].append((now - stamp) * 1e3)
            del state["latency_ms"][:-2000]

    def on_timeout(m):
        with lock:
            state["timeout_s"] = m.data

    def on_ratio(m):
        with lock:
            state["speed_ratio"] = m.data

    def on_gripper(m):
        with lock:
            if not state["enabled"] or state["stopped"] or m.op != "set":
                state["ignored"] += 1
                return
            try:
                p = json.loads(m.args)["signals"]["position_m"]["data"][0]
            except (ValueError, KeyError, IndexError, TypeError):
                state["bad"] += 1
                return
            state["gripper_m"] = min(max(float(p), 0.0), 0.041667)
            state["gripper_target_m"] = state["gripper_m"]
            state["gripper_commands"] += 1

    controller = args.controller_joints.split(",")

    def on_group(m):
        now = time.time()
        with lock:
            data = list(m.data)
            if len(data) != len(controller) or any(v != v or abs(v) == float("inf") for v in data):
                state["bad"] += 1
                return
            if args.ros_control == "velocity":
                for n, v in zip(controller, data):
                    state["velocity"][n] = v
            else:
                state["target"] = dict(zip(controller, data))
            note_gap(now)
            state["last_command"] = now
            state["commands"] += 1

    def on_rate(m):
        with lock:
            if 1 <= m.data <= 800:
                state["rate_hz"] = float(m.data)

    rospy.Subscriber("/robot/limb/right/joint_command", types["JointCommand"], on_command, queue_size=1)
    rospy.Subscriber("/robot/limb/right/joint_command_timeout", Float64, on_timeout)
    rospy.Subscriber("/robot/limb/right/set_speed_ratio", Float64, on_ratio)
    device = "/io/end_effector/" + args.gripper_device
    rospy.Subscriber(device + "/command", types["IOComponentCommand"], on_gripper)
    rospy.Subscriber("/robot/joint_state_publish_rate", UInt16, on_rate)
    config_pub = rospy.Publisher("/io/end_effector/config", types["IONodeConfiguration"], queue_size=1, latch=True)
    config = types["IONodeConfiguration"]()
    config.time = rospy.Time.now()
    config.node = types["IOComponentConfiguration"](name="end_effector", config="{}")
    config.devices = [types["IOComponentConfiguration"](name=args.gripper_device, config="{}")]
    config_pub.publish(config)
    gripper_pub = rospy.Publisher(device + "/state", types["IODeviceStatus"], queue_size=1, latch=True)

    def gripper_state(at_m, target_m):
        m = types["IODeviceStatus"]()
        m.time = rospy.Time.now()
        m.device = types["IOComponentStatus"](name=args.gripper_device)
        m.device.status.tag = "ready"

        def signal_(name, kind, value):
            d = types["IODataStatus"](name=name, format=json.dumps({"type": kind}), data=json.dumps([value]))
            d.status.tag = "ready"
            return d

        m.signals = [
            signal_("position_response_m", "float", at_m),
            # Closed on the commanded opening (the fake has no object to stop on).
            signal_("is_gripping", "bool", target_m < 0.01 and at_m <= target_m + 1e-4),
            signal_("is_calibrated", "bool", True),
            signal_("has_error", "bool", False),
        ]
        return m
    if args.ros_control:
        rospy.Subscriber("/arm_controller/command", Float64MultiArray, on_group, queue_size=1)
    js_topic = "/joint_states" if args.ros_control else "/robot/joint_states"
    js_pub = rospy.Publisher(js_topic, JointState, queue_size=10)
    st_pub = rospy.Publisher("/robot/state", types["RobotAssemblyState"], queue_size=1, latch=True)

    def toggle(key):
        def handler(_sig, _frame):
            with lock:
                state[key] = not state[key]
                if key == "stopped" and state[key]:
                    state["velocity"] = {n: 0.0 for n in LIMITS}
        return handler

    signal.signal(signal.SIGUSR1, toggle("stopped"))
    signal.signal(signal.SIGUSR2, toggle("enabled"))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())

    def report():
        with lock:
            lat = state["latency_ms"]
            gaps = sorted(state["gaps_ms"])
            line = {
                "t": time.time(),
                "md5": state["md5"],
                "enabled": state["enabled"],
                "stopped": state["stopped"],
                "commands": state["commands"],
                "ignored": state["ignored"],
                "ignored_max_speed": state["ignored_max_speed"],
                "bad": state["bad"],
                "holds": state["holds"],
                "held_at": state["held_at"],
                "speed_at_hold": state["speed_at_hold"],
                "last_command_at": state["last_command"],
                "timeout_s": state["timeout_s"],
                "speed_ratio": state["speed_ratio"],
                "gripper_m": state["gripper_m"],
                "gripper_commands": state["gripper_commands"],
                "gripper_at_m": state["gripper_at_m"],
                "rate_hz": state["rate_hz"],
                "latency_ms_median": statistics.median(lat) if lat else None,
                "latency_ms_p95": sorted(lat)[int(0.95 * (len(lat) - 1))] if lat else None,
                "command_gaps": len(gaps),
                "command_gap_ms_median": gaps[len(gaps) // 2] if gaps else None,
                "command_gap_ms_p95": gaps[int(0.95 * (len(gaps) - 1))] if gaps else None,
                "command_gap_ms_max": gaps[-1] if gaps else None,
                "command_gaps_over_50ms": sum(1 for g in gaps if g > 50.0),
                "q": [q[n] for n in sorted(LIMITS)],
                "target": None if state["target"] is None else [state["target"][n] for n in sorted(LIMITS)],
                "velocity": [state["velocity"][n] for n in sorted(LIMITS)],
            }
        print(json.dumps(line), flush=True)

    last = time.time()
    due = last
    next_state = 0.0
    next_report = 0.0
    held = True
    while not stop.is_set() and not rospy.is_shutdown():
        now = time.time()
        dt = now - last
        last = now
        with lock:
            fresh = (
                state["last_command"] is not None
                and now - state["last_command"] <= state["timeout_s"]
                and state["enabled"]
                and not state["stopped"]
            )
            if args.ros_control == "velocity":
                # A ros_control velocity controller keeps its last command for ever.
                pass
            elif args.ros_control == "position":
                if state["target"] is not None:
                    for n, (lo, hi, vmax) in LIMITS.items():
                        d = state["target"][n] - q[n]
                        state["velocity"][n] = max(-vmax, min(vmax, d / dt if dt > 0 else 0.0))
            elif not fresh:
                if not held:
                    state["holds"] += 1
                    state["held_at"] = now
                    state["speed_at_hold"] = max(abs(v) for v in state["velocity"].values())
                held = True
                state["velocity"] = {n: 0.0 for n in LIMITS}
            else:
                held = False
            for n, (lo, hi, vmax) in LIMITS.items():
                v = min(max(state["velocity"][n], -vmax), vmax)
                q[n] = min(max(q[n] + v * dt, lo), hi)
            vel = [0.0 if n not in LIMITS else state["velocity"][n] for n in NAMES]
            positions = [q[n] for n in NAMES]
            enabled, stopped = state["enabled"], state["stopped"]
            g = state["gripper_at_m"]
            state["gripper_at_m"] = g + min(max(state["gripper_target_m"] - g, -0.1 * dt), 0.1 * dt)
            gripper = (state["gripper_at_m"], state["gripper_target_m"])
            period = 1.0 / state["rate_hz"]
        m = JointState()
        m.header.stamp = rospy.Time.from_sec(now + args.offset)
        m.name = NAMES
        m.position = positions
        m.velocity = vel
        m.effort = [0.0] * len(NAMES)
        js_pub.publish(m)
        if now >= next_state:
            s = types["RobotAssemblyState"]()
            s.homed = s.ready = True
            s.enabled = enabled
            s.stopped = stopped
            s.estop_button = 1 if stopped else 0
            s.estop_source = 1 if stopped else 0
            st_pub.publish(s)
            gripper_pub.publish(gripper_state(*gripper))
            next_state = now + 0.1
        if now >= next_report:
            report()
            next_report = now + 0.25
        # On a fixed schedule (the robot's rate), not a fixed pause after each cycle.
        due += period
        if due < time.time() - period:
            due = time.time()
        time.sleep(max(0.0, due - time.time()))
    report()
    rospy.signal_shutdown("done")
    return 0


if __name__ == "__main__":
    sys.exit(main())
