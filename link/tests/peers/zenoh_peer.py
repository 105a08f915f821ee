"""A real zenoh peer (the eclipse-zenoh Python package) for starc-link's tests.

Connects to the robot at tcp/127.0.0.1:<port> (no scouting, no listening), publishes rig
heartbeats built from docs/link.md's layout alone (struct + zlib.crc32), and prints the first
robot heartbeat it receives as JSON: {"key": ..., "hex": ...}. Exits after <seconds> at most.
"""

import json
import struct
import sys
import time
import zlib

import zenoh


def rig_heartbeat(seq: int) -> bytes:
    payload = struct.pack("<B3xIQI", 2, seq, time.time_ns(), 0)
    frame = struct.pack("<4sBBHI", b"STLK", 2, 1, 0, len(payload)) + payload
    return frame + struct.pack("<I", zlib.crc32(frame))


def main() -> int:
    port, seconds = int(sys.argv[1]), float(sys.argv[2])
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    deadline = time.monotonic() + seconds
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber("starc/robot/heartbeat")
        pub = session.declare_publisher("starc/rig/heartbeat")
        seq = 0
        got = None
        # Keep sending after the first robot heartbeat for a while, so the robot sees us Up.
        linger_until = None
        while time.monotonic() < deadline:
            pub.put(rig_heartbeat(seq))
            seq += 1
            sample = sub.try_recv()
            if sample is not None and got is None:
                got = {"key": str(sample.key_expr), "hex": sample.payload.to_bytes().hex()}
                print(json.dumps(got), flush=True)
                linger_until = time.monotonic() + 1.0
            if linger_until is not None and time.monotonic() > linger_until:
                break
            time.sleep(0.02)
    return 0 if got is not None else 1


if __name__ == "__main__":
    sys.exit(main())
