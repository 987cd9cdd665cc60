#!/usr/bin/env bash
# The real-time path's figures of issue 36, IN ONE RUN: every process below
# runs at the same time over the same wall interval on the same machine, so
# the machine's load is the same for all of them.
#
#   - a bare loop of clock_nanosleep at 1 kHz (scripts/bare-loop.c), the
#     CPU yardstick;
#   - `sard --sim` (release): the simulator;
#   - `sard` with the RDT sensor against its emulator (the example
#     rdt_emulator, 500 Hz as the driver asks; the axes simulated); the
#     emulator is another process (at SCHED_FIFO 70 as root, so that the
#     machine's load does not silence it), its CPU is not counted;
#   - cyclictest (`cyclictest -m -p 80 -i 1000 --histogram`), the wake-up
#     latency yardstick;
#   - with SARD_BEFORE=PATH, the same two sards of another build beside
#     them (e.g. main's, to show a change in the same run);
#   - the bare loop with the RDT driver's reads in it (the example
#     rdt_bare_loop: drain and poll each cycle, against its own emulator):
#     the CPU the driver adds to a real-time loop, apart from sard's other
#     work; with RDT_LOOP_BEFORE=PATH, that example built from another tree
#     beside it;
#   - WHICH="sim" or "rdt" measures only those sards (default both);
#   - RDT_PERIOD_US=N: the emulator streams one packet every N us whatever
#     the driver asks (ATI's dialect: 1000 for 1 kHz, 143 for ATI's 7 kHz).
#
# CPU: user + system time of each process (every thread of it), from
# /proc/PID/task/*/schedstat, over the same SECONDS after a warm-up; the bare loop and
# the sards run at SCHED_FIFO 80 like cyclictest (as root; else all at the
# normal priority). Wake-up p99: sard's own (its stop line: the loop's
# wake-up latency over its life, the histogram of `sar_loop::stats`) beside
# cyclictest's over the same interval (it runs from the sards' start to
# their stop). Recording off (the built-in configuration). The load of the
# machine (load average, and the CPU the rest of the machine used) is
# printed with the table.
#
# Usage: scripts/rt-figures.sh [SECONDS] [RUNS]   (defaults 60 and 1)
# Needs cc and cyclictest (Debian: apt-get install rt-tests).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
runs=${2:-1}
warmup=10
priority=80
command -v cc >/dev/null || { echo "rt-figures: cc is needed (the bare loop)" >&2; exit 1; }
command -v cyclictest >/dev/null || { echo "rt-figures: cyclictest is needed (apt-get install rt-tests)" >&2; exit 1; }
target=${CARGO_TARGET_DIR:-$PWD/target}
cargo build --release --locked -p sar-daemon --bin sard --example rdt_emulator --example shm_probe >/dev/null
cargo build --release --locked -p sar-rdt --example rdt_bare_loop >/dev/null
SARD=${SARD:-$target/release/sard}
emulator_bin=$target/release/examples/rdt_emulator
probe_bin=$target/release/examples/shm_probe
rdt_loop_bin=$target/release/examples/rdt_bare_loop
dir=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  if [ -n "${KEEP:-}" ]; then echo "kept $dir" >&2; else rm -rf "$dir"; fi
}
trap cleanup EXIT
cc -O2 -o "$dir/bare-loop" scripts/bare-loop.c
tick=$(getconf CLK_TCK)
fifo=() emulator_fifo=()
if [ "$(id -u)" = 0 ] && command -v chrt >/dev/null; then
  fifo=(chrt -f "$priority")
  # A real sensor is not slowed by the host's load: its emulator runs at
  # SCHED_FIFO too, below the loops.
  emulator_fifo=(chrt -f $((priority - 10)))
fi

