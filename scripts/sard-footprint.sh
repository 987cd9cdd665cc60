#!/usr/bin/env bash
# sard's footprint at 1 kHz (issues 18 and 27): resident memory and CPU time
# of every thread over a run, read from /proc, beside a bare loop of
# clock_nanosleep at 1 kHz (scripts/bare-loop.c, compiled with cc) run over
# the same seconds; and sard's wake-up latency p99 (its stop line) beside
# cyclictest's at the same priority and period, run just before. The goals of
# issue 27: CPU at most 1.5x the bare loop's, wake-up p99 at most 1.2x
# cyclictest's. The yardstick is the article's control unit, an 800 MHz ARM
# with 256 MB of RAM.
#
# (The figures of issue 36, every process at the same time in one run beside
# cyclictest: scripts/rt-figures.sh.)
#
# Usage: scripts/sard-footprint.sh [SECONDS] [sim|rdt|both]
#   SECONDS: each measurement's length (default 60).
#   sim: on the simulator (`sard --sim`); rdt: the RDT sensor against its
#   emulator (the example rdt_emulator, one packet a millisecond), the axes
#   simulated; both (default): one after the other.
# After the CPU's measurement (no client connected meanwhile), a client
# (the example shm_probe) measures the state's publish-to-receive latency and
# the commands' round trip, with and without a subscriber.
# SARD=PATH measures another build of sard (e.g. an older one, to compare);
# by default this tree's, built in release.
# Needs cc, and cyclictest (Debian/Ubuntu: apt-get install rt-tests) for the
# latency comparison (skipped, and said, without it). Run as root for
# SCHED_FIFO (sard's and cyclictest's priority 80), else both run at the
# normal priority.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
which=${2:-both}
priority=80   # [loop] priority of the built-in configuration
if [ -z "${SARD:-}" ]; then
  cargo build --release --locked -p sar-daemon --bin sard >/dev/null
  SARD=$PWD/target/release/sard
fi
# The RDT emulator and the client's probe (the state's publish-to-receive
# latency, the commands' round trip: after the CPU's measurement).
cargo build --release --locked -p sar-daemon --example rdt_emulator --example shm_probe >/dev/null
dir=$(mktemp -d)
pids=()
trap 'for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; rm -rf "$dir"' EXIT
command -v cc >/dev/null || { echo "sard-footprint: cc is needed (the bare loop)" >&2; exit 1; }
cc -O2 -o "$dir/bare-loop" scripts/bare-loop.c
tick=$(getconf CLK_TCK)

# cyclictest's wake-up latency p99, us, over $seconds (its histogram).
cyclictest_p99() {
  if ! command -v cyclictest >/dev/null; then
    echo "cyclictest is not installed (apt-get install rt-tests): no latency comparison" >&2
    echo "-"
    return
  fi
  cyclictest -m -p "$priority" -i 1000 -D "${seconds}s" -q -h 10000 2>/dev/null | awk '
    /^[0-9]+ +[0-9]+/ { n[$1 + 0] += $2; total += $2 }
    /Histogram Overflows:/ { over = $4 + 0; total += over }
    END {
      if (total == 0) { print "-"; exit }
      need = 0.99 * total; s = 0
      for (us = 0; us < 10000; us++) { s += n[us]; if (s >= need) { print us; exit } }
      print ">10000" }'
}

# Every thread's CPU ticks (user + system): "tid ticks name" lines.
thread_ticks() {
  for t in /proc/"$1"/task/*; do
    printf '%s %s %s\n' "${t##*/}" "$(awk '{print $14 + $15}' "$t/stat")" "$(cat "$t/comm")"
  done
}

# One measurement: sard with the arguments given, beside the bare loop.
measure() {
  local label=$1; shift
  echo "== $label"
  local cyc_p99; cyc_p99=$(cyclictest_p99)
  (cd "$dir" && exec "$SARD" "$@" --prefix "sar-footprint-$$") 2>"$dir/log" &
  local pid=$!; pids+=("$pid")
  sleep 5   # start-up (the start-up reset, the first samples)
  kill -0 "$pid" 2>/dev/null || { cat "$dir/log" >&2; return 1; }
  thread_ticks "$pid" >"$dir/t0"
  local t0; t0=$(date +%s.%N)
  "$dir/bare-loop" $((seconds * 1000)) >"$dir/bare" &
  local bare=$!
  sleep "$seconds"
  thread_ticks "$pid" >"$dir/t1"
  local t1; t1=$(date +%s.%N)
  wait "$bare"
  grep -E '^(VmRSS|VmHWM|Threads)' "/proc/$pid/status" | tr -s '\t ' ' '
  target/release/examples/shm_probe "sar-footprint-$$" 5 | sed 's/^/  /' || true
  kill -TERM "$pid"; wait "$pid" || true
  local sard_p99
  sard_p99=$(sed -n 's/.*wake-up latency p50 [0-9]* us p99 \([0-9]*\) us.*/\1/p' "$dir/log")
  awk -v tick="$tick" -v t0="$t0" -v t1="$t1" -v bare="$(cat "$dir/bare")" \
      -v sp99="${sard_p99:--}" -v cp99="$cyc_p99" '
    FNR == NR { c0[$1] = $2; next }
    { d = $2 - c0[$1]; total += d; printf "  thread %-16s %5d ticks  %5.2f %% of a core\n", $3, d, 100 * d / tick / (t1 - t0) }
    END {
      s = total / tick
      printf "CPU: sard %.2f s (%.2f %% of a core) over %.0f s; bare loop %.2f s (%.2f %%); ratio %.2fx (goal <= 1.5x)\n",
        s, 100 * s / (t1 - t0), t1 - t0, bare, 100 * bare / (t1 - t0), (bare > 0 ? s / bare : 0)
      if (sp99 != "-" && cp99 != "-" && cp99 > 0)
        printf "wake-up p99: sard %s us, cyclictest %s us; ratio %.2fx (goal <= 1.2x)\n", sp99, cp99, sp99 / cp99
      else
        printf "wake-up p99: sard %s us, cyclictest %s us\n", sp99, cp99 }' "$dir/t0" "$dir/t1"
  grep -E 'stopped after' "$dir/log" | sed 's/^.*sard: /sard: /' || true
}

if [ "$which" = sim ] || [ "$which" = both ]; then
  measure "simulator (sard --sim), recording off" --sim
fi
if [ "$which" = rdt ] || [ "$which" = both ]; then
  target/release/examples/rdt_emulator "$dir/rdt.toml" >"$dir/emulator" &
  pids+=("$!")
  for _ in $(seq 50); do [ -s "$dir/emulator" ] && break; sleep 0.1; done
  measure "RDT sensor on its emulator at $(cat "$dir/emulator"), simulated axes, recording off" --config "$dir/rdt.toml"
fi
