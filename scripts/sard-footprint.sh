#!/usr/bin/env bash
# sard's footprint at 1 kHz on the simulator (issue 18): resident memory and
# CPU time of the whole process over a run, read from /proc. The yardstick is
# the article's control unit, an 800 MHz ARM with 256 MB of RAM.
#
# Usage: scripts/sard-footprint.sh [SECONDS]   (default 60; builds sard in release)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
cargo build --release --locked -p sar-daemon --bin sard >/dev/null
dir=$(mktemp -d)
trap 'kill "$pid" 2>/dev/null || true; rm -rf "$dir"' EXIT
# Recording off (the built-in configuration's default); its own prefix.
(cd "$dir" && exec "$OLDPWD/target/release/sard" --sim --prefix "sar-footprint-$$") 2>"$dir/log" &
pid=$!
tick=$(getconf CLK_TCK)
cpu() { awk '{print $14 + $15}' "/proc/$pid/stat"; }
sleep 5   # start-up (the start-up reset, the first samples)
t0=$(date +%s.%N); c0=$(cpu)
sleep "$seconds"
t1=$(date +%s.%N); c1=$(cpu)
grep -E '^(VmRSS|VmHWM|RssAnon|RssFile|Threads)' "/proc/$pid/status"
awk -v c0="$c0" -v c1="$c1" -v t0="$t0" -v t1="$t1" -v tick="$tick" 'BEGIN {
  printf "CPU: %.1f %% of one core over %.0f s (user + system, every thread)\n", 100 * (c1 - c0) / tick / (t1 - t0), t1 - t0 }'
kill -TERM "$pid"; wait "$pid" || true
grep -E 'stopped after' "$dir/log" | sed 's/^.*sard: /sard: /' || true
