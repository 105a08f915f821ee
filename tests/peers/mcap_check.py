"""Decode a STARC MCAP recording with real ROS 2 tooling and compare with what was written.

Usage:
  mcap_check.py full RECORDING EXPECTED.json
      Every message decoded three ways: PyPI `mcap` + `mcap-ros2-support` (from the schemas
      stored in the file), `rosbags` AnyReader (opens the .mcap as a rosbag2 recording and parses
      the stored definitions itself), and rosbags' built-in ROS 2 Humble typestore (independent
      definitions: checks our byte layout). Field values must match EXPECTED (written by the
      Rust test). Prints one JSON line with the counts.
  mcap_check.py topics RECORDING
      Decodes every message with `mcap` + `mcap-ros2-support` and opens the file with rosbags'
      AnyReader; prints one JSON line: messages per topic (mcap) and per topic (rosbags).
  mcap_check.py recover RECORDING
      Reads a file that lost its end (no summary, no footer) with `mcap`'s non-seeking reader,
      as far as it goes; prints one JSON line with the count and the error that stopped it.
"""

import json
import math
import sys
from pathlib import Path


def close(a, b, tol=1e-6):
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(close(x, y, tol) for x, y in zip(a, b))
    return math.isclose(float(a), float(b), rel_tol=tol, abs_tol=tol)


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def vec(v):
    return [v.x, v.y, v.z]


def quat(q):
    return [q.x, q.y, q.z, q.w]


def point_values(msg, i):
    """One point of our layout, read by the offsets the message itself declares."""
    import struct

    offsets = {f.name: (f.offset, f.datatype) for f in msg.fields}
    base = i * msg.point_step
    data = bytes(msg.data)
    fmt = {7: "<f", 6: "<I", 2: "<B"}
    out = []
    for name in ["x", "y", "z", "intensity", "t", "line", "tag"]:
        off, dt = offsets[name]
        out.append(struct.unpack_from(fmt[dt], data, base + off)[0])
    return out


def summarize(topic, msg):
    """The fields the Rust side wrote into EXPECTED, from a decoded message of any of the decoders."""
    if topic == "/robot/points":
        return {
            "frame": msg.header.frame_id,
            "stamp_ns": stamp_ns(msg.header),
            "width": msg.width,
            "height": msg.height,
            "point_step": msg.point_step,
            "fields": [[f.name, f.offset, f.datatype, f.count] for f in msg.fields],
            "first": point_values(msg, 0),
            "last": point_values(msg, msg.width - 1),
        }
    if topic == "/robot/imu":
        return {
            "frame": msg.header.frame_id,
            "stamp_ns": stamp_ns(msg.header),
            "gyro": vec(msg.angular_velocity),
            "acc": vec(msg.linear_acceleration),
            "orientation_covariance0": msg.orientation_covariance[0],
        }
    if topic == "/robot/can/rx":
        return {
            "stamp_ns": stamp_ns(msg.header),
            "id": msg.id,
            "is_rtr": bool(msg.is_rtr),
            "is_extended": bool(msg.is_extended),
            "is_error": bool(msg.is_error),
            "dlc": msg.dlc,
            "data": [int(b) for b in msg.data],
        }
    if topic in ("/robot/odom", "/fpv/odom", "/robot/wheel_odom"):
        return {
            "frame": msg.header.frame_id,
            "child": msg.child_frame_id,
            "stamp_ns": stamp_ns(msg.header),
            "position": vec(msg.pose.pose.position),
            "orientation": quat(msg.pose.pose.orientation),
            "linear": vec(msg.twist.twist.linear),
            "angular": vec(msg.twist.twist.angular),
        }
    if topic in ("/tf", "/tf_static"):
        return {
            "transforms": [
                [t.header.frame_id, t.child_frame_id, stamp_ns(t.header), vec(t.transform.translation), quat(t.transform.rotation)]
                for t in msg.transforms
            ]
        }
    if topic == "/detections/markers":
        return {
            "markers": [
                [m.ns, m.id, m.type, m.action, m.header.frame_id, vec(m.pose.position), quat(m.pose.orientation), vec(m.scale), m.text]
                for m in msg.markers
            ]
        }
    if topic == "/fpv/ar_image/compressed":
        data = bytes(msg.data)
        return {
            "frame": msg.header.frame_id,
            "stamp_ns": stamp_ns(msg.header),
            "format": msg.format,
            "png_signature": data[:8] == b"\x89PNG\r\n\x1a\n",
            "png_width": int.from_bytes(data[16:20], "big"),
            "png_height": int.from_bytes(data[20:24], "big"),
            "bytes": len(data),
        }
    raise ValueError(f"unexpected topic {topic}")


