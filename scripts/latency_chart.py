#!/usr/bin/env python3
"""The stages of the real frame path, stacked, one bar per setting (docs/latency.md).

Reads the observer reports `scripts/latency.sh` wrote (out/latency_WxH/watch_D.json) and writes
an SVG of each setting's median stages (capture -> arrived -> read back -> coded and sent ->
network -> decoded, and -> presented where a window watched: out/latency_WxH_window/; the H.264
stream's from out/latency_WxH_h264/) and a CSV
beside it. Usage: scripts/latency_chart.py [OUT.svg] (default
out/latency_stages.svg). Python's standard library only.
"""
import csv
import glob
import json
import os
import re
import sys

STAGES = [
    ("arrive_ms", "capture → arrived", "#4e79a7"),
    ("app_ms", "arrived → read back", "#f28e2b"),
    ("encode_ms", "coded and sent", "#59a14f"),
    ("network_ms", "network", "#e15759"),
    ("decode_ms", "decoded", "#b07aa1"),
    ("display_ms", "decoded → presented (window)", "#9c755f"),
]


def settings():
    rows = []
    for path in sorted(glob.glob("out/latency_*/watch_*.json")):
        m = re.match(r"out/latency_(\d+)x(\d+)(_h264)?(_window)?/watch_(\d+)\.json", path)
        if not m:
            continue
        w, h, h264, window, delay = int(m[1]), int(m[2]), bool(m[3]), m[4], int(m[5])
        with open(path) as f:
            report = json.load(f)
        video = dict(report["video"])
        if window and report.get("window"):
            # The display stage, where a window watched (its frames shown, decoded -> presented).
            video["display_ms"] = report["window"]["display_ms"]
            video["glass_ms"] = report["window"]["glass_to_glass_ms"]
        label = (f"{w}x{h}, " + ("H.264, " if h264 else "") + f"{delay} ms one-way"
                 + (", window" if window else ""))
        rows.append((w * h, bool(window), h264, delay, label, video))
    rows.sort(key=lambda r: r[:4])
    return [(label, video) for *_, label, video in rows]


def med(v, key):
    """A stage's median, 0 where the setting has no such stage (no window)."""
    return v[key]["median"] if key in v else 0.0


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "out/latency_stages.svg"
    rows = settings()
    if not rows:
        sys.exit("no reports: run scripts/latency.sh first")
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    with open(os.path.splitext(out)[0] + ".csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["setting"] + [k for k, _, _ in STAGES]
                        + ["total_ms", "capture_to_presented_ms", "fps"])
        for label, v in rows:
            writer.writerow([label] + [f"{med(v, k):.1f}" for k, _, _ in STAGES]
                            + [f"{v['total_ms']['median']:.1f}",
                               f"{med(v, 'glass_ms'):.1f}" if "glass_ms" in v else "",
                               f"{v['fps']:.1f}"])
    left, bar, gap, width = 280, 28, 18, 560
    longest = max(sum(med(v, k) for k, _, _ in STAGES) for _, v in rows)
    scale = width / (longest * 1.08)
    height = 70 + len(rows) * (bar + gap) + 60
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + width + 140}" '
           f'height="{height}" font-family="sans-serif" font-size="12">',
           f'<rect width="100%" height="100%" fill="white"/>',
           f'<text x="10" y="22" font-size="15">The real frame path by stage (median ms): a '
           f'recorded camera through serve and a watcher</text>']
    y = 50
    for label, v in rows:
        svg.append(f'<text x="{left - 8}" y="{y + bar * 0.65}" text-anchor="end">{label}</text>')
        x = left
        for key, _, colour in STAGES:
            w = med(v, key) * scale
            svg.append(f'<rect x="{x:.1f}" y="{y}" width="{w:.1f}" height="{bar}" '
                       f'fill="{colour}"/>')
            x += w
        total = v["total_ms"]["median"]
        shown = f"{total:.0f} ms decoded"
        if "glass_ms" in v:
            shown += f", {med(v, 'glass_ms'):.0f} ms presented"
        svg.append(f'<text x="{x + 6:.1f}" y="{y + bar * 0.65}">{shown} '
                   f'({v["fps"]:.0f} fps)</text>')
        y += bar + gap
    x = 10
    for _, name, colour in STAGES:
        svg.append(f'<rect x="{x}" y="{y + 10}" width="12" height="12" fill="{colour}"/>')
        svg.append(f'<text x="{x + 16}" y="{y + 21}">{name}</text>')
        x += 24 + 7 * len(name)
    svg.append("</svg>")
    with open(out, "w") as f:
        f.write("\n".join(svg) + "\n")
    print(f"wrote {out} and {os.path.splitext(out)[0]}.csv")


if __name__ == "__main__":
    main()
