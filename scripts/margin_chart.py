#!/usr/bin/env python3
"""Leak and overmask against the erase margin on the real Panda frames (docs/real-footage.md).

Imports ../shared/data/real/franka_easyhec, calibrates the camera (which drops the frames whose
joints are another's and fits on those that carry their own, 0, 1, 5), then replays the
recording with that pose at each dilation of 0..12 px and at the margin the calibration wrote
(no --dilate), each with the margin's band refined to the frame (--refine-edges on) and
without. Writes out/margin/margin.csv and
out/margin/margin.svg: the mean leak and overmask (%) of frames 0, 1 and 5 against the
reference masks, and the rim the report measures without them, per dilation, the calibration's
margin marked. Python's standard library only.

Usage: scripts/margin_chart.py [AVATARM]   (default: the debug build)
"""
import csv
import json
import os
import pathlib
import struct
import subprocess
import sys
import zlib

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


def replay(pose, out, dilate=None, refine="on"):
    """The dilation used, and over frames 0, 1, 5: leak, overmask, rim (%)."""
    extra = [] if dilate is None else ["--dilate", dilate]
    run("replay", "--recording", OUT / "panda.mcap", "--urdf", URDF, "--package-path",
        DATA / "ros", "--pose", pose, *extra, "--photometric", "on", "--refine-edges", refine,
        "--out", out)
    r = json.loads((out / "report.json").read_text())
    frames = [f for f in r["mask"]["vs_reference"]["per_frame"] if f["frame"] in GOOD]
    if not frames or not r["mask"].get("rim"):
        sys.exit(f"{out}: no reference-scored frame among {GOOD}, or no rim measured")
    rims = [f["rim_pct"] for f in r["mask"]["rim"]["per_frame"] if f["frame"] in GOOD]
    mean = lambda k: sum(f[k] for f in frames) / len(frames)
    return (r["erase"]["dilate_px"], mean("leak_pct"), mean("overmask_pct"),
            sum(rims) / max(len(rims), 1))


def read_png(path):
    """An 8-bit, non-interlaced RGB or RGBA PNG as (width, height, rows of RGB bytes)."""
    data = pathlib.Path(path).read_bytes()
    pos, idat, (w, h, channels) = 8, b"", (0, 0, 0)
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, colour = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and colour in (2, 6) and body[12] == 0, f"{path}: 8-bit, non-interlaced RGB(A) only"
            channels = 3 if colour == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw, stride, rows, prev = zlib.decompress(idat), w * channels, [], bytearray(w * channels)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b, c = prev[i], prev[i - channels] if i >= channels else 0
            p = a + b - c
            pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
            pred = (0, a, b, (a + b) // 2, a if pa <= pb and pa <= pc else b if pb <= pc else c)[f]
            line[i] = (line[i] + pred) & 255
        prev = line
        rows.append(bytes(v for i, v in enumerate(line) if channels == 3 or i % 4 != 3))
    return w, h, rows


def write_png(path, w, h, rows):
    chunk = lambda kind, body: struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    raw = b"".join(b"\0" + r for r in rows)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def strip(paths, box, path):
    """The same crop (x0, y0, x1, y1) of each image, side by side, 4 px of white between."""
    x0, y0, x1, y1 = box
    gap = b"\xff" * 12
    rows = [b"" for _ in range(y1 - y0)]
    for k, p in enumerate(paths):
        _, _, img = read_png(p)
        for y in range(y0, y1):
            rows[y - y0] += (gap if k else b"") + img[y][3 * x0:3 * x1]
    write_png(path, len(paths) * (x1 - x0) + 4 * (len(paths) - 1), y1 - y0, rows)


def svg(rows, margin, path):
    """Leak (left axis, red) and overmask (right axis, blue) against the dilation."""
    w, h, left, right, bottom = 600, 320, 60, 60, 40
    most = max(r[0] for r in rows)
    xs = lambda d: left + (w - left - right) * d / most
    ys = lambda v, top: h - bottom - (h - bottom - 20) * v / top
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{left}" y1="{h - bottom}" x2="{w - right}" y2="{h - bottom}" stroke="black"/>',
           f'<text x="{w / 2}" y="{h - 8}" text-anchor="middle">mask dilation (px)</text>']
    for d in range(0, int(most) + 1, 2):
        out.append(f'<text x="{xs(d)}" y="{h - bottom + 15}" text-anchor="middle">{d}</text>')
    tops = (max(max(max(r[1], r[4]) for r in rows), 0.1),
            max(max(max(r[2], r[5]) for r in rows), 1.0))
    for i, (name, colour, x, anchor) in enumerate((
            ("leak (% of the robot, frames 0, 1, 5)", "#e15759", left, "end"),
            ("overmask (%)", "#4e79a7", w - right, "start"))):
        top = tops[i]
        pts = " ".join(f"{xs(r[0])},{ys(r[4 + i], top)}" for r in rows)
        out.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2" stroke-dasharray="6 3"/>')
        out.append(f'<line x1="{x}" y1="20" x2="{x}" y2="{h - bottom}" stroke="{colour}"/>')
        for v in (0, top / 2, top):
            dx = -5 if anchor == "end" else 5
            out.append(f'<text x="{x + dx}" y="{ys(v, top) + 4}" text-anchor="{anchor}" fill="{colour}">{v:.1f}</text>')
        pts = " ".join(f"{xs(r[0])},{ys(r[1 + i], top)}" for r in rows)
        out.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="2"/>')
        out.append(f'<text x="{left + 10}" y="{34 + 16 * i}" fill="{colour}">{name}</text>')
    out.append(f'<text x="{left + 10}" y="66" fill="#555">dashed: the band refined to the frame (--refine-edges on)</text>')
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
        DATA / "ros", "--out", OUT / "calibrated")
    pose = OUT / "calibrated" / "camera_pose.yaml"
    for refine in ("off", "on"):
        margin, leak, over, rim = replay(pose, OUT / f"replay_margin_{refine}", refine=refine)
        print(f"the calibration's margin: {margin} px, band refined {refine}: leak {leak:.3f} %, overmask {over:.1f} %, rim {rim:.2f} %")
    rows = []
    for d in range(0, 13):
        plain = replay(pose, OUT / f"replay_{d}", d, "off")
        refined = replay(pose, OUT / f"replay_{d}_refined", d, "on")
        rows.append((d, *plain[1:], *refined[1:]))
        print(f"dilate {d:2} px: leak {plain[1]:.3f} / {refined[1]:.3f} %, overmask {plain[2]:.1f} / {refined[2]:.1f} %, rim {plain[3]:.2f} / {refined[3]:.2f} % (margin alone / refined)")
    with open(OUT / "margin.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["dilate_px", "leak_pct", "overmask_pct", "rim_pct", "refined_leak_pct",
                      "refined_overmask_pct", "refined_rim_pct"])
        out.writerows([[f"{v:.4f}" if isinstance(v, float) else v for v in r] for r in rows])
    svg(rows, margin, OUT / "margin.svg")
    # Frame 5 (its own joints): the frame, erased with no dilation (the rim), with the
    # calibration's margin alone, and with the band refined.
    strip([DATA / "real/franka_easyhec/color/000005.png", OUT / "replay_0" / "erased_00005.png",
           OUT / "replay_margin_off" / "erased_00005.png",
           OUT / "replay_margin_on" / "erased_00005.png"], (0, 80, 320, 480), OUT / "frame5.png")
    print(f"wrote {OUT / 'margin.csv'} and {OUT / 'margin.svg'}")


if __name__ == "__main__":
    main()
