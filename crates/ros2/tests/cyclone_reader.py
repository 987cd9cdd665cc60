#!/usr/bin/env python3
"""A ROS 2 subscriber that is not part of the project: Eclipse Cyclone DDS
(the DDS of ROS 2's rmw_cyclonedds_cpp), from Python, reads the bridge's
topics on a DDS domain and compares every message with a recording of the
same run.

The types are IDL structs (cyclonedds.idl): ROS 2 Jazzy's standard messages
written out below from their .msg definitions, and sar_msgs made from the
package's own .msg files (--msg-dir) as rosidl makes its IDL; each with the
DDS type name ROS 2 registers (pkg::msg::dds_::Type_), on the topics ROS 2
names (rt/...). The recording is read by the mcap and mcap-ros2-support
packages (from the schemas it carries). Both sides are flattened into
field=value lists (floats as their IEEE bits) and compared exactly.

Usage: cyclone_reader.py --msg-dir DIR --domain N
       cyclone_reader.py --msg-dir DIR --domain N --figures SECONDS
  (CYCLONEDDS_URI names the participant's configuration)
With --figures (scripts/ros2-figures.sh): reads /sar/estimate/state and
/sar/scene/status for SECONDS after the first message (or until SIGTERM),
keeping only each message's cycle, stamp and receive time, and prints their
latency from the loop's cycle (p50, p99, max) and the cycles missing
between the first and the last received.
stdin:  "late"            create late-joining readers (transient local topics)
        "stop RECORDING"  stop reading, compare with RECORDING.mcap
stdout: {"ready": ...} once the readers exist, then one JSON summary.
Exit 3 when a package is missing.
"""
import argparse
import dataclasses
import json
import os
import re
import struct
import sys
import threading
import time
import types as pytypes

try:
    from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
    from cyclonedds.core import Policy, Qos, ReadCondition, SampleState, ViewState, InstanceState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.idl import IdlStruct
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration
    import cyclonedds.idl.types as t
except ImportError as e:  # pragma: no cover
    print(f"missing Python package: {e} (scripts/setup-test-readers.sh installs it)", file=sys.stderr)
    sys.exit(3)


def struct_type(pkg, name, fields):
    """An IDL struct `pkg::msg::dds_::name_` with `fields` [(name, type)]."""
    def body(ns):
        ns["__annotations__"] = dict(fields)
    cls = pytypes.new_class(name, (IdlStruct,), {"typename": f"{pkg}::msg::dds_::{name}_"}, body)
    return dataclasses.dataclass(cls)


# ROS 2 Jazzy's standard messages (their .msg files, field by field).
Time = struct_type("builtin_interfaces", "Time", [("sec", t.int32), ("nanosec", t.uint32)])
Duration = struct_type("builtin_interfaces", "Duration", [("sec", t.int32), ("nanosec", t.uint32)])
Header = struct_type("std_msgs", "Header", [("stamp", Time), ("frame_id", str)])
ColorRGBA = struct_type("std_msgs", "ColorRGBA", [(c, t.float32) for c in "rgba"])
Vector3 = struct_type("geometry_msgs", "Vector3", [(c, t.float64) for c in "xyz"])
Point = struct_type("geometry_msgs", "Point", [(c, t.float64) for c in "xyz"])
Quaternion = struct_type("geometry_msgs", "Quaternion", [(c, t.float64) for c in "xyzw"])
Pose = struct_type("geometry_msgs", "Pose", [("position", Point), ("orientation", Quaternion)])
Wrench = struct_type("geometry_msgs", "Wrench", [("force", Vector3), ("torque", Vector3)])
WrenchStamped = struct_type("geometry_msgs", "WrenchStamped", [("header", Header), ("wrench", Wrench)])
Transform = struct_type("geometry_msgs", "Transform", [("translation", Vector3), ("rotation", Quaternion)])
TransformStamped = struct_type(
    "geometry_msgs", "TransformStamped",
    [("header", Header), ("child_frame_id", str), ("transform", Transform)])
JointState = struct_type(
    "sensor_msgs", "JointState",
    [("header", Header), ("name", t.sequence[str]), ("position", t.sequence[t.float64]),
     ("velocity", t.sequence[t.float64]), ("effort", t.sequence[t.float64])])
CompressedImage = struct_type(
    "sensor_msgs", "CompressedImage",
    [("header", Header), ("format", str), ("data", t.sequence[t.uint8])])
