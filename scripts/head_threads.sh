#!/usr/bin/env bash
# Alice's head camera (docs/alice-view.md, "Frame cost"): `assets/scenes/head_camera.toml`
# replayed headless twice in one run, its view-following background re-projected on one CPU
# thread and then on one per core (`[camera.head.background] threads`); prints each replay's
# speed and the background's CPU time per frame (median and 95th percentile, ms). A GPU
# machine runs it from scripts/gpu_check.sh; no Rust is needed, only a built binary:
#
#   scripts/head_threads.sh [BINARY] [OUT]      # defaults: target/release/avatarm, out/head_threads
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-target/release/avatarm}"
out="${2:-out/head_threads}"
mkdir -p "$out"
[ -x "$bin" ] || { echo "error: no avatarm binary at $bin (cargo build --release)" >&2; exit 1; }
. scripts/gpu_env.sh "$out"
for threads in 1 0; do
  sed -e "s#\"../robots/#\"$PWD/assets/robots/#" \
      -e "s#^\[erase\]#[camera.head.background]\nthreads = $threads\n\n[erase]#" \
      assets/scenes/head_camera.toml > "$out/head_threads_$threads.toml"
  grep -q "^threads = $threads\$" "$out/head_threads_$threads.toml" \
    || { echo "error: no [erase] table in head_camera.toml to set the threads before" >&2; exit 1; }
  "$bin" replay "$out/head_threads_$threads.toml" --headless --frames-every 1000 \
    --out "$out/head_threads_$threads" 2>&1 | grep "replayed" | tee -a "$out/head.txt"
  printf 'threads %s (0: one per core; nproc says %s): ' "$threads" "$(nproc)" | tee -a "$out/head.txt"
  { grep -A2 '"cpu_ms"' "$out/head_threads_$threads/report.json" || echo "no cpu_ms"; } \
    | tr -d ' \n' | tee -a "$out/head.txt"
  echo | tee -a "$out/head.txt"
done
