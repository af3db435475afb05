#!/usr/bin/env python3
"""A fake ros2_control arm on ROS 2's DDS, written with PyPI's cyclonedds (Eclipse Cyclone DDS,
the DDS under ROS 2's rmw_cyclonedds_cpp), not with anything of Avatarm's: it follows ROS 2's
DDS conventions (topics `rt/<name>`, types `<pkg>::msg::dds_::<Type>_`, ROS 2's default QoS:
reliable, volatile, keep last 10) as rmw does.

- Publishes sensor_msgs/msg/JointState on /joint_states at --rate Hz, stamped with its own clock
  (the wall clock plus --offset s), as joint_state_broadcaster does.
- Subscribes to std_msgs/msg/Float64MultiArray on /<controller>/commands, one value per joint
  in --joints order (starting at --start), as forward_command_controller does: velocities (--mode velocity), clamped
  to +-(--max-velocity) and integrated, or position targets (--mode position) approached at
  --max-velocity (NaN velocities published with --no-velocity, as joint_state_broadcaster
  does for hardware without a velocity interface). A command of the wrong length is counted as bad and ignored. With no
  command for --timeout s, velocities go to zero.
- --mode trajectory: subscribes to trajectory_msgs/msg/JointTrajectory on
  /<controller>/joint_trajectory instead, as joint_trajectory_controller does: each message
  replaces the trajectory (header stamp zero: from now); its joint_names may come in any order
  (mapped by name; unknown or missing names, no point or a point of the wrong length count as
  bad); the arm moves linearly from where it is to the last point's positions over its
  time_from_start (at most --max-velocity) and holds them once reached, commands or not. Its
  report adds "horizon": the last point's time_from_start (s).
- --namespace /NS: its topics in that namespace (/NS/joint_states, /NS/<controller>/...).
- Prints a JSON report every 50 ms: t (wall clock), q, velocity, commands, bad, and the
  receipts of the last 300 commands as [wall time, first value].

--rmw zenoh --router ENDPOINT: the same arm on rmw_zenoh instead (rmw_zenoh_peer.py: eclipse-zenoh
and rosbags, written from rmw_zenoh's design document): the same topics keyed with their types'
REP-2016 hashes, so a command sent under another hash never arrives. Its report adds "graph" (the
liveliness tokens alive on the domain), "command_key" (the key it takes commands on),
"no_attachment" (commands without rmw_zenoh's attachment) and "undecodable".

Run it with PYTHONPATH=~/.cache/avatarm/python (scripts/setup.sh installs cyclonedds, rosbags and
eclipse-zenoh there).
"""

import argparse
import json
import sys
import time



class DdsLink:
    """The arm's topics on DDS (Cyclone DDS, ROS 2's DDS conventions)."""

    def __init__(self, a):
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        import ros2_types as t

        self.t = t
        qos = t.default_qos()
        dp = DomainParticipant(a.domain)
        ns = a.namespace.rstrip("/")
        self.states = DataWriter(
            dp, Topic(dp, "rt%s/joint_states" % ns, t.JointState, qos=qos), qos=qos
        )
        if a.mode == "trajectory":
            topic = Topic(
                dp, "rt%s/%s/joint_trajectory" % (ns, a.controller), t.JointTrajectory, qos=qos
            )
        else:
            topic = Topic(
                dp, "rt%s/%s/commands" % (ns, a.controller), t.Float64MultiArray, qos=qos
            )
        self.commands = DataReader(dp, topic, qos=qos)

    def take(self):
        # A writer gone (the link's end) comes as an instance-state sample without data.
        kinds = (self.t.JointTrajectory, self.t.Float64MultiArray)
        return [m for m in self.commands.take(N=100) if isinstance(m, kinds)]

    def publish_state(self, stamp_s, names, position, velocity):
        t = self.t
        self.states.write(
            t.JointState(
                header=t.Header(stamp=t.stamp_of(stamp_s), frame_id=""),
                name=names,
                position=position,
                velocity=velocity,
                effort=[],
            )
        )

    def report(self):
        return {}