UVCoordinate = struct_type("visualization_msgs", "UVCoordinate", [("u", t.float32), ("v", t.float32)])
MeshFile = struct_type("visualization_msgs", "MeshFile", [("filename", str), ("data", t.sequence[t.uint8])])
Marker = struct_type(
    "visualization_msgs", "Marker",
    [("header", Header), ("ns", str), ("id", t.int32), ("type", t.int32), ("action", t.int32),
     ("pose", Pose), ("scale", Vector3), ("color", ColorRGBA), ("lifetime", Duration),
     ("frame_locked", bool), ("points", t.sequence[Point]), ("colors", t.sequence[ColorRGBA]),
     ("texture_resource", str), ("texture", CompressedImage),
     ("uv_coordinates", t.sequence[UVCoordinate]), ("text", str), ("mesh_resource", str),
     ("mesh_file", MeshFile), ("mesh_use_embedded_materials", bool)])
MarkerArray = struct_type("visualization_msgs", "MarkerArray", [("markers", t.sequence[Marker])])
TFMessage = struct_type("tf2_msgs", "TFMessage", [("transforms", t.sequence[TransformStamped])])

PRIMITIVES = {
    "bool": bool, "byte": t.uint8, "char": t.uint8, "int8": t.int8, "uint8": t.uint8,
    "int16": t.int16, "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32,
    "int64": t.int64, "uint64": t.uint64, "float32": t.float32, "float64": t.float64,
    "string": str,
}
KNOWN = {"std_msgs/Header": Header, "builtin_interfaces/Time": Time}


def msg_type(path, pkg="sar_msgs"):
    """The IDL struct of a .msg file: its fields in order (constants and
    comments left out), as rosidl makes the IDL of it."""
    name = os.path.splitext(os.path.basename(path))[0]
    fields = []
    for line in open(path, encoding="utf-8"):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        ftype, rest = line.split(None, 1)
        if "=" in rest:
            continue  # a constant
        fname = rest.split()[0]
        m = re.fullmatch(r"([\w/]+)(\[(\d*)\])?", ftype)
        base, array, size = m.group(1), m.group(2), m.group(3)
        inner = PRIMITIVES.get(base) or KNOWN[base if "/" in base else f"{pkg}/{base}"]
        if array is None:
            typ = inner
        elif size:
            typ = t.array[inner, int(size)]
        else:
            typ = t.sequence[inner]
        fields.append((fname, typ))
    return struct_type(pkg, name, fields)


BEST_EFFORT, RELIABLE, LATCHED = "best_effort", "reliable", "latched"


def topics(msg_dir):
    """(ROS 2 topic, IDL type, the QoS a ROS 2 subscriber asks)."""
    sar = {n: msg_type(os.path.join(msg_dir, f"{n}.msg"))
           for n in ("EstimatorState", "GuardEvent", "SceneStatus")}
    return [
        ("/sar/sensor/wrench", WrenchStamped, BEST_EFFORT),
        ("/sar/joints", JointState, BEST_EFFORT),
        ("/sar/estimate/state", sar["EstimatorState"], BEST_EFFORT),
        ("/sar/estimate/tip_wrench", WrenchStamped, BEST_EFFORT),
        ("/sar/estimate/tip_wrench_filtered", WrenchStamped, BEST_EFFORT),
        ("/sar/estimate/passive_joints", JointState, BEST_EFFORT),
        ("/sar/guard/events", sar["GuardEvent"], LATCHED),
        ("/sar/sim/tip_wrench_truth", WrenchStamped, BEST_EFFORT),
        ("/sar/scene", MarkerArray, RELIABLE),
        ("/sar/scene/status", sar["SceneStatus"], RELIABLE),
        ("/tf", TFMessage, RELIABLE),
        ("/tf_static", TFMessage, LATCHED),
    ]


def qos(kind, depth):
    if kind == BEST_EFFORT:
        return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(depth))
    if kind == RELIABLE:
        return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(depth))
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
               Policy.History.KeepLast(depth))


