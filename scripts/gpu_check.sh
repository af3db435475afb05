#!/usr/bin/env bash
# The erase's figures on a hardware GPU, in one short run (docs/erase.md, "The erase against the
# memory floor"): `avatarm bench gpu` at 640x480, 1280x720 and 1920x1080 for one and two
# cameras, then the default scene replayed at 640x480 and at 1920x1080 for 1 s each. Run it on
# the machine with the GPU, with a built binary (no Rust needed there):
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
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv | tee "$out/gpu.txt"
short_scene() {  # the default scene cut to 1 s, its robot found from this checkout
  sed -e 's/duration_s = 10.0/duration_s = 1.0/' \
      -e "s#\"../robots/#\"$PWD/assets/robots/#" assets/scenes/default.toml > "$out/default_1s.toml"
}
short_scene
"$bin" bench gpu --frames 300 --out "$out/bench_gpu" 2>&1 | grep -v " INFO \| WARN " | tee "$out/bench_gpu.txt"
"$bin" bench gpu --frames 300 --dilate 4 --feather 2 --out "$out/bench_gpu_d4f2" 2>&1 \
  | grep -v " INFO \| WARN " | tee "$out/bench_gpu_d4f2.txt"
for size in 640x480 1920x1080; do
  "$bin" replay "$out/default_1s.toml" --headless --camera-size "$size" --frames-every 1000 \
    --out "$out/replay_$size" 2>&1 | grep "replayed" | tee -a "$out/replays.txt"
done
echo "gpu check: done; results in $out"
