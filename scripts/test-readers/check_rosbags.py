#!/usr/bin/env python3
"""A strict check of MCAP recordings with Python `rosbags` (as a ROS 2 user
would open them): `rosbags.rosbag2.Reader` opens each file (it refuses a file
whose profile is not `ros2`), a type store is built ONLY from the schemas
embedded in the file (`Stores.EMPTY` + `get_types_from_msg` per schema), and
every message is deserialized from CDR with it. Each channel's
`offered_qos_profiles` must parse (history, reliability, durability known).

Usage: check_rosbags.py FILE.mcap...
Prints one JSON object: {"files": [{"path", "schemas", "channels",
"messages", "failures", "errors": [...], "topics": {topic: count}}]}.
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


def check(path):
    out = {"path": path, "schemas": 0, "channels": 0, "messages": 0, "failures": 0,
           "errors": [], "topics": {}}

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
                        types.update(get_types_from_msg(c.msgdef.data, c.msgtype))
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
                    store.deserialize_cdr(raw, c.msgtype)
                except Exception as e:  # noqa: BLE001
                    fail(f"{c.topic}: message: {e}")
    except Exception as e:  # noqa: BLE001
        fail(f"open: {type(e).__name__}: {e}")
    return out


def main():
    print(json.dumps({"files": [check(p) for p in sys.argv[1:]]}))


if __name__ == "__main__":
    main()