def flatten(prefix, value, out):
    """field=value in order; floats as IEEE bits (NaN equals itself)."""
    if isinstance(value, bool):
        out.append(f"{prefix}=b:{int(value)}")
    elif isinstance(value, float):
        out.append(f"{prefix}=f:{struct.unpack('<Q', struct.pack('<d', value))[0]}")
    elif isinstance(value, int):
        out.append(f"{prefix}=i:{value}")
    elif isinstance(value, str):
        out.append(f"{prefix}=s:{value.encode('utf-8').hex()}")
    elif isinstance(value, (bytes, bytearray)):
        for i, v in enumerate(value):
            out.append(f"{prefix}[{i}]=i:{v}")
    elif isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
        items = value.tolist() if hasattr(value, "tolist") else value
        for i, v in enumerate(items):
            flatten(f"{prefix}[{i}]", v, out)
    elif dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            flatten(f"{prefix}.{f.name}" if prefix else f.name, getattr(value, f.name), out)
    elif hasattr(value, "__slots__"):
        for name in value.__slots__:
            flatten(f"{prefix}.{name}" if prefix else name, getattr(value, name), out)
    else:
        raise TypeError(f"{prefix}: unexpected {type(value)}")
    return out


def stamp_ns(flat):
    """The first header stamp of a flattened message, ns."""
    sec = nsec = None
    for item in flat:
        key, val = item.split("=", 1)
        if sec is None and key.endswith("header.stamp.sec"):
            sec = int(val[2:])
        elif sec is not None and key.endswith("header.stamp.nanosec"):
            nsec = int(val[2:])
            break
    return None if sec is None else sec * 1_000_000_000 + nsec


# Static frames: their stamp says when they were sent (the recording's at its
# first scene, the bridge's at its own), not what they are; tf2 ignores it.
STAMPLESS = {"/tf_static"}


def unstamped(name, flat):
    """A message as compared: without its header stamps on STAMPLESS topics."""
    if name not in STAMPLESS:
        return flat
    return [item for item in flat if "header.stamp." not in item.split("=", 1)[0]]


def key_of(name, flat):
    return None if name in STAMPLESS else stamp_ns(flat)


def percentile(sorted_values, q):
    if not sorted_values:
        return None
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--msg-dir", required=True)
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--figures", type=float)
    args = ap.parse_args()
    if args.figures is not None:
        figures(args)
        return

    dp = DomainParticipant(args.domain)
    published = topics(args.msg_dir)
    dds_topics = {}
    readers = []
    waitset = WaitSet(dp)
    for name, typ, kind in published:
        dds_topics[name] = Topic(dp, "rt" + name, typ)
        # Deep enough for what arrives between two takes at 1 kHz.
        r = DataReader(dp, dds_topics[name], qos=qos(kind, 4096 if kind == BEST_EFFORT else 256))
        readers.append((name, r))
        waitset.attach(ReadCondition(r, SampleState.Any | ViewState.Any | InstanceState.Any))
    publications = BuiltinDataReader(dp, BuiltinTopicDcpsPublication)

    commands = []
    lock = threading.Lock()

    def read_stdin():
        for line in sys.stdin:
            with lock:
                commands.append(line.strip())

    threading.Thread(target=read_stdin, daemon=True).start()
    print(json.dumps({"ready": True, "topics": len(readers)}), flush=True)

    received = {name: [] for name, _, _ in published}  # (recv_ns, flat)
    late_received = {}
    late_readers = []
    discovered = {}
    stop_path = None
    stop_at = None
    while True:
        waitset.wait(duration(milliseconds=20))
        now = time.monotonic_ns()
        for name, r in readers:
            for s in r.take(N=4096):
                received[name].append((now, flatten("", s, [])))
        for name, r in late_readers:
            for s in r.take(N=256):
                late_received.setdefault(name, []).append(flatten("", s, []))
        for p in publications.take(N=64):
            if p.topic_name.startswith("rt/"):
                q = p.qos
                discovered[p.topic_name] = {
                    "type": p.type_name,
                    "reliability": type(q[Policy.Reliability]).__name__ if Policy.Reliability in q else None,
                    "durability": type(q[Policy.Durability]).__name__ if Policy.Durability in q else None,
                    "history": repr(q[Policy.History]) if Policy.History in q else None,
                }
        with lock:
            pending, commands[:] = list(commands), []
        for c in pending:
            if c == "late":
                for name, typ, kind in published:
                    if kind == LATCHED:
                        late_readers.append((name, DataReader(dp, dds_topics[name], qos=qos(kind, 256))))
            elif c.startswith("stop "):
                stop_path = c[5:]
                # Time for the late readers' history to arrive.
                stop_at = time.monotonic() + 2.0
        if stop_at is not None and time.monotonic() >= stop_at:
            break

    print(json.dumps(compare(stop_path, published, received, late_received, discovered)), flush=True)


