#!/usr/bin/env bash
# The erased video's latency by stage at 0, 50 and 150 ms one-way (docs/network.md): the robot
# site with video, an operator and an observer through `avatarm relay`; the observer's report
# has each stage. Needs a built target/debug/avatarm, or the binary AVATARM names (a release
# build on a machine with a GPU; headless NVIDIA there needs `. scripts/gpu_env.sh DIR` first).
# CODEC=h264 codes the video with H.264 (default jpeg). Output: out/network_latency_CODEC/.
set -euo pipefail
A=$(realpath "${AVATARM:-$(dirname "$0")/../target/debug/avatarm}")
cd "$(dirname "$0")/.."
[ -x "$A" ] || { echo "error: no avatarm binary at $A (cargo build)" >&2; exit 1; }
S=assets/scenes/pouring.toml
codec=${CODEC:-jpeg}
O=out/network_latency_$codec; rm -rf "$O"; mkdir -p "$O"
port=7600
for d in 0 50 150; do
  port=$((port+3))
  "$A" serve $S --insecure-lan --codec "$codec" --listen tcp/127.0.0.1:$port --duration 45 --report $O/serve_$d.json 2>$O/serve_$d.log &
  sp=$!
  "$A" relay --to 127.0.0.1:$port --delay-ms $d --duration 50 > $O/relay_$d.txt &
  sleep 1
  rp=$(sed -n 's#^tcp/127.0.0.1:\([0-9]*\) .*#\1#p' $O/relay_$d.txt)
  "$A" join tcp/127.0.0.1:$rp --watch --duration 40 --wait 30 --report $O/watch_$d.json 2>$O/watch_$d.log &
  wp=$!
  "$A" join tcp/127.0.0.1:$rp --wait 30 --report $O/join_$d.json 2>$O/join_$d.log
  wait $wp
  wait $sp
  python3 -c "
import json; v = json.load(open('$O/watch_$d.json'))['video']
print('$d ms:', ', '.join('%s %.1f/%.1f ms' % (k[:-3], v[k]['median'], v[k]['p95'])
      for k in ['erase_ms', 'encode_ms', 'network_ms', 'decode_ms', 'total_ms']),
      '%.1f fps %.2f Mbit/s, %d of %d shown' % (v['fps'], v['mbit_s'], v['shown'], v['frames']))"
done