class ZenohLink:
    """The arm's topics on rmw_zenoh (rmw_zenoh_peer.py)."""

    def __init__(self, a):
        import rmw_zenoh_peer as z

        self.z = z
        self.types = z.TYPES.types
        self.node = z.Node(a.router, a.domain, "fake_ros2_arm", a.namespace or "/")
        self.graph = self.node.graph()
        # Relative names: in the node's namespace.
        self.states = self.node.publisher("joint_states", "sensor_msgs/msg/JointState")
        if a.mode == "trajectory":
            topic = ("%s/joint_trajectory" % a.controller, "trajectory_msgs/msg/JointTrajectory")
        else:
            topic = ("%s/commands" % a.controller, "std_msgs/msg/Float64MultiArray")
        self.commands = self.node.subscription(*topic)
        self.command_key = self.node.key(*topic)

    def take(self):
        return self.commands.take()

    def publish_state(self, stamp_s, names, position, velocity):
        T, z = self.types, self.z
        self.states.publish(
            T["sensor_msgs/msg/JointState"](
                header=T["std_msgs/msg/Header"](stamp=z.ros_time(stamp_s), frame_id=""),
                name=list(names),
                position=z.float64s(position),
                velocity=z.float64s(velocity),
                effort=z.float64s([]),
            )
        )

    def report(self):
        return {
            "graph": self.graph.alive(),
            "command_key": self.command_key,
            "no_attachment": self.commands.no_attachment,
            "undecodable": self.commands.undecodable,
        }


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--domain", type=int, default=0)
    p.add_argument("--rmw", choices=["dds", "zenoh"], default="dds")
    p.add_argument("--namespace", default="", help="the arm's namespace (/robot1); default none")
    p.add_argument("--router", default="tcp/127.0.0.1:7447", help="the Zenoh router (--rmw zenoh)")
    p.add_argument("--joints", required=True)
    p.add_argument("--controller", default="forward_velocity_controller")
    p.add_argument("--mode", choices=["velocity", "position", "trajectory"], default="velocity")
    p.add_argument("--rate", type=float, default=100.0)
    p.add_argument("--offset", type=float, default=0.0)
    p.add_argument("--max-velocity", type=float, default=1.0)
    p.add_argument("--timeout", type=float, default=0.5)
    p.add_argument("--start", default="", help="the joints' start positions, comma-separated")
    p.add_argument(
        "--no-velocity",
        action="store_true",
        help="publish NaN velocities, as joint_state_broadcaster does for hardware without a velocity interface",
    )
    a = p.parse_args()
    joints = a.joints.split(",")
    n = len(joints)
    link = ZenohLink(a) if a.rmw == "zenoh" else DdsLink(a)
    # The trajectory followed (--mode trajectory): from, to, its start and its duration.
    segment = None
    horizon = None
    q = [float(x) for x in a.start.split(",")] if a.start else [0.0] * n
    v = [0.0] * n
    target = None
    last_command = None
    count, bad = 0, 0
    receipts = []
    period = 1.0 / a.rate
    t_prev = time.time()
    next_report = t_prev
    next_state = t_prev
    while True:
        now = time.time()
        for m in link.take():
            if a.mode == "trajectory":
                point = m.points[-1] if m.points else None
                if (
                    point is None
                    or sorted(m.joint_names) != sorted(joints)
                    or len(point.positions) != len(m.joint_names)
                ):
                    bad += 1
                    continue
                count += 1
                last_command = now
                goal = dict(zip(m.joint_names, point.positions))
                receipts.append([now, goal[joints[0]]])
                del receipts[:-300]
                duration = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
                segment = (list(q), [goal[j] for j in joints], now, duration)
                horizon = duration
                continue
            if len(m.data) != n:
                bad += 1
                continue
            count += 1
            last_command = now
            receipts.append([now, m.data[0]])
            del receipts[:-300]
            if a.mode == "velocity":
                v = [max(-a.max_velocity, min(a.max_velocity, x)) for x in m.data]
            else:
                target = list(m.data)
        dt = now - t_prev
        t_prev = now
        if a.mode == "velocity":
            if last_command is None or now - last_command > a.timeout:
                v = [0.0] * n
            q = [qi + vi * dt for qi, vi in zip(q, v)]
        elif a.mode == "trajectory":
            if segment is not None:
                start, goal, t0, duration = segment
                f = 1.0 if duration <= 0 else min(1.0, (now - t0) / duration)
                want = [s0 + (g - s0) * f for s0, g in zip(start, goal)]
                step = a.max_velocity * dt
                new_q = [qi + max(-step, min(step, w - qi)) for w, qi in zip(want, q)]
                v = [(nq - qi) / max(dt, 1e-6) for nq, qi in zip(new_q, q)]
                q = new_q
        elif target is not None:
            step = a.max_velocity * dt
            v = [max(-a.max_velocity, min(a.max_velocity, (t - qi) / max(dt, 1e-6))) for t, qi in zip(target, q)]
            q = [qi + max(-step, min(step, t - qi)) for t, qi in zip(target, q)]
        if now >= next_state:
            link.publish_state(
                now + a.offset, joints, q, [float("nan")] * n if a.no_velocity else v
            )
            next_state += period
            if next_state < now:
                next_state = now + period
        if now >= next_report:
            print(
                json.dumps(
                    {
                        "t": now,
                        "q": q,
                        "velocity": v,
                        "commands": count,
                        "bad": bad,
                        "receipts": receipts,
                        "horizon": horizon,
                        **link.report(),
                    }
                ),
                flush=True,
            )
            next_report = now + 0.05
        time.sleep(0.001)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        sys.exit(0)
