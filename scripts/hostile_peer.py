#!/usr/bin/env python3
"""A hostile peer for `avatarm serve`, written against docs/network.md only (PyPI's
eclipse-zenoh, not Avatarm's code): it logs in with the operator's credentials over the given
endpoint (tcp/, tls/ or quic/) and puts bad targets on `avatarm/<site>/operator/target`, a
burst now and then, while the real operator (`avatarm join`) sends valid ones.

Each kind of bad target must be refused by the robot site with the arm stopped, never crash it
nor reach the robot (scripts/hostile_serve.sh runs it beside serve and join).

Usage: hostile_peer.py ENDPOINT --user U --password P [--ca CA.pem] [--site desk]
       [--seconds 60] [--every-s 2.0]
Prints one JSON line at the end: what it put, by kind.
"""

import argparse
import json
import os
import random
import sys
import time

import zenoh


def bad_targets(rng):
    """(kind, payload) pairs: each one the robot site must refuse."""
    good = {
        "v": 6,
        "seq": rng.randrange(1, 1 << 40),
        "stamp_s": 1.0,
        "hand_stamp_s": 1.0,
        "hand_tracked": True,
        "position": [0.6, 0.0, 0.9],
        "rotation_xyzw": [0.0, 0.0, 0.0, 1.0],
        "object_twist": [0.0] * 6,
        "twin_twist": [0.0] * 6,
        "squeeze_n": 1.0,
        "rank": 6,
        "contacts": 2,
        "held": True,
    }

    def with_(**changes):
        m = dict(good)
        m.update(changes)
        return json.dumps(m).encode()

    deep = ("[" * 2000 + "]" * 2000).encode()
    return [
        ("random bytes", os.urandom(rng.randrange(1, 512))),
        ("empty", b""),
        ("not an object", b"[1, 2, 3]"),
        ("2000-deep JSON", deep),
        ("10 MB", b"{" + b" " * (10 << 20) + b"}"),
        ("NaN position", with_(position=[float("nan"), 0.0, 0.9])),
        ("1e999", json.dumps(good).replace('"squeeze_n": 1.0', '"squeeze_n": 1e999').encode()),
        ("zero quaternion", with_(rotation_xyzw=[0.0, 0.0, 0.0, 0.0])),
        ("100 m away", with_(position=[100.0, 0.0, 0.9])),
        ("foreign version", with_(v=999)),
        ("stamped 5 s ahead", with_(stamp_s=1e9)),
        ("stamp 1e300", with_(stamp_s=1e300, hand_stamp_s=1e300)),
        ("unknown field", with_(extra=1)),
        ("missing field", json.dumps({k: v for k, v in good.items() if k != "position"}).encode()),
    ]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("endpoint")
    p.add_argument("--user", required=True)
    p.add_argument("--password", required=True)
    p.add_argument("--ca")
    p.add_argument("--site", default="desk")
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--every-s", type=float, default=2.0)
    p.add_argument("--seed", type=int, default=7)
    a = p.parse_args()
    link = {}
    if a.ca:
        link = {"tls": {"root_ca_certificate": a.ca}}
    conf = {
        "mode": "client",
        "connect": {"endpoints": [a.endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {
            "auth": {"usrpwd": {"user": a.user, "password": a.password}},
            "link": link,
        },
    }
    session = zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))
    key = f"avatarm/{a.site}/operator/target"
    rng = random.Random(a.seed)
    put = {}
    end = time.time() + a.seconds
    while time.time() < end:
        # A burst of every kind, then quiet: the robot site must stop the arm for each, and
        # resume with the operator's next valid target.
        for kind, payload in bad_targets(rng):
            session.put(key, payload)
            put[kind] = put.get(kind, 0) + 1
            time.sleep(0.02)
        time.sleep(a.every_s)
    session.close()
    print(json.dumps({"put": put, "total": sum(put.values())}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
