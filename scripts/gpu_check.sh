#!/usr/bin/env bash
# The erase's figures on a hardware GPU, in one short run (docs/erase.md, "The erase against the
# memory floor"): `avatarm bench gpu` at 640x480, 1280x720 and 1920x1080 for one and two
# cameras (once as it is, once with a light load holding the GPU's clock up), then the default
# scene replayed at 640x480 and at 1920x1080 for 1 s each, and the live preview at 1080p where
# Xvfb is installed. Run it on the machine with the GPU, with a built binary (no Rust needed
# there):
#
#   scripts/gpu_check.sh [BINARY] [OUT]      # defaults: target/release/avatarm, out/gpu_check
#
# A GPU at its idle clock under this light load is not at its floor: the bench reads the SM
# clock with nvidia-smi before and after each point and writes it beside the figures.
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-target/release/avatarm}"
out="${2:-out/gpu_check}"
mkdir -p "$out"
[ -x "$bin" ] || { echo "error: no avatarm binary at $bin (cargo build --release)" >&2; exit 1; }
# Headless NVIDIA Vulkan and the loader check (sets VK_ICD_FILENAMES where it must).
. scripts/gpu_env.sh "$out"
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv | tee "$out/gpu.txt"
short_scene() {  # the default scene cut to 1 s, its robot found from this checkout
  sed -e 's/duration_s = 10.0/duration_s = 1.0/' \
      -e "s#\"../robots/#\"$PWD/assets/robots/#" assets/scenes/default.toml > "$out/default_1s.toml"
}
short_scene
"$bin" bench gpu --frames 300 --out "$out/bench_gpu" 2>&1 | grep -v " INFO \| WARN " | tee "$out/bench_gpu.txt"
"$bin" bench gpu --frames 300 --dilate 4 --feather 2 --out "$out/bench_gpu_d4f2" 2>&1 \
  | grep -v " INFO \| WARN " | tee "$out/bench_gpu_d4f2.txt"
# The same bench with the GPU's clock held up by a light load beside it (a 640x480 replay of the
# default scene, looping), as a headset's compositor would: the SM clock is written beside each
# point, so the two runs say what the clock costs.
sed -e 's/duration_s = 10.0/duration_s = 60.0/' \
    -e "s#\"../robots/#\"$PWD/assets/robots/#" assets/scenes/default.toml > "$out/default_60s.toml"
# In its own process group, so that the loop and the replay it runs stop together.
setsid bash -c 'while :; do "$0" replay "$1" --headless --frames-every 100000 --out "$2" \
  >/dev/null 2>&1; done' "$bin" "$out/default_60s.toml" "$out/load" &
load=$!
trap 'kill -- -"$load" 2>/dev/null || true' EXIT
sleep 5
"$bin" bench gpu --frames 300 --out "$out/bench_gpu_loaded" 2>&1 | grep -v " INFO \| WARN " \
  | tee "$out/bench_gpu_loaded.txt"
kill -- -"$load" 2>/dev/null || true
wait "$load" 2>/dev/null || true
trap - EXIT
for size in 640x480 1920x1080; do
  "$bin" replay "$out/default_1s.toml" --headless --camera-size "$size" --frames-every 1000 \
    --out "$out/replay_$size" 2>&1 | grep "replayed" | tee -a "$out/replays.txt"
done
# Alice's head camera: its view-following background on one CPU thread and on all.
scripts/head_threads.sh "$bin" "$out/head" || echo "head camera replays failed; see $out/head" >&2
# The live preview's frame at 1080p, where a display server is at hand (Xvfb): its budget line.
if command -v Xvfb >/dev/null; then
  Xvfb :77 -screen 0 1920x1080x24 >/dev/null 2>&1 & xvfb=$!
  sleep 2
  DISPLAY=:77 timeout 120 "$bin" run "$out/default_1s.toml" --frames 60 --camera-size 1920x1080 \
    2>&1 | grep -i "budget\|error" | tee "$out/preview_1080p.txt" || true
  kill "$xvfb" 2>/dev/null || true
else
  echo "no Xvfb: the live preview was not run" | tee "$out/preview_1080p.txt"
fi
echo "gpu check: done; results in $out"