def same(a, b):
    """Deep comparison, floats with a tolerance (f32 fields went through float32)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return isinstance(b, (list, tuple)) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return close(a, b)
    return a == b


def full(path, expected_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    expected = json.loads(Path(expected_path).read_text())
    humble = get_typestore(Stores.ROS2_HUMBLE)
    failures = []
    counts = {"mcap_ros2": 0, "rosbags_anyreader": 0, "rosbags_humble": 0}
    topics = {}

    # 1. mcap + mcap-ros2-support, and rosbags' Humble typestore on the same raw payloads.
    got_mcap = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr", (schema.encoding, channel.message_encoding)
            got_mcap.append([channel.topic, message.log_time, summarize(channel.topic, decoded)])
            counts["mcap_ros2"] += 1
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
            if schema.name not in humble.fielddefs:
                # Not a Humble core type (can_msgs/msg/Frame): register it from the file's own
                # definition, as a user without that package installed would.
                text = schema.data.decode().split("\n" + "=" * 80)[0]
                humble.register(get_types_from_msg(text, schema.name))
            h = humble.deserialize_cdr(message.data, schema.name)
            if not same(summarize(channel.topic, h), got_mcap[-1][2]):
                failures.append(f"humble typestore disagrees on {channel.topic} at {message.log_time}")
            counts["rosbags_humble"] += 1
    stats = summary.statistics if summary else None

    # 2. rosbags AnyReader: the .mcap opened as a rosbag2 recording.
    got_rosbags = []
    qos = {}
    with AnyReader([Path(path)]) as reader:
        for conn in reader.connections:
            profiles = conn.ext.offered_qos_profiles
            qos[conn.topic] = [p.durability.name.lower() for p in profiles]
        for conn, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            got_rosbags.append([conn.topic, timestamp, summarize(conn.topic, msg)])
            counts["rosbags_anyreader"] += 1

    key = lambda m: (m[0], m[1])
    exp = sorted(expected, key=key)
    for name, got in (("mcap_ros2", got_mcap), ("rosbags_anyreader", got_rosbags)):
        got = sorted(got, key=key)
        if len(got) != len(exp):
            failures.append(f"{name}: {len(got)} messages, expected {len(exp)}")
        for g, e in zip(got, exp):
            if not same(g, e):
                failures.append(f"{name}: {g[0]} at {g[1]}: got {json.dumps(g[2])} expected {json.dumps(e[2])}")
                if len(failures) > 10:
                    break

    print(
        json.dumps(
            {
                "ok": not failures,
                "counts": counts,
                "topics": topics,
                "durability": qos,
                "summary_messages": stats.message_count if stats else None,
                "summary_chunks": stats.chunk_count if stats else None,
                "failures": failures[:10],
            }
        )
    )


def recover(path):
    from mcap.reader import NonSeekingReader

    n = 0
    stopped_by = None
    topics = {}
    with open(path, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True)
        try:
            for _schema, channel, _message in reader.iter_messages(log_time_order=False):
                n += 1
                topics[channel.topic] = topics.get(channel.topic, 0) + 1
        except Exception as e:  # the reader's way to say where the file ends
            stopped_by = f"{type(e).__name__}: {e}"
    print(json.dumps({"messages": n, "topics": topics, "stopped_by": stopped_by}))



def topics(path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    counts = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert decoded is not None
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    rosbags_counts = {}
    with AnyReader([Path(path)]) as r:
        for conn, _t, raw in r.messages():
            r.deserialize(raw, conn.msgtype)
            rosbags_counts[conn.topic] = rosbags_counts.get(conn.topic, 0) + 1
    print(json.dumps({"mcap": counts, "rosbags": rosbags_counts}))

if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "topics":
        topics(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "full":
        full(sys.argv[2], sys.argv[3])
    elif len(sys.argv) == 3 and sys.argv[1] == "recover":
        recover(sys.argv[2])
    else:
        sys.exit(__doc__)
