#!/usr/bin/env python3
"""Reads a WitMotion IMU (our mock) with PyPI `witmotion`.

Used by tests/serial_imu_peers.rs. Usage: witmotion_read.py PORT BAUD SECONDS [RATE_HZ]. Counts
the messages witmotion decodes for SECONDS; with RATE_HZ, then asks the device for that output
rate (witmotion sends the unlock and the rate register write) and counts for SECONDS again.
Prints JSON.
"""

import json
import sys
import time

import witmotion
from witmotion import protocol


def count(imu, seconds):
    counts = {}
    last = {}

    def on_message(msg):
        name = type(msg).__name__
        counts[name] = counts.get(name, 0) + 1
        if isinstance(msg, protocol.AccelerationMessage):
            last["a"] = list(msg.a)
            last["temp_c"] = msg.temp_celsius
        elif isinstance(msg, protocol.AngularVelocityMessage):
            last["w_deg_s"] = list(msg.w)
        elif isinstance(msg, protocol.AngleMessage):
            last["angle_deg"] = [msg.roll, msg.pitch, msg.yaw]

    imu.subscribers[None].clear()
    imu.subscribe(on_message)
    time.sleep(seconds)
    imu.subscribers[None].clear()
    return counts, last


def main() -> int:
    port, baud, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    rate = float(sys.argv[4]) if len(sys.argv) > 4 else None
    imu = witmotion.IMU(port, baudrate=baud)
    try:
        time.sleep(0.2)  # skip what waited in the tty
        result = {}
        result["counts"], result["last"] = count(imu, seconds)
        if rate is not None:
            imu.set_update_rate(int(rate) if rate == int(rate) else rate)
            time.sleep(0.3)
            result["counts_after_rate"], _ = count(imu, seconds)
        print(json.dumps(result))
    finally:
        imu.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
