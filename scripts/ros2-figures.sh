#!/usr/bin/env bash
# The ROS 2 bridge's figures (issue 37), measured by hand, not in CI:
#  1. latency from the loop's cycle to a Cyclone DDS reader (p50, p99, max)
#     of /sar/estimate/state (1 kHz) and /sar/scene/status (the scene's
#     rate), and the estimate's cycles lost, over SECONDS;
#  2. CPU over those SECONDS: sard's (every thread), the bridge's and a bare
#     loop of clock_nanosleep at 1 kHz (scripts/bare-loop.c) in the same run;
#  3. a stalled reader: a second subscriber of every topic (reliable where
#     the topic is) stopped with SIGSTOP for STALL seconds while a reader
#     goes on: what the bridge refused, what the other reader lost, and
#     sard's figures before and after (its guard state and reason, the
#     publisher-stall check's Fault, wake-up p99 and max, overruns, the
#     publishing queue's drops).
# Everything in a private network namespace on its loopback (`unshare -n`:
# root), release builds of sard and sar-ros2, the built-in
# configuration of `sard --sim` with `[ros2] interfaces = ["127.0.0.1"]`.
#
# Usage: scripts/ros2-figures.sh [SECONDS] [STALL]   (defaults 60 and 30)
# 600 seconds gives the closing note's loss over 10 minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
stall=${2:-30}
[ "$(id -u)" = 0 ] || { echo "ros2-figures: needs root (a network namespace of its own)" >&2; exit 1; }

if [ -z "${SAR_ROS2_FIGURES_IN_NETNS:-}" ]; then
  cargo build --release --locked -p sar-daemon --bin sard -p sar-ros2 --bin sar-ros2 >/dev/null
  # `sarctl status` only reads the published state: the debug build does.
  cargo build --locked -p sarctl --bin sarctl >/dev/null
  SAR_SKIP_NODE=1 scripts/setup-test-readers.sh >/dev/null
  command -v cc >/dev/null || { echo "ros2-figures: cc is needed (the bare loop)" >&2; exit 1; }
  exec unshare -n env SAR_ROS2_FIGURES_IN_NETNS=1 "$0" "$@"
fi

ip link set lo up multicast on
ip route add 224.0.0.0/4 dev lo 2>/dev/null || true
rel=$PWD/target/release
readers=$PWD/target/test-readers
dir=$(mktemp -d)
pids=()
# The logs of the last run are kept in target/ros2-figures/.
keep=$PWD/target/ros2-figures
cleanup() {
  for p in "${pids[@]}"; do kill -CONT "$p" 2>/dev/null || true; kill "$p" 2>/dev/null || true; done
  sleep 1
  rm -rf "$keep"; mkdir -p "$keep"
  cp "$dir"/*.log "$dir"/*.json "$dir"/*.out "$keep"/ 2>/dev/null || true
  rm -rf "$dir"
}
trap cleanup EXIT
trap 'exit 1' INT TERM
cc -O2 -o "$dir/bare-loop" scripts/bare-loop.c
tick=$(getconf CLK_TCK)

printf '%s\n\n[ros2]\ninterfaces = ["127.0.0.1"]\n' "$(cat crates/config/src/default_config.toml)" >"$dir/sim.toml"
cat >"$dir/cyclonedds.xml" <<'EOF'
<?xml version="1.0" encoding="UTF-8" ?>
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <General>
      <Interfaces><NetworkInterface name="lo" multicast="true"/></Interfaces>
      <AllowMulticast>true</AllowMulticast>
    </General>
  </Domain>
</CycloneDDS>
EOF
export SAR_RUNTIME_DIR="$dir/run" SAR_SERVICE_PREFIX="ros2-figures-$$" ROS_DOMAIN_ID=0
export CYCLONEDDS_URI="file://$dir/cyclonedds.xml" PYTHONPATH="$readers/dds" PYTHONDONTWRITEBYTECODE=1
reader=(python3 crates/ros2/tests/cyclone_reader.py --msg-dir crates/msgs/msg --domain 0)
ticks() { awk '{print $14 + $15}' /proc/"$1"/task/*/stat | awk '{s += $1} END {print s}'; }
alive() {
  for p in "$@"; do
    [ -d /proc/"$p" ] || { echo "ros2-figures: process $p ended early (its logs: $keep)" >&2; exit 1; }
  done
}
status() { "$PWD/target/debug/sarctl" status --format json; }
# One line of sard's published figures (`sarctl status --format json`).
cat >"$dir/said.py" <<'EOF'
import json, sys
v = json.load(open(sys.argv[1]))
w = v["wakeup_ns"]
print(f"  sard {sys.argv[2]}: guard {v['guard']} ({v['reason']}), wake-up p99 {w['p99'] // 1000} us, "
      f"max {w['max'] // 1000} us, overruns {v['overruns']}, publish queue drops "
      f"{v['publish_queue_drops']}, publish errors {v['publish_errors']}")
