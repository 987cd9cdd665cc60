#!/usr/bin/env bash
# The README's test command N times in a row beside K CPU hogs (a loaded
# two-core machine without real-time scheduling), each run's result and
# failing tests summarised at the end. Usage:
#   scripts/stress-suite.sh [RUNS=5] [HOGS=2]
# Builds first (not under load), then runs `cargo test --workspace
# --no-fail-fast` RUNS times with HOGS busy loops (nice 0) beside it. The
# logs stay in target/stress/.
set -uo pipefail
cd "$(dirname "$0")/.."
runs=${1:-5}
hogs=${2:-2}
out=target/stress
mkdir -p "$out"
cargo test --workspace --no-run --locked >"$out/build.log" 2>&1 || { tail -20 "$out/build.log"; exit 1; }
pids=()
for _ in $(seq 1 "$hogs"); do
  ( while :; do :; done ) &
  pids+=($!)
done
trap 'kill "${pids[@]}" 2>/dev/null' EXIT
failed=0
for r in $(seq 1 "$runs"); do
  start=$(date +%s)
  cargo test --workspace --no-fail-fast >"$out/run$r.log" 2>&1
  rc=$?
  secs=$(( $(date +%s) - start ))
  fails=$(grep -E '^test .* FAILED$' "$out/run$r.log" | sed 's/^test //; s/ \.\.\. FAILED$//' | tr '\n' ' ')
  echo "run $r: exit $rc in ${secs} s; failed: ${fails:-none}"
  [ "$rc" = 0 ] || failed=$((failed + 1))
done
echo "$failed of $runs runs failed (beside $hogs CPU hogs)"
[ "$failed" = 0 ]
