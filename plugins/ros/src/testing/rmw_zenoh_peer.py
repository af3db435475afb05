#!/usr/bin/env python3
"""A ROS 2 peer on rmw_zenoh, written from rmw_zenoh's design document (ros2/rmw_zenoh,
docs/design.md, Jazzy) with PyPI's eclipse-zenoh and rosbags (CDR and REP-2016 type hashes),
not with anything of Avatarm's, so that what Avatarm sends is checked by what a ROS 2 node on
rmw_zenoh would key on:

- data on `<domain>/<fully qualified name>/<type as in DDS>/<RIHS01 hash>` (the hash from
  rosbags' Jazzy type store: a publisher or subscriber with another hash is not matched);
- CDR payloads with their encapsulation header;
- each sample's attachment: sequence number (int64 LE), source timestamp (int64 LE, ns),
  the GID's length (1 byte, 16) and the GID (16 bytes);
- a liveliness token per node (`NN`) and per publisher (`MP`) and subscription (`MS`):
  `@ros2_lv/<domain>/<session>/<node>/<entity>/<kind>/<enclave>/<namespace>/<node name>
  [/<mangled topic>/<type>/<hash>/<qos>]`, `/` mangled to `%`.

`python3 rmw_zenoh_peer.py router --listen tcp/127.0.0.1:PORT` runs a Zenoh router (what
`ros2 run rmw_zenoh_cpp rmw_zenohd` is to ROS 2 nodes on rmw_zenoh) until killed.
"""

import argparse
import json
import os
import struct
import threading
import time

import numpy
import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

TYPES = get_typestore(Stores.ROS2_JAZZY)

# The QoS field of a liveliness token (rmw_zenoh's compact form) for ROS 2's default profile:
# reliable, volatile, keep last 10; and for a latched one (transient local, keep last 1).
DEFAULT_QOS = "::,10:,:,:,,"
LATCHED_QOS = ":1:,1:,:,:,,"


def ros_time(seconds):
    """builtin_interfaces/msg/Time of `seconds` since the epoch."""
    sec = int(seconds // 1)
    return TYPES.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((seconds - sec) * 1e9))


def float64s(values):
    """A float64[] field's value (rosbags takes numpy arrays)."""
    return numpy.array(values, dtype=numpy.float64)


def dds_type(ros_type):
    """`pkg/msg/Name` -> `pkg::msg::dds_::Name_` (the type name as declared in DDS)."""
    package, kind, name = ros_type.split("/")
    return "%s::%s::dds_::%s_" % (package, kind, name)


def mangle(name):
    """A name in a liveliness token: `/` replaced by `%` (`%` alone when empty)."""
    return name.replace("/", "%") if name else "%"


def qualified(namespace, topic):
    """The fully qualified name of `topic` in `namespace`, without its leading `/`."""
    if topic.startswith("/"):
        return topic.strip("/")
    return ("%s/%s" % (namespace.strip("/"), topic)).strip("/")


def attachment(sequence, gid):
    """rmw_zenoh's attachment: sequence number, source timestamp (ns), GID length, GID."""
    return struct.pack("<qqB16s", sequence, time.time_ns(), len(gid), gid)


def parse_attachment(data):
    """(sequence, timestamp ns, gid) from an attachment, or None if it is not one."""
    if data is None or len(data) != 33 or data[16] != 16:
        return None
    sequence, stamp = struct.unpack_from("<qq", data)
    return sequence, stamp, data[17:]


