#!/usr/bin/env bash
# The demo: the default scene in the desktop preview, or, without a display, a headless replay
# that writes frames and out/demo/report.json.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
if [ -n "${DISPLAY:-}" ] || [ -n "${WAYLAND_DISPLAY:-}" ]; then
  exec cargo run -- run assets/scenes/default.toml "$@"
else
  echo "no display: replaying the default scene headless into out/demo"
  cargo run -- replay assets/scenes/default.toml --headless --out out/demo --frames-every 15 "$@"
  cat out/demo/report.json
fi
