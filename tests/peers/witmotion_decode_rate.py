#!/usr/bin/env python3
"""Times PyPI `witmotion`'s own receive loop over the bytes of a file (no serial port: a
stand-in hands out the bytes). Used by drivers/imu/benches/decode.rs for a side-by-side figure.
Usage: witmotion_decode_rate.py FILE. Prints JSON {frames, seconds}.
"""

import collections
import json
import sys
import time

import witmotion


class StandIn:
    def __init__(self, data, imu):
        self.data, self.pos, self.imu = data, 0, imu

    def read(self, size=1):
        chunk = self.data[self.pos : self.pos + size]
        self.pos += len(chunk)
        if not chunk:
            self.imu.should_exit = True
        return chunk


def main() -> int:
    data = open(sys.argv[1], "rb").read()
    imu = witmotion.IMU.__new__(witmotion.IMU)
    imu.ser = StandIn(data, imu)
    imu.should_exit = False
    imu.subscribers = collections.defaultdict(list)
    for attr in ("last_timestamp", "last_temp_celsius", "last_a", "last_w", "last_q", "last_mag"):
        setattr(imu, attr, None)
    count = [0]
    imu.subscribe(lambda m: count.__setitem__(0, count[0] + 1))
    t0 = time.perf_counter()
    imu._rxloop()
    dt = time.perf_counter() - t0
    print(json.dumps({"frames": count[0], "seconds": dt}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
