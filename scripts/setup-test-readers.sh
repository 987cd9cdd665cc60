#!/usr/bin/env bash
# Installs the strict readers the tests decode recordings with, under
# target/test-readers/ (no root, no system pip; outside it only pip's and
# npm's download caches in the home directory):
#   node/  the parsers Foxglove and Lichtblick use, pinned in
#          scripts/test-readers/package.json and package-lock.json (npm ci):
#          @foxglove/rosmsg, @foxglove/rosmsg2-serialization, @mcap/core,
#          @mcap/support (zstd), @foxglove/ws-protocol, ws;
#   py/    rosbags, mcap, mcap-ros2-support, mcap-protobuf-support (pinned
#          below), installed with `python3 -m pip install --target`, which
#          works beside a distribution's EXTERNALLY-MANAGED marker (PEP 668)
#          and needs no venv/ensurepip; the tests put it on PYTHONPATH.
#   dds/   Eclipse Cyclone DDS for Python (cyclonedds, pinned below, its
#          wheel bundles the C library), the DDS the ROS 2 bridge's test
#          reads with (crates/ros2/tests/cyclone.rs); the same way, apart
#          from py/ so that one part's failure leaves the other alone;
#   rosidl/ ROS 2 Jazzy's rosidl_adapter and rosidl_parser (pinned below):
#          the .msg -> IDL step of rosidl_generate_interfaces, which the
#          test of ros2/sar_msgs runs on the .msg files; installed with
#          --prefix (their wheels put the modules under lib/pythonX.Y/
#          site-packages, which --target loses).
#
# Idempotent and safe to run concurrently (a lock file): it does nothing when
# the stamp matches (same pins, same python3 and node). The tests run it
# themselves on first use; run it by hand to set up ahead (needs network).
# Needs python3 with pip (Debian/Ubuntu: python3-pip) and node with npm
# (nodejs, npm). SAR_SKIP_PYTHON=1 / SAR_SKIP_NODE=1 skip either part
# (SAR_SKIP_PYTHON=1 every Python part); SAR_SKIP_DDS=1 skips dds/ and
# rosidl/ alone.
#
# Usage: scripts/setup-test-readers.sh [TARGET_DIR]   (default: ./target)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
target="${1:-${CARGO_TARGET_DIR:-$root/target}}"
dir="$target/test-readers"
mkdir -p "$dir"

PY_PINS=(rosbags==0.11.9 mcap==1.6.0 mcap-ros2-support==0.6.0 mcap-protobuf-support==0.6.0)
DDS_PINS=(cyclonedds==11.0.1)
ROSIDL_PINS=(ros-jazzy-rosidl-adapter==4.6.6 ros-jazzy-rosidl-parser==4.6.6)

exec 9>"$dir/.lock"
flock 9

skip_py="${SAR_SKIP_PYTHON:-0}"
skip_node="${SAR_SKIP_NODE:-0}"
skip_dds="${SAR_SKIP_DDS:-0}"
[ "$skip_py" = 1 ] && skip_dds=1

# pip install --target DIR PINS... (MODE --target) or --prefix DIR,
# recording what the pins pulled in (DIR-freeze.txt) and a stamp of the pins
# and the interpreter (DIR.stamp): nothing is done when the stamp matches.
install_py() {
  local name="$1" mode="$2"; shift 2
  local stamp
  stamp="$(printf '%s\n' "$@" "$(python3 -c 'import sys; print(sys.version)')")"
  if [ ! -f "$dir/$name.stamp" ] || [ "$(cat "$dir/$name.stamp")" != "$stamp" ]; then
    python3 -m pip --version >/dev/null 2>&1 || {
      echo "setup-test-readers: python3 has no pip (Debian/Ubuntu: apt-get install python3-pip), or set SAR_SKIP_PYTHON=1" >&2
      exit 2
    }
    echo "setup-test-readers: installing $* into $dir/$name" >&2
    rm -rf "${dir:?}/$name" "$dir/$name.stamp"
    PIP_BREAK_SYSTEM_PACKAGES=0 python3 -m pip install --quiet --disable-pip-version-check \
      --no-input --no-warn-script-location --root-user-action=ignore "$mode" "$dir/$name" "$@" >&2
    local path="$dir/$name"
    [ "$mode" = --prefix ] && path="$(echo "$dir/$name"/lib/python3*/site-packages)"
    PYTHONPATH="$path" python3 -c '
import importlib.metadata as m, sys
for d in sorted(m.distributions(path=[sys.argv[1]]), key=lambda d: d.metadata["Name"].lower()):
    print(d.metadata["Name"] + "==" + d.version)' "$path" > "$dir/$name-freeze.txt"
    printf '%s' "$stamp" > "$dir/$name.stamp"
  fi
}

if [ "$skip_py" != 1 ]; then
  command -v python3 >/dev/null || {
    echo "setup-test-readers: python3 not found (Debian/Ubuntu: apt-get install python3 python3-pip), or set SAR_SKIP_PYTHON=1" >&2
    exit 2
  }
  install_py py --target "${PY_PINS[@]}"
fi

if [ "$skip_dds" != 1 ]; then
  install_py dds --target "${DDS_PINS[@]}"
  install_py rosidl --prefix "${ROSIDL_PINS[@]}"
fi

if [ "$skip_node" != 1 ]; then
  command -v node >/dev/null && command -v npm >/dev/null || {
    echo "setup-test-readers: node and npm not found (Debian/Ubuntu: apt-get install nodejs npm), or set SAR_SKIP_NODE=1" >&2
    exit 2
  }
  node_stamp="$(cat "$root/scripts/test-readers/package.json" "$root/scripts/test-readers/package-lock.json"; node --version)"
  if [ ! -f "$dir/node.stamp" ] || [ "$(cat "$dir/node.stamp")" != "$node_stamp" ]; then
    echo "setup-test-readers: installing the npm packages of scripts/test-readers/package-lock.json into $dir/node" >&2
    rm -rf "$dir/node" "$dir/node.stamp"
    mkdir -p "$dir/node"
    cp "$root/scripts/test-readers/package.json" "$root/scripts/test-readers/package-lock.json" "$dir/node/"
    npm ci --prefix "$dir/node" --no-audit --no-fund --ignore-scripts --loglevel=error >&2
    printf '%s' "$node_stamp" > "$dir/node.stamp"
  fi
fi
echo "$dir"
