#!/usr/bin/env python3
"""Where an update's milliseconds go, from a Chrome trace of Bevy's spans.

Usage: scripts/profile_summary.py TRACE.json [--top N] [--skip-s S]

The trace comes from an avatarm built with the `trace` feature and run with
AVATARM_TRACE_CHROME=TRACE.json (docs/latency.md, "Profile"). Spans are keyed by their name and
their `name` field (Bevy's "system", "schedule" and "sub app" spans carry one). Printed: the
main world's and each sub app's update time (median, p95 per update), then the spans that cost
the most per update (total time over the updates counted), with their median per occurrence.
The first S seconds (default 5: start-up, pipelines compiling) are left out.
"""
import argparse
import json
import statistics
from collections import defaultdict


WRAPPERS = {"main app", "render thread", "multithreaded executor"}


def load(path):
    with open(path) as f:
        text = f.read().strip()
    # tracing-chrome closes the array when it flushes; a killed process leaves it open.
    if not text.endswith("]"):
        text = text.rstrip(",\n") + "]"
    return json.loads(text)


def key(event):
    args = event.get("args") or {}
    name = args.get("name")
    return f"{event['name']} {name}" if name else event["name"]


def spans(events):
    """(key, thread, start µs, duration µs) of every complete span."""
    open_ = defaultdict(list)
    out = []
    for e in events:
        ph = e.get("ph")
        if ph == "X":
            out.append((key(e), e.get("tid"), e["ts"], e.get("dur", 0.0)))
        elif ph == "B":
            open_[(e.get("tid"), e["name"])].append(e)
        elif ph == "E":
            stack = open_.get((e.get("tid"), e["name"]))
            if stack:
                b = stack.pop()
                out.append((key(b), b.get("tid"), b["ts"], e["ts"] - b["ts"]))
    return out


def pct(values, p):
    values = sorted(values)
    return values[min(len(values) - 1, int(p * (len(values) - 1) + 0.5))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("trace")
    ap.add_argument("--top", type=int, default=20)
    ap.add_argument("--skip-s", type=float, default=5.0)
    a = ap.parse_args()
    all_spans = spans(load(a.trace))
    if not all_spans:
        raise SystemExit(f"{a.trace}: no spans (built without the trace feature?)")
    t0 = min(s[2] for s in all_spans) + a.skip_s * 1e6
    kept = [s for s in all_spans if s[2] >= t0]
    updates = [s for s in kept if s[0] == "main app"]
    n = max(1, len(updates))
    print(f"{a.trace}: {len(kept)} spans after the first {a.skip_s:g} s, {len(updates)} main-world updates")
    for k in sorted({s[0] for s in kept if s[0] == "main app" or s[0].startswith("sub app")}):
        d = [s[3] / 1e3 for s in kept if s[0] == k]
        print(f"  {k}: {len(d)} times, median {statistics.median(d):.2f} ms, p95 {pct(d, 0.95):.2f} ms")
    by_key = defaultdict(list)
    for s in kept:
        # Wrappers: their children are listed.
        if s[0] in WRAPPERS or s[0].startswith(("sub app", "schedule")):
            continue
        by_key[s[0]].append(s[3] / 1e3)
    rows = sorted(by_key.items(), key=lambda kv: -sum(kv[1]))[: a.top]
    print(f"  the {len(rows)} costliest spans (ms per main-world update; median per occurrence):")
    for k, d in rows:
        print(f"    {sum(d) / n:8.3f}  {statistics.median(d):8.3f}  x{len(d) / n:5.2f}  {k}")


if __name__ == "__main__":
    main()
