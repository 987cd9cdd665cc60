#!/usr/bin/env python3
"""A strict check of MCAP recordings with Python `rosbags` (as a ROS 2 user
would open them): `rosbags.rosbag2.Reader` opens each file (it refuses a file
whose profile is not `ros2`), a type store is built ONLY from the schemas
embedded in the file (`Stores.EMPTY` + `get_types_from_msg` per schema), and
every message is deserialized from CDR with it. Each channel's
`offered_qos_profiles` must parse (history, reliability, durability known).

Usage: check_rosbags.py [--scene] FILE.mcap...
Prints one JSON object: {"files": [{"path", "schemas", "channels",
"messages", "failures", "errors": [...], "topics": {topic: count}}]}.
With --scene, each file also gives "scene": up to 30 `/sar/scene` messages
whose tip-force arrow is shown, each {"log_time", "markers": [{"ns", "id",
"type", "action", "position", "orientation", "scale", "points"}], "state":
the `/sar/estimate/state` of the same log time ({"ujoint_m", "tip_m",
"tip_force_n"}) or null}, and "jazzy": the nested types of the scene's
schemas whose fields differ from rosbags' ROS 2 Jazzy type store
([name, ours, jazzy]; empty when they all agree).
Exit 0 when it ran (the caller checks the failures), 3 when rosbags is missing.
"""
import json
import sys

try:
    from rosbags.interfaces import (
        MessageDefinitionFormat,
        QosDurability,
        QosHistory,
        QosReliability,
    )
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
except ImportError as e:  # pragma: no cover
    print(f"missing Python package: {e} (scripts/setup-test-readers.sh)", file=sys.stderr)
    sys.exit(3)


SCENE_TYPES = ("visualization_msgs/msg/MarkerArray", "tf2_msgs/msg/TFMessage")


def fields(defs):
    """A type's fields without constants or defaults: [(name, kind)]."""
    return [(name, repr(kind)) for name, kind in defs[1]]


def jazzy_mismatches(types):
    jazzy = get_typestore(Stores.ROS2_JAZZY).fielddefs
    return [[name, fields(d), fields(jazzy[name])] for name, d in sorted(types.items())
            if name not in jazzy or fields(d) != fields(jazzy[name])]


def vec(v):
    return [v.x, v.y, v.z]


def marker(m):
    return {"ns": m.ns, "id": m.id, "type": m.type, "action": m.action,
            "position": vec(m.pose.position),
            "orientation": [m.pose.orientation.x, m.pose.orientation.y,
                            m.pose.orientation.z, m.pose.orientation.w],
            "scale": vec(m.scale), "points": [vec(p) for p in m.points]}


def check(path, scene=False):
    out = {"path": path, "schemas": 0, "channels": 0, "messages": 0, "failures": 0,
           "errors": [], "topics": {}}
    scenes, states, scene_types = [], {}, {}

    def fail(what):
        out["failures"] += 1
        if len(out["errors"]) < 20:
            out["errors"].append(what)

    try:
        with Reader(path) as reader:
            store = get_typestore(Stores.EMPTY)
            types = {}
            seen = set()
            for c in reader.connections:
                out["channels"] += 1
                if c.msgdef.format != MessageDefinitionFormat.MSG:
                    fail(f"{c.topic}: schema format {c.msgdef.format}")
                    continue
                if c.msgtype not in seen:
                    seen.add(c.msgtype)
                    out["schemas"] += 1
                    try:
                        found = get_types_from_msg(c.msgdef.data, c.msgtype)
                        types.update(found)
                        if c.msgtype in SCENE_TYPES:
                            scene_types.update(found)
                    except Exception as e:  # noqa: BLE001
                        fail(f"{c.topic}: schema {c.msgtype}: {e}")
                qos = c.ext.offered_qos_profiles
                if len(qos) != 1:
                    fail(f"{c.topic}: {len(qos)} offered QoS profiles")
                for q in qos:
                    if (q.history == QosHistory.UNKNOWN or q.reliability == QosReliability.UNKNOWN
                            or q.durability == QosDurability.UNKNOWN):
                        fail(f"{c.topic}: QoS not understood: {q}")
            store.register(types)
            for c, _t, raw in reader.messages():
                out["messages"] += 1
                out["topics"][c.topic] = out["topics"].get(c.topic, 0) + 1
                try:
                    msg = store.deserialize_cdr(raw, c.msgtype)
                except Exception as e:  # noqa: BLE001
                    fail(f"{c.topic}: message: {e}")
                    continue
                if not scene:
                    continue
                if c.topic == "/sar/estimate/state":
                    states[_t] = {"ujoint_m": list(msg.ujoint_m), "tip_m": list(msg.tip_m),
                                  "tip_force_n": list(msg.tip_force_n)}
                elif c.topic == "/sar/scene" and len(scenes) < 30 and any(
                        m.ns == "tip_force" and m.id == 0 and m.action == 0 for m in msg.markers):
                    scenes.append({"log_time": _t,
                                   "markers": [marker(m) for m in msg.markers]})
    except Exception as e:  # noqa: BLE001
        fail(f"open: {type(e).__name__}: {e}")
    if scene:
        for sc in scenes:
            sc["state"] = states.get(sc["log_time"])
        out["scene"] = scenes
        out["jazzy"] = jazzy_mismatches(scene_types)
    return out


def main():
    args = sys.argv[1:]
    scene = "--scene" in args
    files = [a for a in args if a != "--scene"]
    print(json.dumps({"files": [check(p, scene) for p in files]}))


if __name__ == "__main__":
    main()
