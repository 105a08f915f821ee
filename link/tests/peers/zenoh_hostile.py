"""A hostile zenoh peer (the eclipse-zenoh Python package) for starc-link's tests.

It dials (--connect) or listens on (--listen) one endpoint only, on loopback, never scouting,
with what TLS material it is given (--ca alone: trusts our CA but shows no certificate; --cert
and --key as well: an insider holding a stolen certificate). It subscribes to everything and
puts what a hostile end would, built from docs/link.md's frame layout alone (struct +
zlib.crc32):

- default: every 20 ms a rig heartbeat, a robot heartbeat and robot detections (a stranger
  trying to bring a node up or pass off robot messages; or a fake robot the rig dials);
- --flood: messages beyond a rig's role and junk on its own keys, cycling through: robot
  detections, robot map tiles, robot heartbeats, garbage on the rig's heartbeat and clock keys,
  15 MiB of junk on the rig's and the robot's detections keys (a few) and one message of
  17 MiB, beyond the link's zenoh max_message_size (16 MiB + 64 KiB).

Bounded: at most --max-puts puts and --seconds seconds. Prints one JSON line: the most
transports it ever had open, samples heard from others, and puts made per category.
"""

import argparse
import json
import os
import struct
import sys
import time
import zlib

import zenoh

MIB = 1 << 20
# Forged detections carry seq from here on, so the test can tell them from the robot's own.
FORGED_SEQ = 1_000_000


def frame(kind: int, payload: bytes) -> bytes:
    head = struct.pack("<4sBBHI", b"STLK", 2, kind, 0, len(payload)) + payload
    return head + struct.pack("<I", zlib.crc32(head))


def heartbeat(role: int, seq: int, map_tiles: int = 0) -> bytes:
    return frame(1, struct.pack("<B3xIQI", role, seq, time.time_ns(), map_tiles))


def detections(seq: int) -> bytes:
    now = time.time_ns()
    # seq, scan-end stamp on the PTP clock (2), last packet and sent host times, no people.
    return frame(5, struct.pack("<IQBQQI", seq, now, 2, now, now, 0))


def map_tile(i: int) -> bytes:
    # A tile header that names tile (i, 0, 0) at a version far ahead, then junk.
    return frame(6, b"STMT" + struct.pack("<BxxxIiiiI", 1, 0, i, 0, 0, 0xFFFF_FFFF) + bytes(64))


def plan(flood: bool):
    """(category, key, payload maker) in the order they are put, cycled."""
    if not flood:
        return [
            ("rig_heartbeat", "starc/rig/heartbeat", lambda i: heartbeat(2, i)),
            ("robot_heartbeat", "starc/robot/heartbeat", lambda i: heartbeat(1, i)),
            ("robot_detections", "starc/robot/detections", lambda i: detections(FORGED_SEQ + i)),
        ]
    return [
        ("robot_detections", "starc/robot/detections", lambda i: detections(FORGED_SEQ + i)),
        ("robot_map_tile", "starc/robot/map_tile", map_tile),
        ("robot_heartbeat", "starc/robot/heartbeat", lambda i: heartbeat(1, i, 1_000_000)),
        ("rig_garbage", "starc/rig/heartbeat", lambda i: os.urandom(64 + i % 512)),
        ("rig_garbage", "starc/rig/clock_probe", lambda i: b"STLK" + os.urandom(32)),
    ]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect")
    ap.add_argument("--listen")
    ap.add_argument("--ca")
    ap.add_argument("--cert")
    ap.add_argument("--key")
    ap.add_argument("--mode", default="peer", choices=["peer", "client"])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--max-puts", type=int, default=2000)
    ap.add_argument("--flood", action="store_true")
    args = ap.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(args.mode))
    conf.insert_json5("connect/endpoints", json.dumps([args.connect] if args.connect else []))
    conf.insert_json5("listen/endpoints", json.dumps([args.listen] if args.listen else []))
    conf.insert_json5("connect/timeout_ms", "-1")
    conf.insert_json5("connect/exit_on_failure", "false")
    conf.insert_json5("connect/retry", "{ period_init_ms: 100, period_max_ms: 100, period_increase_factor: 1 }")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    if args.ca:
        conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(args.ca))
    if args.cert and args.key:
        for side in ("connect", "listen"):
            conf.insert_json5(f"transport/link/tls/{side}_certificate", json.dumps(args.cert))
            conf.insert_json5(f"transport/link/tls/{side}_private_key", json.dumps(args.key))
        conf.insert_json5("transport/link/tls/enable_mtls", "true")
    # A fake robot the rig dials must not check the rig's name in turn.
    conf.insert_json5("transport/link/tls/verify_name_on_connect", "false")

    heard = 0
    heard_keys = []

    def on_sample(sample):
        nonlocal heard
        heard += 1
        if len(heard_keys) < 5:
            heard_keys.append(str(sample.key_expr))

    puts = {}
    errors = 0
    most_transports = 0
    steps = plan(args.flood)
    # The large ones, one every 40 puts while they last: (category, key, bytes).
    large = [("rig_large", "starc/rig/detections", 15 * MIB)] * 6
    large += [("robot_large", "starc/robot/detections", 15 * MIB)] * 3
    large += [("oversize", "starc/rig/detections", 17 * MIB)]
    matched = False
    with zenoh.open(conf) as session:
        # Connect (or be refused): 1 s at most (a listener: until the rig has dialled in). Then,
        # connected, learn the robot's rig-key subscription (2 s at most), so that no put below
        # is dropped here for want of a subscriber.
        until = time.monotonic() + 1.0
        while time.monotonic() < until and not session.info.transports():
            time.sleep(0.02)
        probe = session.declare_publisher("starc/rig/heartbeat")
        until = time.monotonic() + 2.0
        while args.connect and session.info.transports() and time.monotonic() < until and not probe.matching_status.matching:
            time.sleep(0.02)
        matched = probe.matching_status.matching
        probe.undeclare()
        session.declare_subscriber("**", on_sample, allowed_origin=zenoh.Locality.REMOTE)
        deadline = time.monotonic() + args.seconds
        i = 0
        total = 0
        while time.monotonic() < deadline and total < args.max_puts:
            most_transports = max(most_transports, len(session.info.transports()))
            category, key, make = steps[i % len(steps)]
            batch = [(category, key, make(i))]
            if args.flood and i % 40 == 20 and large:
                name, lkey, size = large.pop(0)
                batch.append((name, lkey, bytes(size)))
            for category, key, payload in batch:
                try:
                    session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
                    puts[category] = puts.get(category, 0) + 1
                except zenoh.ZError:
                    errors += 1
                total += 1
            i += 1
            if not args.flood:
                time.sleep(0.02)
            elif i % 100 == 0:
                # Let the other end's counters keep up; still hundreds of puts a second.
                time.sleep(0.01)
        most_transports = max(most_transports, len(session.info.transports()))
        # Whatever is still on its way may still be heard.
        time.sleep(0.3)
    out = {"transports": most_transports, "matched": int(matched), "heard": heard, "errors": errors}
    out["puts"] = sum(puts.values())
    out.update(puts)
    out["heard_keys"] = heard_keys
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
