#!/usr/bin/env python3
"""Writes IMU frames into a serial port with pyserial, as a device would, garbage included.

Used by tests/serial_imu_peers.rs. Usage: serial_write.py PORT PROTOCOL SAMPLES SEED, PROTOCOL
mip or witmotion. Frames are built here, independently of STARC's encoder:

- mip: one 0x80 packet per sample: accel (0x04) = [k/1000, 0.5, -1] g, gyro (0x05) =
  [k/10000, -0.25, 0.125] rad/s, GPS time (0x12) = tow k/100 s, week 2300, flags 7;
- witmotion: acc (0x51) [k, -k, 2048, 2500], gyro (0x52) [3k, 1, -1, 2500], angle (0x53)
  [100, 200, k, 0].

Every 5th sample is preceded by garbage: for WitMotion a stray 0x55 (the case PyPI `witmotion`
gets wrong) or `55 51`; for MIP a stray 0x75 or a false header `75 65 80 ff`. Bytes go out in
random chunks with short pauses. For WitMotion the same bytes are also run through PyPI
`witmotion`'s own receive loop (over a stand-in port) to count what it decodes. Prints JSON.
"""

import json
import random
import struct
import sys
import time

import serial


def fletcher16(b):
    s1 = s2 = 0
    for x in b:
        s1 = (s1 + x) & 0xFF
        s2 = (s2 + s1) & 0xFF
    return bytes([s1, s2])


def mip_sample(k):
    fields = [
        (0x04, struct.pack(">fff", k / 1000.0, 0.5, -1.0)),
        (0x05, struct.pack(">fff", k / 10000.0, -0.25, 0.125)),
        (0x12, struct.pack(">dHH", k / 100.0, 2300, 7)),
    ]
    payload = b"".join(bytes([len(d) + 2, desc]) + d for desc, d in fields)
    body = bytes([0x75, 0x65, 0x80, len(payload)]) + payload
    return body + fletcher16(body)


def wit_frame(kind, values):
    body = bytes([0x55, kind]) + struct.pack("<hhhh", *values)
    return body + bytes([sum(body) & 0xFF])


def wit_sample(k):
    return (
        wit_frame(0x51, (k, -k, 2048, 2500))
        + wit_frame(0x52, (3 * k, 1, -1, 2500))
        + wit_frame(0x53, (100, 200, k, 0))
    )


class StandIn:
    """A port that hands out fixed bytes, for running witmotion's receive loop on them."""

    def __init__(self, data, imu):
        self.data, self.pos, self.imu = data, 0, imu

    def read(self, size=1):
        chunk = self.data[self.pos : self.pos + size]
        self.pos += len(chunk)
        if not chunk:
            self.imu.should_exit = True
        return chunk


def pypi_witmotion_decode(data):
    import witmotion
    from witmotion import protocol

    imu = witmotion.IMU.__new__(witmotion.IMU)
    imu.ser = StandIn(data, imu)
    imu.should_exit = False
    imu.subscribers = {None: []}
    for attr in ("last_timestamp", "last_temp_celsius", "last_a", "last_w", "last_q", "last_mag"):
        setattr(imu, attr, None)
    frames = []
    imu.subscribers = __import__("collections").defaultdict(list)
    imu.subscribe(lambda m: frames.append(type(m).__name__))
    imu._rxloop()
    return len(frames)


def main() -> int:
    port, proto, samples, seed = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    rng = random.Random(seed)
    stream = bytearray()
    garbage_bursts = garbage_bytes = 0
    for k in range(samples):
        if k % 5 == 4 and k + 1 < samples:
            if proto == "witmotion":
                g = bytes([0x55]) if rng.random() < 0.5 else bytes([0x55, 0x51])
            else:
                g = bytes([0x75]) if rng.random() < 0.5 else bytes([0x75, 0x65, 0x80, 0xFF])
            stream += g
            garbage_bursts += 1
            garbage_bytes += len(g)
        stream += mip_sample(k) if proto == "mip" else wit_sample(k)
    with serial.Serial(port, 115200, timeout=1) as s:
        pos = 0
        while pos < len(stream):
            n = rng.randint(1, 64)
            s.write(stream[pos : pos + n])
            pos += n
            time.sleep(0.0005)
        s.flush()
    result = {"samples": samples, "bytes": len(stream), "garbage_bursts": garbage_bursts, "garbage_bytes": garbage_bytes}
    if proto == "witmotion":
        result["pypi_witmotion_frames"] = pypi_witmotion_decode(bytes(stream))
        result["frames"] = 3 * samples
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
