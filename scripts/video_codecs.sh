#!/usr/bin/env bash
# The erased video's codecs (docs/network.md, "The video's codecs"): replays the fast_motion
# scene (the arm moving fast, the robot erased) with its camera at 1280x720, recording every
# frame, then `avatarm bench video` codes its erased frames and its camera frames with JPEG and
# H.264 at 640x480 and 1280x720. Usage: scripts/video_codecs.sh [OUT] (default out/video_codecs); AVATARM names the
# binary (default target/debug/avatarm).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/video_codecs}
avatarm=${AVATARM:-target/debug/avatarm}
mkdir -p "$out"
# The scene's camera at 1280x720, its vertical field of view kept; 4.5 s of video at 30 fps,
# of which the bench codes the first 96 frames.
"$avatarm" replay assets/scenes/fast_motion.toml --camera-size 1280x720 \
  --record "$out/fast_motion_720p.mcap" --out "$out/replay" --frames-every 1000 > "$out/replay.log"
"$avatarm" bench video --recording "$out/fast_motion_720p.mcap" --out "$out" --frames 96 "${@:2}"