# CPU time of a whole process, us: the sum of its threads' run time
# (/proc/PID/task/TID/schedstat, ns, precise; its threads live from start
# to stop, none ends within the interval).
cpu_us() { cat /proc/"$1"/task/*/schedstat | awk '{s += $1} END {printf "%d\n", s / 1000}'; }
# The machine's busy and total jiffies (every CPU).
machine() { awk '/^cpu / {print $2 + $3 + $4 + $7 + $8 + $9, $2 + $3 + $4 + $5 + $6 + $7 + $8 + $9}' /proc/stat; }

# An emulator streaming to one sard; its config file path is printed.
start_emulator() {
  local name=$1
  "${emulator_fifo[@]}" "$emulator_bin" "$dir/$name.toml" ${RDT_PERIOD_US:+"$RDT_PERIOD_US"} >"$dir/$name.addr" &
  pids+=("$!")
  for _ in $(seq 100); do [ -s "$dir/$name.addr" ] && break; sleep 0.1; done
  [ -s "$dir/$name.addr" ] || { echo "rt-figures: the RDT emulator did not start" >&2; exit 1; }
}

# cyclictest's p99 from its histogram (us).
cyclictest_p99() {
  awk '
    /^[0-9]+ +[0-9]+/ { n[$1 + 0] += $2; total += $2 }
    /Histogram Overflows:/ { over = $4 + 0; total += over }
    END {
      if (total == 0) { print "-"; exit }
      need = 0.99 * total; s = 0
      for (us = 0; us < 10000; us++) { s += n[us]; if (s >= need) { print us; exit } }
      print ">10000" }' "$1"
}

one_run() {
  local run=$1
  local -a names=() bins=()
  local w
  for w in ${WHICH:-sim rdt}; do names+=("$w"); bins+=("$SARD"); done
  if [ -n "${SARD_BEFORE:-}" ]; then
    for w in ${WHICH:-sim rdt}; do names+=("$w-before"); bins+=("$SARD_BEFORE"); done
  fi
  declare -A pid
  local i name
  for i in "${!names[@]}"; do
    name=${names[$i]}
    local -a args=(--sim)
    if [[ $name == rdt* ]]; then
      start_emulator "$name"
      args=(--config "$dir/$name.toml")
    fi
    (cd "$dir" && exec "${fifo[@]}" "${bins[$i]}" "${args[@]}" --prefix "rtfig-$$-$name") 2>"$dir/$name.log" &
    pid[$name]=$!
    pids+=("$!")
  done
  # The bare loop with the driver's reads (and the same from another tree).
  local -a loops=() loop_bins=()
  if [[ " ${WHICH:-sim rdt} " == *" rdt "* ]]; then
    loops+=("rdt reads"); loop_bins+=("$rdt_loop_bin")
    if [ -n "${RDT_LOOP_BEFORE:-}" ]; then loops+=("rdt reads-before"); loop_bins+=("$RDT_LOOP_BEFORE"); fi
  fi
  for i in "${!loops[@]}"; do
    name=${loops[$i]}
    start_emulator "loop$i"
    "${fifo[@]}" "${loop_bins[$i]}" "$(cat "$dir/loop$i.addr")" $(((warmup + seconds + 30) * 1000)) >/dev/null 2>"$dir/loop$i.log" &
    pid[$name]=$!
    pids+=("$!")
  done
  cyclictest -m -p "$priority" -i 1000 -D "$((warmup + seconds))s" -q -h 10000 >"$dir/cyclictest" 2>/dev/null &
  local cyc=$!
  pids+=("$cyc")
  "${fifo[@]}" "$dir/bare-loop" $(((warmup + seconds + 30) * 1000)) >/dev/null &
  local bare=$!
  pids+=("$bare")
  # The RDT sards start in Fault, waiting for the operator's first reset
  # (the simulator resets by itself): the probe's RESETs (a client as
  # sarctl, its other commands and a 1 s subscription with them), during
  # the warm-up, before the measured interval.
  local started; started=$(date +%s)
  sleep 3
  for name in "${names[@]}"; do
    kill -0 "${pid[$name]}" 2>/dev/null || { cat "$dir/$name.log" >&2; exit 1; }
    if [[ $name == rdt* ]]; then "$probe_bin" "rtfig-$$-$name" 1 >/dev/null 2>&1 || true; fi
  done
  sleep $((warmup - ($(date +%s) - started)))
  declare -A c0 c1
  local m0 m1 t0 t1 load0 load1
  load0=$(cut -d' ' -f1-3 /proc/loadavg)
  m0=$(machine)
  t0=$(date +%s.%N)
  c0[bare]=$(cpu_us "$bare")
  for name in "${names[@]}" "${loops[@]}"; do c0[$name]=$(cpu_us "${pid[$name]}"); done
  sleep "$seconds"
  c1[bare]=$(cpu_us "$bare")
  for name in "${names[@]}" "${loops[@]}"; do c1[$name]=$(cpu_us "${pid[$name]}"); done
  t1=$(date +%s.%N)
  m1=$(machine)
  load1=$(cut -d' ' -f1-3 /proc/loadavg)
  # The threads of the first sard, for what dominates.
  local threads=""
  for name in "${names[@]}"; do
    threads+="  $name threads (CPU ms since start):"
    for t in /proc/"${pid[$name]}"/task/*; do
      threads+=" $(cat "$t/comm")=$(awk '{printf "%d", $1 / 1e6}' "$t/schedstat")"
    done
    threads+=$'\n'
  done
  for name in "${names[@]}"; do kill -TERM "${pid[$name]}"; done
  for name in "${names[@]}"; do wait "${pid[$name]}" || true; done
  kill "$bare" 2>/dev/null || true
  for name in "${loops[@]}"; do
    kill -0 "${pid[$name]}" 2>/dev/null || echo "  $name ended early: $(cat "$dir"/loop*.log)"
    kill "${pid[$name]}" 2>/dev/null || true
  done
  wait "$cyc" || true
  local cp99; cp99=$(cyclictest_p99 "$dir/cyclictest")
  local rate="at the driver's 500 Hz"
  if [ -n "${RDT_PERIOD_US:-}" ]; then rate="every $RDT_PERIOD_US us"; fi
  echo "== run $run of $runs: $seconds s at 1 kHz, the RDT emulator $rate, $(nproc) CPUs; load average $load0 at the start, $load1 at the end"
  awk -v m0="$m0" -v m1="$m1" -v tick="$tick" -v own_us="$(
      s=$((c1[bare] - c0[bare])); for name in "${names[@]}" "${loops[@]}"; do s=$((s + c1[$name] - c0[$name])); done; echo $s)" 'BEGIN {
    split(m0, a, " "); split(m1, b, " ")
    busy = b[1] - a[1]; total = b[2] - a[2]; own = own_us * tick / 1e6
    printf "   the machine: %.0f %% of its CPUs busy over the interval, %.0f %% of it by other processes than these\n",
      100 * busy / total, 100 * (busy - own) / total }'
  printf '| %-26s | %9s | %12s | %9s | %13s | %13s |\n' "process" "CPU s" "% of a core" "vs bare" "wake-up p99" "vs cyclictest"
  printf '|%s|%s|%s|%s|%s|%s|\n' "----------------------------" "-----------" "--------------" "-----------" "---------------" "---------------"
  local bare_us=$((c1[bare] - c0[bare]))
  row() {
    awk -v label="$1" -v d="$2" -v bare="$bare_us" -v t0="$t0" -v t1="$t1" -v p99="$3" -v cp="$cp99" 'BEGIN {
      if (d == "-") { cpu = "-"; share = "-"; ratio = "-" }
      else {
        s = d / 1e6; cpu = sprintf("%.2f", s); share = sprintf("%.2f", 100 * s / (t1 - t0))
        ratio = bare > 0 ? sprintf("%.2fx", d / bare) : "-" }
      pr = (p99 != "-" && cp != "-" && cp > 0) ? sprintf("%.2fx", p99 / cp) : "-"
      printf "| %-26s | %9s | %12s | %9s | %10s us | %13s |\n", label, cpu, share, ratio, p99, pr }'
  }
  row "bare clock_nanosleep" "$bare_us" "-"
  for name in "${loops[@]}"; do
    row "bare + $name" "$((c1[$name] - c0[$name]))" "-"
  done
  row "cyclictest" "-" "$cp99"
  for name in "${names[@]}"; do
    local p99
    p99=$(sed -n 's/.*wake-up latency p50 [0-9]* us p99 \([0-9]*\) us.*/\1/p' "$dir/$name.log")
    row "sard $name" "$((c1[$name] - c0[$name]))" "${p99:--}"
  done
  printf '%s' "$threads"
  for name in "${names[@]}"; do
    grep -E 'stopped after' "$dir/$name.log" | sed "s/^.*sard: /  $name: /" || true
  done
  # The emulators of this run.
  for p in $(jobs -p); do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  pids=()
}

for r in $(seq "$runs"); do one_run "$r"; done
