#!/usr/bin/env bash
# Runs the timing-sensitive tests alone, N times each (default 10), and says how many passed:
# the ROS 1 link (avatarm_ros's `link` tests), the two-site network tests and XR (the app's
# `realtime` binary). A test that fails once is a bug to find, not to retry: the log of every
# failed run is kept in target/repeat/. FILTER (optional) is passed to both binaries as a test
# name filter, e.g. `xr::` for the XR tests alone. The XR tests say SKIPPED unless
# XR_RUNTIME_JSON names an OpenXR runtime (docs/quest2.md: Monado's null compositor).
# Usage: scripts/repeat_tests.sh [N] [FILTER]
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-10}
filter=${2:-}
[[ "$runs" =~ ^[1-9][0-9]*$ ]] || { echo "usage: $0 [RUNS] [FILTER]: RUNS a whole number from 1" >&2; exit 2; }
[ -f "${XR_RUNTIME_JSON:-}" ] || echo "repeat: XR_RUNTIME_JSON names no file: the XR tests (if the filter runs any) will be SKIPPED (docs/quest2.md)"
scripts/setup.sh
cargo test -p avatarm_ros --test link --no-run
cargo test -p avatarm --test realtime --no-run
logs=target/repeat
mkdir -p "$logs"
failed=0
for suite in "avatarm_ros link" "avatarm realtime"; do
  read -r package binary <<<"$suite"
  pass=0
  tests=
  for i in $(seq 1 "$runs"); do
    log="$logs/$package-$binary-$i.log"
    if cargo test -q -p "$package" --test "$binary" -- --test-threads 1 ${filter:+"$filter"} >"$log" 2>&1; then
      pass=$((pass + 1))
      tests=$(grep -Eo '[0-9]+ passed' "$log" | tail -1 || true)
      rm -f "$log"
    else
      echo "repeat: $package --test $binary run $i failed (log: $log)"
    fi
  done
  if [ "$pass" -eq "$runs" ] && [ "${tests:-0 passed}" = "0 passed" ]; then
    # The filter matched none of this binary's tests: nothing was repeated.
    echo "repeat: $package --test $binary: no test matches '$filter'"
    continue
  fi
  echo "repeat: $package --test $binary${filter:+ (filter $filter)}: $pass of $runs runs passed (the last passing run: ${tests:-none})"
  [ "$pass" -eq "$runs" ] || failed=1
done
exit "$failed"
