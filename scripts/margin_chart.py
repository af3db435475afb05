#!/usr/bin/env python3
"""Leak and overmask against the erase margin on the real Panda frames (docs/real-footage.md).

Imports ../shared/data/real/franka_easyhec, calibrates the camera on the frames that carry their
own joints (0, 1, 5), then replays the recording with that pose at each dilation of 0..12 px
and at the margin the calibration wrote (no --dilate). Writes out/margin/margin.csv and
out/margin/margin.svg: the mean leak and overmask (%) of frames 0, 1 and 5 against the
reference masks, per dilation, the calibration's margin marked. Python's standard library only.

Usage: scripts/margin_chart.py [AVATARM]   (default: the debug build)
"""
import csv
import json
import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
DATA = pathlib.Path(os.environ.get("AVATARM_SHARED_DATA", ROOT.parent / "shared" / "data"))
TARGET = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
AVATARM = sys.argv[1] if len(sys.argv) > 1 else str(TARGET / "debug" / "avatarm")
OUT = ROOT / "out" / "margin"
URDF = DATA / "ros/example-robot-data/robots/panda_description/urdf/panda.urdf"
GOOD = [0, 1, 5]
ROUGH = """camera_from_base:
  - [0.93969262, 0.34202009, 0.0, -0.64085639]
  - [0.17101002, -0.46984622, -0.86602539, 0.49582830]
  - [-0.29619810, 0.81379771, -0.49999991, 1.24120010]
  - [0, 0, 0, 1]
"""


def run(*args):
    done = subprocess.run([AVATARM, *map(str, args)], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"avatarm {args[0]} failed ({done.returncode}):\n{done.stderr[-2000:]}")


def replay(pose, out, dilate=None):
    extra = [] if dilate is None else ["--dilate", dilate]
    run("replay", "--recording", OUT / "panda.mcap", "--urdf", URDF, "--package-path",
        DATA / "ros", "--pose", pose, *extra, "--out", out)
    r = json.loads((out / "report.json").read_text())
    frames = [f for f in r["mask"]["vs_reference"]["per_frame"] if f["frame"] in GOOD]
    mean = lambda k: sum(f[k] for f in frames) / len(frames)
    return r["erase"]["dilate_px"], mean("leak_pct"), mean("overmask_pct")


def svg(rows, margin, path):
    """Leak (left axis, red) and overmask (right axis, blue) against the dilation."""
    w, h, left, right, bottom = 600, 320, 60, 60, 40
    most = max(r[0] for r in rows)
    tops = (max(max(r[1] for r in rows), 0.1), max(max(r[2] for r in rows), 1.0))
    xs = lambda d: left + (w - left - right) * d / most
    ys = lambda v, top: h - bottom - (h - bottom - 20) * v / top
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{left}" y1="{h - bottom}" x2="{w - right}" y2="{h - bottom}" stroke="black"/>',
           f'<text x="{w / 2}" y="{h - 8}" text-anchor="middle">mask dilation (px)</text>']
    for d in range(0, int(most) + 1, 2):
        out.append(f'<text x="{xs(d)}" y="{h - bottom + 15}" text-anchor="middle">{d}</text>')
    for i, (name, colour, x, anchor) in enumerate((
            ("leak (% of the robot, frames 0, 1, 5)", "#e15759", left, "end"),
            ("overmask (%)", "#4e79a7", w - right, "start"))):
        top = tops[i]
        out.append(f'<line x1="{x}" y1="20" x2="{x}" y2="{h - bottom}" stroke="{colour}"/>')
        for v in (0, top / 2, top):
            dx = -5 if anchor == "end" else 5
            out.append(f'<text x="{x + dx}" y="{ys(v, top) + 4}" text-anchor="{anchor}" fill="{colour}">{v:.1f}</text>')
        pts = " ".join(f"{xs(r[0])},{ys(r[1 + i], top)}" for r in rows)
        out.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
        out.append(f'<text x="{left + 10}" y="{34 + 16 * i}" fill="{colour}">{name}</text>')
    out.append(f'<line x1="{xs(margin)}" y1="20" x2="{xs(margin)}" y2="{h - bottom}" stroke="#59a14f" stroke-dasharray="4 3"/>')
    out.append(f'<text x="{xs(margin) + 4}" y="{h - bottom - 6}" fill="#59a14f">calibrated margin {margin} px</text>')
    out.append("</svg>")
    path.write_text("\n".join(out) + "\n")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "rough_pose.yaml").write_text(ROUGH)
    names = ",".join([f"panda_joint{i}" for i in range(1, 8)] + ["panda_finger_joint1", "panda_finger_joint2"])
    run("import", DATA / "real/franka_easyhec", "--out", OUT / "panda.mcap", "--pose",
        OUT / "rough_pose.yaml", "--joint-names", names)
    run("calibrate", "--recording", OUT / "panda.mcap", "--urdf", URDF, "--package-path",
        DATA / "ros", "--fit", "0-1,5", "--out", OUT / "calibrated")
    pose = OUT / "calibrated" / "camera_pose.yaml"
    margin, leak, over = replay(pose, OUT / "replay_margin")
    print(f"the calibration's margin: {margin} px: leak {leak:.2f} %, overmask {over:.1f} %")
    rows = []
    for d in range(0, 13):
        rows.append(replay(pose, OUT / f"replay_{d}", d))
        print(f"dilate {d:2} px: leak {rows[-1][1]:.2f} %, overmask {rows[-1][2]:.1f} %")
    with open(OUT / "margin.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["dilate_px", "leak_pct", "overmask_pct"])
        out.writerows(rows)
    svg(rows, margin, OUT / "margin.svg")
    print(f"wrote {OUT / 'margin.csv'} and {OUT / 'margin.svg'}")


if __name__ == "__main__":
    main()
