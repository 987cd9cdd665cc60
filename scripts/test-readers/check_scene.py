#!/usr/bin/env python3
"""The 3D scene of a recording as Python `rosbags` reads it, with none of
this project's code: the type store is built only from the schemas the file
embeds, and
- every type of the scene's schemas (`visualization_msgs/msg/MarkerArray`,
  `tf2_msgs/msg/TFMessage` and all they nest) has the field names and types
  of ROS 2 Jazzy's (`Stores.ROS2_JAZZY`, rosbags' built-in store);
- one `/sar/scene` message whose tip force arrow is drawn is decoded, with
  the `/sar/estimate/state` of the same log time.

Usage: check_scene.py FILE.mcap
Prints one JSON object: {"mismatches": [...], "types": N, "scene": {"rod":
[[x,y,z],[x,y,z]], "arrow": [[...],[...]], "arrow_action": int,
"frame_id": str}, "state": {"ujoint_m", "tip_m", "tip_force_n"},
"tf_static": [[parent, child]]}.
"""
import json
import sys

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

SCENE_TYPES = ("visualization_msgs/msg/MarkerArray", "tf2_msgs/msg/TFMessage")


def nested(types, name, seen):
    """`name` and every type its fields name, recursively."""
    if name in seen or name not in types:
        return
    seen.add(name)
    for _, desc in types[name][1]:
        node = desc
        while isinstance(node, tuple) and node and not isinstance(node[0], str) and int(node[0]) in (3, 4):
            node = node[1][0]
        if isinstance(node, tuple) and int(node[0]) == 2:
            nested(types, node[1], seen)


def main(path):
    out = {"mismatches": [], "types": 0}
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    with Reader(path) as reader:
        store = get_typestore(Stores.EMPTY)
        types = {}
        for c in reader.connections:
            types.update(get_types_from_msg(c.msgdef.data, c.msgtype))
        store.register(types)
        seen = set()
        for t in SCENE_TYPES:
            nested(types, t, seen)
        out["types"] = len(seen)
        for t in sorted(seen):
            ours = [(n, repr(d)) for n, d in types[t][1]]
            theirs = [(n, repr(d)) for n, d in jazzy.fielddefs[t][1]]
            if ours != theirs:
                out["mismatches"].append({"type": t, "ours": ours, "jazzy": theirs})
        states = {}
        scene = None
        tf_static = []
        for conn, t, raw in reader.messages():
            if conn.topic == "/sar/estimate/state":
                states[t] = store.deserialize_cdr(raw, conn.msgtype)
            elif conn.topic == "/tf_static":
                m = store.deserialize_cdr(raw, conn.msgtype)
                tf_static += [[x.header.frame_id, x.child_frame_id] for x in m.transforms]
            elif conn.topic == "/sar/scene" and scene is None:
                m = store.deserialize_cdr(raw, conn.msgtype)
                by = {(x.ns, x.id): x for x in m.markers}
                arrow = by[("tip_force", 0)]
                if arrow.action == 0:
                    scene = (t, by)
        if scene is None:
            raise SystemExit("no /sar/scene message with the tip force drawn")
        t, by = scene
        pts = lambda m: [[p.x, p.y, p.z] for p in m.points]
        rod, arrow = by[("rod", 0)], by[("tip_force", 0)]
        out["scene"] = {"rod": pts(rod), "arrow": pts(arrow), "arrow_action": arrow.action,
                        "frame_id": rod.header.frame_id, "markers": len(by)}
        st = states[t]
        out["state"] = {k: [float(x) for x in getattr(st, k)] for k in ("ujoint_m", "tip_m", "tip_force_n")}
        out["tf_static"] = tf_static
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