def session(router):
    """A Zenoh session as rmw_zenoh opens one: a peer connected to the router, no multicast,
    samples timestamped (what a publication cache needs)."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps([router]))
    config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("timestamping/enabled", "true")
    return zenoh.open(config)


class Node:
    """A ROS 2 node on rmw_zenoh: its session, its token, its publishers and subscriptions."""

    def __init__(self, router, domain, name, namespace="/"):
        self.session = session(router)
        self.domain = domain
        self.name = name
        self.namespace = namespace
        self.zid = str(self.session.info.zid())
        self._next_entity = 10
        self._tokens = [self._token("0", "NN")]

    def _token(self, entity, kind, topic=None, ros_type=None, qos=DEFAULT_QOS):
        key = "@ros2_lv/%d/%s/0/%s/%s/%%/%s/%s" % (
            self.domain,
            self.zid,
            entity,
            kind,
            mangle(self.namespace.strip("/") and "/" + self.namespace.strip("/")),
            self.name,
        )
        if topic is not None:
            key += "/%s/%s/%s/%s" % (
                mangle("/" + qualified(self.namespace, topic)),
                dds_type(ros_type),
                TYPES.hash_rihs01(ros_type),
                qos,
            )
        return self.session.liveliness().declare_token(key)

    def key(self, topic, ros_type):
        """The key expression of `topic` carrying `ros_type`."""
        return "%d/%s/%s/%s" % (
            self.domain,
            qualified(self.namespace, topic),
            dds_type(ros_type),
            TYPES.hash_rihs01(ros_type),
        )

    def _entity(self, kind, topic, ros_type, qos=DEFAULT_QOS):
        entity = str(self._next_entity)
        self._next_entity += 1
        self._tokens.append(self._token(entity, kind, topic, ros_type, qos))

    def publisher(self, topic, ros_type, latched=False):
        """A publisher; `latched` (transient local, as tf2's static broadcaster): Zenoh's
        advanced publisher keeping its last sample for late subscribers, which rmw_zenoh's
        transient-local subscriptions query (the design document's Quality of Service)."""
        key = self.key(topic, ros_type)
        if latched:
            self._entity("MP", topic, ros_type, LATCHED_QOS)
            publisher = zenoh.ext.declare_advanced_publisher(
                self.session,
                key,
                cache=zenoh.ext.CacheConfig(max_samples=1),
                publisher_detection=True,
            )
        else:
            self._entity("MP", topic, ros_type)
            publisher = self.session.declare_publisher(key)
        return Publisher(publisher, ros_type)

    def subscription(self, topic, ros_type):
        self._entity("MS", topic, ros_type)
        return Subscription(self.session, self.key(topic, ros_type), ros_type)

    def graph(self):
        """The liveliness tokens alive on this domain (every node's, this one's included)."""
        return Graph(self.session, self.domain)


class Publisher:
    def __init__(self, publisher, ros_type):
        self._publisher = publisher
        self._type = ros_type
        self._sequence = 0
        self._gid = os.urandom(16)

    def publish(self, message):
        self._sequence += 1
        payload = bytes(TYPES.serialize_cdr(message, self._type))
        self._publisher.put(payload, attachment=attachment(self._sequence, self._gid))


class Subscription:
    """Samples decoded as they arrive; `take()` returns those not yet taken. Samples whose
    attachment is missing or malformed are counted (`no_attachment`), those that do not decode
    too (`undecodable`)."""

    def __init__(self, zenoh_session, key, ros_type):
        self._type = ros_type
        self._lock = threading.Lock()
        self._queue = []
        self.no_attachment = 0
        self.undecodable = 0
        self._subscriber = zenoh_session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample):
        raw = sample.attachment.to_bytes() if sample.attachment is not None else None
        try:
            message = TYPES.deserialize_cdr(sample.payload.to_bytes(), self._type)
        except Exception:  # noqa: BLE001 - any decoding failure is the sender's fault
            with self._lock:
                self.undecodable += 1
            return
        with self._lock:
            if parse_attachment(raw) is None:
                self.no_attachment += 1
            self._queue.append(message)

    def take(self):
        with self._lock:
            taken, self._queue = self._queue, []
        return taken


class Graph:
    """The liveliness tokens alive on a domain (rmw_zenoh's graph), kept up to date."""

    def __init__(self, zenoh_session, domain):
        self._lock = threading.Lock()
        self._alive = set()
        self._subscriber = zenoh_session.liveliness().declare_subscriber(
            "@ros2_lv/%d/**" % domain, self._on_token, history=True
        )

    def _on_token(self, sample):
        key = str(sample.key_expr)
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(key)
            else:
                self._alive.discard(key)

    def alive(self):
        with self._lock:
            return sorted(self._alive)


def main():
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("router", help="run a Zenoh router until killed")
    r.add_argument("--listen", required=True)
    a = p.parse_args()
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([a.listen]))
    config.insert_json5("scouting/multicast/enabled", "false")
    router = zenoh.open(config)
    print(json.dumps({"router": a.listen, "zid": str(router.info.zid())}), flush=True)
    while True:
        time.sleep(1)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        pass
