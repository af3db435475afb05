#!/usr/bin/env bash
# The real frame path's latency by stage (docs/latency.md): a second of the pouring scene
# recorded by the replay, played as the robot site's camera (`serve --camera-recording`), an
# operator and an observer through `avatarm relay` at each one-way delay; the observer's and
# the site's reports give each stage. Needs a built avatarm (target/debug/avatarm, or the binary
# AVATARM names; headless NVIDIA needs `. scripts/gpu_env.sh DIR` first). SIZE=WxH records and
# serves at another camera size (e.g. 1920x1080); DELAYS lists the one-way delays in ms (default
# "0 25"); SECONDS_WATCHED how long the observer watches (default 15); WINDOW=1 watches in
# `join --window` under xvfb-run (the display stage: decoded -> presented, and glass to glass);
# CODEC=h264 sends the H.264 stream (`serve --codec h264`) instead of JPEG.
# Output: out/latency_WxH/ (with _h264 after it for H.264, _window after that with WINDOW=1).
set -euo pipefail
A=$(realpath "${AVATARM:-$(dirname "$0")/../target/debug/avatarm}")
cd "$(dirname "$0")/.."
[ -x "$A" ] || { echo "error: no avatarm binary at $A (cargo build)" >&2; exit 1; }
size=${SIZE:-640x480}
watched=${SECONDS_WATCHED:-15}
codec=${CODEC:-jpeg}
case "$codec" in jpeg | h264) ;; *) echo "error: CODEC=$codec: expected jpeg or h264" >&2; exit 1 ;; esac
O=out/latency_$size; [ "$codec" = h264 ] && O=${O}_h264; [ "${WINDOW:-0}" = 1 ] && O=${O}_window
rm -rf "$O"; mkdir -p "$O"
S=$O/scene.toml
# The pouring scene, a second long, its robot by absolute path.
sed -e "s#\.\./robots/#$PWD/assets/robots/#" -e '0,/^duration_s = 2.0/s//duration_s = 1.0/' \
  assets/scenes/pouring.toml > "$S"
sizes=(); [ "$size" = 640x480 ] || sizes=(--camera-size "$size")
"$A" replay "$S" "${sizes[@]}" --record $O/session.mcap --out $O/replay > $O/replay.log 2>&1
port=7700
for d in ${DELAYS:-0 25}; do
  port=$((port+3))
  "$A" serve "$S" "${sizes[@]}" --codec "$codec" --insecure-lan --listen tcp/127.0.0.1:$port \
    --camera-recording $O/session.mcap --background $O/replay/background.png \
    --duration $((watched + 20)) --report $O/serve_$d.json 2>$O/serve_$d.log &
  sp=$!
  "$A" relay --to 127.0.0.1:$port --delay-ms $d --duration $((watched + 25)) > $O/relay_$d.txt &
  sleep 1
  rp=$(sed -n 's#^tcp/127.0.0.1:\([0-9]*\) .*#\1#p' $O/relay_$d.txt)
  win=(); pre=()
  if [ "${WINDOW:-0}" = 1 ]; then win=(--window); pre=(xvfb-run -a -s "-screen 0 1280x720x24"); fi
  "${pre[@]}" "$A" join tcp/127.0.0.1:$rp --scene "$S" --watch "${win[@]}" --duration $watched --wait 30 \
    --report $O/watch_$d.json 2>$O/watch_$d.log
  wait $sp
  python3 -c "
import json
w = json.load(open('$O/watch_$d.json'))
v = w['video']
if w.get('window'):
    print('$size, $codec, $d ms, window: decoded->presented %.1f/%.1f, capture->presented %.1f/%.1f ms'
          % tuple(w['window'][k][s] for k in ['display_ms', 'glass_to_glass_ms'] for s in ['median', 'p95']))
c = json.load(open('$O/serve_$d.json'))['video_cameras'][0]
print('$size, $codec, $d ms:', ', '.join('%s %.1f/%.1f' % (k[:-3], v[k]['median'], v[k]['p95'])
      for k in ['arrive_ms', 'app_ms', 'encode_ms', 'network_ms', 'decode_ms', 'total_ms']),
      'ms; %.1f fps shown, waited %s, main world %.1f ms/update, gpu %s' % (v['fps'],
      v['waited_updates'], c['update_ms']['median'],
      {k: round(s['median'], 1) for k, s in c['gpu_ms'].items()}))"
done
