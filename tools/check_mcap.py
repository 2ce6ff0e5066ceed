#!/usr/bin/env python3
"""Reads an sdem trajectory log with the official `mcap` package (PyPI) and prints what it holds.

    python3 -m venv target/mcap-venv && target/mcap-venv/bin/pip install mcap [mcap-ros2-support]
    target/mcap-venv/bin/python tools/check_mcap.py run.mcap [--frame K] [--grain G]

Prints the channels with their message counts (from the summary section and from a full pass
over the messages), the frame count, and one decoded grain state of frame K (default: the last).
The CDR channels are decoded from their ROS 2 schema text by the small reader below, so this
script checks that the schemas describe the bytes. If `mcap-ros2-support` is installed, the same
/grains message is also decoded by its ROS 2 decoder and the two decodings are compared.

Floats are printed with repr(), which round-trips exactly: tests compare them bit for bit.
Exit status: 0 if everything was read and consistent, 1 otherwise.
"""

import argparse
import json
import struct
import sys

from mcap.reader import make_reader

PRIMITIVES = {
    # type: (struct code, size)
    "bool": ("?", 1),
    "byte": ("B", 1),
    "char": ("B", 1),
    "int8": ("b", 1),
    "uint8": ("B", 1),
    "int16": ("h", 2),
    "uint16": ("H", 2),
    "int32": ("i", 4),
    "uint32": ("I", 4),
    "int64": ("q", 8),
    "uint64": ("Q", 8),
    "float32": ("f", 4),
    "float64": ("d", 8),
}


def parse_msg_schema(text):
    """Fields of a flat ROS 2 .msg definition: [(type, name, is_sequence)]."""
    fields = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        ftype, name = line.split()[:2]
        sequence = ftype.endswith("[]")
        fields.append((ftype[:-2] if sequence else ftype, name, sequence))
    return fields


def decode_cdr(fields, data):
    """Decodes plain little-endian CDR (XCDR1) of a flat message."""
    if len(data) < 4 or data[1] != 1:
        raise ValueError("not CDR_LE")
    pos = 4

    def align(size):
        nonlocal pos
        pos += (size - (pos - 4) % size) % size

    def scalar(ftype):
        nonlocal pos
        code, size = PRIMITIVES[ftype]
        align(size)
        (value,) = struct.unpack_from("<" + code, data, pos)
        pos += size
        return value

    out = {}
    for ftype, name, sequence in fields:
        if ftype == "string":
            if sequence:
                raise ValueError("string sequences not supported")
            n = scalar("uint32")
            out[name] = data[pos : pos + n - 1].decode("utf-8")
            pos += n
            continue
        if not sequence:
            out[name] = scalar(ftype)
            continue
        n = scalar("uint32")
        code, size = PRIMITIVES[ftype]
        if n:
            align(size)
        if pos + n * size > len(data):
            raise ValueError(f"{name}: sequence runs past the message end")
        out[name] = list(struct.unpack_from(f"<{n}{code}", data, pos))
        pos += n * size
    return out


def at_time(log_time):
    """Keyword arguments selecting the messages at one log time (new and old mcap releases)."""
    import inspect

    from mcap.reader import McapReader

    if "starting_at" in inspect.signature(McapReader.iter_messages).parameters:
        return {"starting_at": log_time, "ending_at": log_time}
    return {"start_time": log_time, "end_time": log_time + 1}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file")
    parser.add_argument("--frame", type=int, default=-1)
    parser.add_argument("--grain", type=int, default=0)
    args = parser.parse_args()

    with open(args.file, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        if summary is None:
            print("error: no summary section", file=sys.stderr)
            return 1
        print(f"library: {header.library}")
        counts = summary.statistics.channel_message_counts
        seen = {}
        grain_messages = []
        schemas = {}
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema
            if channel.topic == "/grains":
                grain_messages.append((message.log_time, message.data))
        for cid in sorted(summary.channels):
            ch = summary.channels[cid]
            schema = summary.schemas.get(ch.schema_id)
            print(
                f"channel {ch.topic} {schema.name if schema else '-'} "
                f"{schema.encoding if schema else '-'} {ch.message_encoding} "
                f"{counts.get(cid, 0)} {seen.get(ch.topic, 0)}"
            )
            if counts.get(cid, 0) != seen.get(ch.topic, 0):
                print(f"error: {ch.topic}: summary and messages disagree", file=sys.stderr)
                return 1
        print(f"frames {len(grain_messages)}")
        if not grain_messages:
            return 0
        log_time, data = grain_messages[args.frame]
        fields = parse_msg_schema(schemas["/grains"].data.decode("utf-8"))
        grains = decode_cdr(fields, data)
        g = args.grain
        print(f"frame log_time {log_time} step {grains['step']} time {grains['time']!r}")
        values = " ".join(
            f"{name}={grains[name][g]!r}"
            for _, name, sequence in fields
            if sequence
        )
        print(f"grain {g} {values}")
        print(f"grains {len(grains['x'])}")

        # The other channels of the same frame, decoded from their schemas.
        f.seek(0)
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(**at_time(log_time)):
            if schema.encoding == "ros2msg":
                msg = decode_cdr(parse_msg_schema(schema.data.decode("utf-8")), message.data)
                if channel.topic == "/contacts":
                    print(f"contacts {len(msg['first'])}")
                elif channel.topic == "/macro":
                    print(f"macro step={msg['step']} phase={msg['phase']} phi={msg['phi']!r} p_c={msg['p_c']!r}")
                elif channel.topic == "/walls":
                    print(f"walls {len(msg['point_x'])}")
            elif channel.topic == "/scene":
                scene = json.loads(message.data)
                cylinders = sum(len(e["cylinders"]) for e in scene["entities"])
                print(f"scene entities={len(scene['entities'])} cylinders={cylinders}")

    # Optional cross-check with the ROS 2 decoder of mcap-ros2-support.
    try:
        from mcap_ros2.decoder import DecoderFactory
    except ImportError:
        print("mcap_ros2: not installed, cross-check skipped")
        return 0
    with open(args.file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        checked = []
        for schema, channel, message in reader.iter_messages(**at_time(log_time)):
            if schema.encoding != "ros2msg":
                continue
            fields = parse_msg_schema(schema.data.decode("utf-8"))
            ours = decode_cdr(fields, message.data)
            theirs = DecoderFactory().decoder_for(channel.message_encoding, schema)(message.data)
            for _, name, sequence in fields:
                value = getattr(theirs, name)
                if (list(value) if sequence else value) != ours[name]:
                    print(f"error: mcap_ros2 decodes {channel.topic}.{name} differently", file=sys.stderr)
                    return 1
            checked.append(channel.topic)
        print(f"mcap_ros2: {' '.join(checked)} decoded identically")
    return 0


if __name__ == "__main__":
    sys.exit(main())
