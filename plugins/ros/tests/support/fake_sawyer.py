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
  - takes the electric gripper's /io/end_effector/right_gripper/command (IOComponentCommand,
    op "set", JSON args with signals.position_m).
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
from std_msgs.msg import Float64

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
    header = open(os.path.join(MSG, "std_msgs", "msg", "Header.msg")).read()
    sep = "\n" + "=" * 80 + "\n"
    out = {}
    for name in ("JointCommand", "RobotAssemblyState", "IOComponentCommand"):
        text = open(os.path.join(MSG, "intera_core_msgs", "msg", name + ".msg")).read()
        if "Header header" in text:
            text += sep + "MSG: std_msgs/Header\n" + header
        full = "intera_core_msgs/" + name
        out[name] = genpy.dynamic.generate_dynamic(full, text)[full]
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--offset", type=float, default=0.0, help="robot clock minus wall clock (s)")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--start", type=str, default="", help="right_j0..j6 start values, comma-separated")
    ap.add_argument("--disabled", action="store_true")
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
        "holds": 0,
        "gripper_m": None,
        "gripper_commands": 0,
        "md5": types["JointCommand"]._md5sum,
    }

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
            state["gripper_commands"] += 1

    rospy.Subscriber("/robot/limb/right/joint_command", types["JointCommand"], on_command, queue_size=1)
    rospy.Subscriber("/robot/limb/right/joint_command_timeout", Float64, on_timeout)
    rospy.Subscriber("/robot/limb/right/set_speed_ratio", Float64, on_ratio)
    rospy.Subscriber("/io/end_effector/right_gripper/command", types["IOComponentCommand"], on_gripper)
    js_pub = rospy.Publisher("/robot/joint_states", JointState, queue_size=10)
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
                "timeout_s": state["timeout_s"],
                "speed_ratio": state["speed_ratio"],
                "gripper_m": state["gripper_m"],
                "gripper_commands": state["gripper_commands"],
                "latency_ms_median": statistics.median(lat) if lat else None,
                "latency_ms_p95": sorted(lat)[int(0.95 * (len(lat) - 1))] if lat else None,
                "q": [q[n] for n in sorted(LIMITS)],
                "velocity": [state["velocity"][n] for n in sorted(LIMITS)],
            }
        print(json.dumps(line), flush=True)

    period = 1.0 / args.rate
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
            if not fresh:
                if not held:
                    state["holds"] += 1
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