EOF
# A reader's --figures output as lines.
cat >"$dir/figures.py" <<'EOF'
import json, sys
v = json.loads(open(sys.argv[1]).read().splitlines()[-1])
for name, f in v.items():
    p50, p99, mx = (x / 1e6 if x is not None else float("nan") for x in f["latency_ns"])
    lost = f.get("missing_cycles")
    span = f["last_cycle"] - f["first_cycle"] + 1 if f["first_cycle"] is not None else 0
    print(f"  {sys.argv[2]}{name}: {f['received']} messages, latency from the cycle p50 {p50:.2f} ms, "
          f"p99 {p99:.2f} ms, max {mx:.2f} ms" + (f", cycles missing {lost} of {span}" if lost is not None else ""))
EOF
said() { python3 "$dir/said.py" "$@"; }
figures() { python3 "$dir/figures.py" "$@"; }

# A copy of sard under a name of its own: a clean-up elsewhere on a shared
# machine that stops processes named `sard` does not end this measurement.
cp "$rel/sard" "$dir/sard-figures"
(cd "$dir" && exec "$dir/sard-figures" --sim --config "$dir/sim.toml") 2>"$dir/sard.log" &
sard=$!; pids+=("$sard")
for _ in $(seq 100); do status >/dev/null 2>&1 && break; sleep 0.1; done
"$rel/sar-ros2" --config "$dir/sim.toml" 2>"$dir/bridge.log" &
bridge=$!; pids+=("$bridge")
sleep 3   # start-up, the first reset

echo "== 1. latency and loss over ${seconds} s, CPU over the same seconds"
"${reader[@]}" --figures "$seconds" >"$dir/figures.json" &
fig=$!; pids+=("$fig")
sleep 3   # discovery
alive "$sard" "$bridge"
s0=$(ticks "$sard"); b0=$(ticks "$bridge"); t0=$(date +%s.%N)
rss() { awk '/VmRSS/ {print $2 " kB"}' /proc/"$1"/status; }
"$dir/bare-loop" $((seconds * 1000)) >"$dir/bare" &
wait $!
alive "$sard" "$bridge"
s1=$(ticks "$sard"); b1=$(ticks "$bridge"); t1=$(date +%s.%N)
wait "$fig" || true
figures "$dir/figures.json" ""
awk -v tick="$tick" -v t0="$t0" -v t1="$t1" -v s="$((s1 - s0))" -v b="$((b1 - b0))" -v bare="$(cat "$dir/bare")" 'BEGIN {
  w = t1 - t0
  printf "  CPU over %.0f s: sard %.2f %% of a core, sar-ros2 %.2f %%, bare loop %.2f %%\n", w, 100 * s / tick / w, 100 * b / tick / w, 100 * bare / w }'
status >"$dir/before.json"

echo "== 3. a subscriber of every topic stopped (SIGSTOP) for ${stall} s, another reading on"
sleep infinity | "${reader[@]}" >"$dir/stalled.out" &
stalled=$!; pids+=("$stalled")
sleep 4   # discovery, then it reads
"${reader[@]}" --figures "$stall" >"$dir/during.json" &
during=$!; pids+=("$during")
sleep 2
echo "  sar-ros2's resident memory before the stall: $(rss "$bridge")"
kill -STOP "$stalled"
sleep "$stall"
echo "  sar-ros2's resident memory after ${stall} s of it: $(rss "$bridge")"
wait "$during" || true
status >"$dir/after.json"
figures "$dir/during.json" "the other reader, "
said "$dir/before.json" "before the stall"
said "$dir/after.json" "after ${stall} s of it"
kill -CONT "$stalled" 2>/dev/null || true
kill "$stalled" 2>/dev/null || true
kill -TERM "$bridge"; wait "$bridge" || true
kill -TERM "$sard"; wait "$sard" || true
grep -E 'publisher_stalled' "$dir/sard.log" | head -3 || echo "  sard's log: no publisher_stalled"
grep -E '^sar-ros2: stopped' "$dir/bridge.log" | sed 's/^/  /'
grep -E 'stopped after|wake-up latency' "$dir/sard.log" | sed 's/^.*sard: /  sard: /' | tail -2
