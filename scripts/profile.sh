#!/usr/bin/env bash
# A Chrome trace of the robot site's updates (Bevy's spans: every system, schedule and render
# step) and where its milliseconds go (docs/latency.md, "Profile"). Needs an avatarm built with
# the trace feature: `cargo build --features trace`, the binary in AVATARM (default
# target/debug/avatarm). SOURCE=recorded (default: a second of the pouring scene recorded by the
# replay, served as a live camera) or sim (the simulated room's camera); SECONDS_WATCHED (default
# 12) with one `join --watch` on loopback. SOURCE=replay traces the headless replay of the
# pouring scene instead, and SOURCE=run the desktop preview of the default scene under Xvfb
# (FRAMES, default 120). Output: out/profile_SOURCE/ (trace.json, which chrome://tracing or
# ui.perfetto.dev opens, and summary.txt).
set -euo pipefail
A=$(realpath "${AVATARM:-$(dirname "$0")/../target/debug/avatarm}")
cd "$(dirname "$0")/.."
[ -x "$A" ] || { echo "error: no avatarm binary at $A (cargo build --features trace)" >&2; exit 1; }
source=${SOURCE:-recorded}
if [ "$source" = replay ] || [ "$source" = run ]; then
  O=out/profile_$source; rm -rf "$O"; mkdir -p "$O"
  export AVATARM_TRACE_CHROME=$O/trace.json
  if [ "$source" = replay ]; then
    cmd=("$A" replay assets/scenes/pouring.toml --out $O/replay)
  else
    # No OpenXR runtime: the preview, not a headset.
    cmd=(env XR_RUNTIME_JSON=$O/no_runtime.json xvfb-run -a -s "-screen 0 1280x720x24"
      "$A" run --frames "${FRAMES:-120}")
  fi
  "${cmd[@]}" > $O/$source.log 2>&1 || { tail -n 20 $O/$source.log >&2; exit 1; }
  # These runs are short: only their first second (start-up, pipelines compiling) is left out.
  python3 scripts/profile_summary.py $O/trace.json --top 25 --skip-s "${SKIP_S:-1}" | tee $O/summary.txt
  exit 0
fi
watched=${SECONDS_WATCHED:-12}
O=out/profile_$source; rm -rf "$O"; mkdir -p "$O"
S=$O/scene.toml
sed -e "s#\.\./robots/#$PWD/assets/robots/#" -e '0,/^duration_s = 2.0/s//duration_s = 1.0/' \
  assets/scenes/pouring.toml > "$S"
camera=()
if [ "$source" = recorded ]; then
  "$A" replay "$S" --record $O/session.mcap --out $O/replay > $O/replay.log 2>&1
  camera=(--camera-recording $O/session.mcap --background $O/replay/background.png)
fi
port=7790
AVATARM_TRACE_CHROME=$O/trace.json "$A" serve "$S" --insecure-lan --listen tcp/127.0.0.1:$port \
  "${camera[@]}" --duration $((watched + 8)) --report $O/serve.json 2>$O/serve.log &
sp=$!
sleep 1
"$A" join tcp/127.0.0.1:$port --scene "$S" --watch --duration $watched --wait 30 \
  --report $O/watch.json 2>$O/watch.log
wait $sp
python3 scripts/profile_summary.py $O/trace.json --top 25 | tee $O/summary.txt
