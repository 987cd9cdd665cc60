#!/usr/bin/env python3
"""An independent reader of a SAR recording: the `mcap`, `mcap-ros2-support` and
`mcap-protobuf-support` packages decode every message with the ROS 2 decoder
(cdr topics) or the protobuf decoder (the 3D scene), from the schemas the file
carries, and print one canonical line per message, which the Rust tests compare
with what they recorded.

Usage: read_recording.py FILE.mcap
Output:
  profile <profile>
  channel <topic> <schema name> <schema encoding> <message encoding>
  msg <topic>|<sequence>|<log_time>|<publish_time>|<field>=<value>;...
Values: f64 as its IEEE bits in decimal (f:<bits>), integers (i:<v>), bools
(b:0|1), strings as the hex of their UTF-8 bytes (s:<hex>); arrays flattened
as field[i]. Exit 3 when the packages are missing.
"""
import struct
import sys

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
except ImportError as e:  # pragma: no cover
    print(
        f"missing Python package: {e} (scripts/setup-test-readers.sh installs it)",
        file=sys.stderr,
    )
    sys.exit(3)


def flatten(prefix, value, out):
    if isinstance(value, bool):
        out.append(f"{prefix}=b:{int(value)}")
    elif isinstance(value, float):
        out.append(f"{prefix}=f:{struct.unpack('<Q', struct.pack('<d', value))[0]}")
    elif isinstance(value, int):
        out.append(f"{prefix}=i:{value}")
    elif isinstance(value, str):
        out.append(f"{prefix}=s:{value.encode('utf-8').hex()}")
    elif isinstance(value, (bytes, bytearray)):
        # A uint8[] (e.g. a Marker's empty texture data).
        out.append(f"{prefix}=x:{bytes(value).hex()}")
    elif isinstance(value, (list, tuple)) or hasattr(value, "tolist"):
        items = value.tolist() if hasattr(value, "tolist") else value
        for i, v in enumerate(items):
            flatten(f"{prefix}[{i}]", v, out)
    elif hasattr(value, "ListFields"):
        # A protobuf message: its set fields, by name.
        for field, v in value.ListFields():
            flatten(f"{prefix}.{field.name}" if prefix else field.name, v, out)
    elif hasattr(value, "__len__") and hasattr(value, "__getitem__") and not isinstance(
        value, (str, bytes)
    ):
        # A protobuf repeated field.
        for i in range(len(value)):
            flatten(f"{prefix}[{i}]", value[i], out)
    elif hasattr(value, "__slots__"):
        for name in value.__slots__:
            flatten(f"{prefix}.{name}" if prefix else name, getattr(value, name), out)
    else:
        raise TypeError(f"{prefix}: unexpected {type(value)}")


def main():
    path = sys.argv[1]
    lines = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory(), ProtobufDecoderFactory()])
        header = reader.get_header()
        print(f"profile {header.profile}")
        summary = reader.get_summary()
        for cid in sorted(summary.channels):
            ch = summary.channels[cid]
            sc = summary.schemas[ch.schema_id]
            print(f"channel {ch.topic} {sc.name} {sc.encoding} {ch.message_encoding}")
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            fields = []
            flatten("", decoded, fields)
            lines.append(
                (channel.topic, message.sequence,
                 f"msg {channel.topic}|{message.sequence}|{message.log_time}|{message.publish_time}|"
                 + ";".join(fields))
            )
    lines.sort(key=lambda t: (t[0], t[1]))
    for _, _, line in lines:
        print(line)


if __name__ == "__main__":
    main()
