#!/usr/bin/env bash
# The erased video's codecs (docs/network.md, "The video's codecs"): replays the fast_motion
# scene (the arm moving fast, the robot erased) with its camera at 1280x720, recording every
# frame, then `avatarm bench video` codes the erased frames with JPEG and H.264 at 640x480 and
# 1280x720. Usage: scripts/video_codecs.sh [OUT] (default out/video_codecs); AVATARM names the
# binary (default target/debug/avatarm).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/video_codecs}
avatarm=${AVATARM:-target/debug/avatarm}
mkdir -p "$out"
root=$(pwd)
# The same camera at 1280x720: the vertical field of view kept (fx = fy = 360 / tan(27.5°)),
# 3.2 s of video (96 frames at 30 fps).
sed -e "s|\"\.\./robots/|\"$root/assets/robots/|" \
    -e 's|^intrinsics = {.*}|intrinsics = { fx = 691.5, fy = 691.5, cx = 639.5, cy = 359.5, width = 1280, height = 720 }|' \
    -e '0,/^duration_s = .*/s//duration_s = 3.2/' \
    assets/scenes/fast_motion.toml > "$out/fast_motion_720p.toml"
"$avatarm" replay "$out/fast_motion_720p.toml" --record "$out/fast_motion_720p.mcap" \
  --out "$out/replay" --frames-every 1000 > "$out/replay.log"
"$avatarm" bench video --recording "$out/fast_motion_720p.mcap" --out "$out" --frames 96 "${@:2}"
