"""A ROS 2 system's side of the rmw_zenoh wire, for starc-link's ROS 2 bridge tests.

Plays the ROS 2 router (eclipse-zenoh in router mode, listening on 127.0.0.1:<port>, plain tcp,
or mutual tls with the certificate `starc link certs` makes for 127.0.0.1, robot.pem, in <certdir>), watches every rmw_zenoh liveliness token and every
sample on `<domain>/**`, decodes each payload with rosbags (Jazzy types, plus vision_msgs
written here from its .msg files), and publishes geometry_msgs/Twist (2 m/s forward, 0.1 rad/s)
on <cmd_vel key> with rmw_zenoh's attachment at 20 Hz for one second once the bridge's subscription token is seen (or
2 s passed without it).
Prints "ready", then one JSON line at the end.

usage: ros2_peer.py PORT SECONDS plain|tls CERTDIR CMD_VEL_KEY
"""

import json
import signal
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

VISION = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
}


def typestore():
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name, text in VISION.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def ros_type(dds: str) -> str:
    # sensor_msgs::msg::dds_::Imu_ -> sensor_msgs/msg/Imu
    pkg, kind, _, ty = dds.split("::")
    return f"{pkg}/{kind}/{ty[:-1]}"


def summary(msg) -> dict:
    out = {}
    header = getattr(msg, "header", None)
    if header is not None:
        out["frame_id"] = header.frame_id
        out["stamp_ns"] = header.stamp.sec * 1_000_000_000 + header.stamp.nanosec
    for field in ("width", "point_step", "child_frame_id", "format"):
        if hasattr(msg, field):
            out[field] = getattr(msg, field)
    if hasattr(msg, "transforms"):
        out["transforms"] = [[t.header.frame_id, t.child_frame_id] for t in msg.transforms]
    if hasattr(msg, "markers"):
        out["markers"] = len(msg.markers)
    if hasattr(msg, "detections"):
        out["detections"] = [
            [d.id, *[r.hypothesis.class_id for r in d.results], d.bbox.size.z] for d in msg.detections
        ]
    if hasattr(msg, "linear_acceleration"):
        out["acc_z"] = msg.linear_acceleration.z
    if hasattr(msg, "pose") and hasattr(msg.pose, "pose"):
        out["x"] = msg.pose.pose.position.x
    if hasattr(msg, "data") and hasattr(msg, "format"):
        out["data_len"] = len(msg.data)
    return out


def main() -> int:
    port, seconds, mode, certdir, cmd_vel_key = sys.argv[1:6]
    store = typestore()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([f"{mode if mode == 'tls' else 'tcp'}/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    if mode == "tls":
        conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(f"{certdir}/ca.pem"))
        conf.insert_json5("transport/link/tls/listen_certificate", json.dumps(f"{certdir}/robot.pem"))
        conf.insert_json5("transport/link/tls/listen_private_key", json.dumps(f"{certdir}/robot.key"))
        conf.insert_json5("transport/link/tls/enable_mtls", "true")
    lock = threading.Lock()
    tokens, samples, errors = [], {}, []

    def on_token(sample):
        with lock:
            tokens.append([str(sample.kind), str(sample.key_expr)])

    def on_sample(sample):
        key = str(sample.key_expr)
        att = sample.attachment.to_bytes() if sample.attachment is not None else b""
        entry = samples.setdefault(key, {"count": 0, "seqs": [], "attachment_len": len(att)})
        try:
            msg = store.deserialize_cdr(sample.payload.to_bytes(), ros_type(key.split("/")[-2]))
            with lock:
                entry["count"] += 1
                if len(att) == 33:
                    entry["seqs"].append(struct.unpack_from("<q", att, 0)[0])
                entry["first"] = entry.get("first") or summary(msg)
        except Exception as e:  # noqa: BLE001: reported to the test, which fails on it
            with lock:
                errors.append(f"{key}: {e!r}")

    deadline = time.monotonic() + float(seconds)
    # SIGINT or SIGTERM end the watch early, with the report still printed.
    stopping = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stopping.set())
    sent, last_sent_ns = 0, None
    with zenoh.open(conf) as session:
        session.liveliness().declare_subscriber("@ros2_lv/**", on_token, history=True)
        session.declare_subscriber("*/**", on_sample)
        pub = session.declare_publisher(cmd_vel_key)
        print("ready", flush=True)
        gid = bytes(range(16))
        # Sends anyway after 2 s without the subscription's token (a bridge that refuses us).
        send_anyway_at = time.monotonic() + 2.0
        while time.monotonic() < deadline and not stopping.is_set():
            with lock:
                sub_seen = any("/MS/" in k and "cmd_vel" in k for _, k in tokens)
            if (sub_seen or time.monotonic() > send_anyway_at) and sent < 20:
                sent += 1
                # 2 m/s forward: past the base's 1 m/s limit, which the base must apply.
                payload = b"\x00\x01\x00\x00" + struct.pack("<6d", 2.0, 0.0, 0.0, 0.0, 0.0, 0.1)
                last_sent_ns = time.time_ns()
                att = struct.pack("<qqB", sent, last_sent_ns, 16) + gid
                pub.put(payload, attachment=att)
            time.sleep(0.05)
    with lock:
        print(json.dumps({"tokens": tokens, "samples": samples, "errors": errors, "cmd_vel_sent": sent,
                          "last_cmd_vel_ns": last_sent_ns}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