def figures(args):
    """Latency and loss of the estimate (1 kHz) and the scene's status."""
    import signal
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    dp = DomainParticipant(args.domain)
    chosen = {n: (typ, kind) for n, typ, kind in topics(args.msg_dir)
              if n in ("/sar/estimate/state", "/sar/scene/status")}
    waitset = WaitSet(dp)
    readers = []
    for name, (typ, kind) in chosen.items():
        r = DataReader(dp, Topic(dp, "rt" + name, typ), qos=qos(kind, 4096))
        readers.append((name, r))
        waitset.attach(ReadCondition(r, SampleState.Any | ViewState.Any | InstanceState.Any))
    print(json.dumps({"ready": True}), flush=True)
    got = {name: [] for name in chosen}
    first = None
    while not stop and (first is None or time.monotonic() - first < args.figures):
        waitset.wait(duration(milliseconds=50))
        now = time.monotonic_ns()
        for name, r in readers:
            for s in r.take(N=4096):
                stamp = s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec
                got[name].append((s.cycle, now - stamp))
                if first is None:
                    first = time.monotonic()
    out = {}
    for name, samples in got.items():
        cycles = sorted(c for c, _ in samples)
        lat = sorted(l for _, l in samples)
        span = cycles[-1] - cycles[0] + 1 if cycles else 0
        out[name] = {
            "received": len(samples),
            "first_cycle": cycles[0] if cycles else None,
            "last_cycle": cycles[-1] if cycles else None,
            "duplicates": len(cycles) - len(set(cycles)),
            "latency_ns": [percentile(lat, 0.5), percentile(lat, 0.99), lat[-1] if lat else None],
        }
        if name == "/sar/estimate/state":
            out[name]["missing_cycles"] = span - len(set(cycles))
    print(json.dumps(out), flush=True)


def recorded_messages(path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    out = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            flat = flatten("", decoded, [])
            out.setdefault(channel.topic, []).append((message.log_time, flat))
    return out


def compare(path, published, received, late_received, discovered):
    recorded = recorded_messages(path)
    summary = {"discovered": discovered, "topics": {}, "late": {}}
    for name, _, kind in published:
        by_stamp = {}
        for log_time, flat in recorded.get(name, []):
            by_stamp.setdefault(key_of(name, flat), []).append(unstamped(name, flat))
        got = received[name]
        matched = mismatched = unrecorded = 0
        first_mismatch = None
        unrecorded_stamps = []
        latencies = []
        for recv_ns, flat in got:
            s = stamp_ns(flat)
            latencies.append(recv_ns - s)
            candidates = by_stamp.get(key_of(name, flat))
            flat = unstamped(name, flat)
            if candidates is None:
                unrecorded += 1
                unrecorded_stamps.append(s)
            elif flat in candidates:
                matched += 1
            else:
                mismatched += 1
                if first_mismatch is None:
                    want = candidates[0]
                    diff = [(a, b) for a, b in zip(want, flat) if a != b][:3]
                    first_mismatch = {"stamp": s, "fields": len(flat), "recorded_fields": len(want), "diff": diff}
        latencies.sort()
        summary["topics"][name] = {
            "received": len(got),
            "recorded": len(recorded.get(name, [])),
            "matched": matched,
            "mismatched": mismatched,
            "unrecorded": unrecorded,
            "unrecorded_stamps": unrecorded_stamps[:5],
            "first_mismatch": first_mismatch,
            "first_stamp": min((stamp_ns(f) for _, f in got), default=None),
            "latency_ns": [percentile(latencies, 0.5), percentile(latencies, 0.99),
                           latencies[-1] if latencies else None],
        }
    for name, msgs in late_received.items():
        recorded_flat = [unstamped(name, f) for _, f in recorded.get(name, [])]
        msgs = [unstamped(name, m) for m in msgs]
        summary["late"][name] = {
            "received": len(msgs),
            "all_recorded": all(m in recorded_flat for m in msgs),
            "last_is_recorded_last": bool(msgs) and bool(recorded_flat) and msgs[-1] == recorded_flat[-1],
        }
    return summary


if __name__ == "__main__":
    main()
