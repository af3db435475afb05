#!/usr/bin/env bash
# The robot site's upload and CPU with 1, 4 and 16 observers, directly and through a router
# (docs/network.md): bytes sent by the robot site's TCP sockets (ss), CPU from /proc. Needs a
# built target/debug/avatarm. Output: out/network_observers/observers.txt.
set -euo pipefail
cd "$(dirname "$0")/.."
A=target/debug/avatarm
S=assets/scenes/pouring.toml
O=out/network_observers; rm -rf "$O"; mkdir -p "$O"
cpu() { awk '{print $14+$15}' /proc/$1/stat; }
sent() { ss -tinpH state established 2>/dev/null | awk -v p="pid=$1," 'index($0,p){getline; if (match($0,/bytes_sent:[0-9]+/)) s+=substr($0,RSTART+11,RLENGTH-11)} END{print s+0}'; }
port=7900
for n in 1 4 16; do
 for via in direct router; do
  port=$((port+3))
  $A serve $S --insecure-lan --listen tcp/127.0.0.1:$port --duration 40 2>/dev/null &
  sp=$!
  target=$port
  if [ $via = router ]; then
    $A router --insecure-lan --listen tcp/127.0.0.1:$((port+1)) --connect tcp/127.0.0.1:$port --duration 42 2>/dev/null &
    target=$((port+1))
  fi
  sleep 12
  pids=""
  for i in $(seq 1 $n); do
    $A join tcp/127.0.0.1:$target --watch --duration 22 --wait 20 --report $O/w_${via}_${n}_$i.json 2>/dev/null >/dev/null &
    pids="$pids $!"
  done
  sleep 4
  c0=$(cpu $sp); b0=$(sent $sp)
  sleep 15
  c1=$(cpu $sp); b1=$(sent $sp)
  for p in $pids; do wait $p; done
  fr=$(python3 -c "
import json,glob
r=[json.load(open(f))['video'] for f in glob.glob('$O/w_${via}_${n}_*.json')]
print('%.1f fps, %.2f Mbit/s each (mean of %d)'%(sum(v['fps'] for v in r)/len(r), sum(v['mbit_s'] for v in r)/len(r), len(r)))")
  echo "$via $n: robot site CPU $(( (c1-c0)/15 ))% of a core, sent $(( (b1-b0)*8/15/1000 )) kbit/s; observers $fr" | tee -a $O/observers.txt
  wait $sp
 done
done
