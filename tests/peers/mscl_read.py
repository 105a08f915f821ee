#!/usr/bin/env python3
"""Reads a MIP IMU (our mock) with PyPI `pymscl`, the vendor's MicroStrain Communication Library.

Used by tests/serial_imu_peers.rs. Usage: mscl_read.py PORT BAUD SECONDS. MSCL opens the serial
port without any handshake (Connection.Serial + InertialNode do not talk to the device), then
this script pings the device, sets it idle and resumes it (each waits for our ACK), and reads
data packets for SECONDS. Prints what it saw as JSON; on an MSCL error prints {"error": ...}.
"""

import json
import sys
import time

import mscl


def main() -> int:
    port, baud, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    result = {"ping": None, "idle": None, "resume": None}
    try:
        connection = mscl.Connection.Serial(port, baud)
        node = mscl.InertialNode(connection)
        node.timeout(500)
        result["ping"] = bool(node.ping())
        node.setToIdle()
        result["idle"] = True
        time.sleep(0.2)
        node.getDataPackets(0)  # what came before idle
        idle_packets = len(node.getDataPackets(300))
        result["packets_while_idle"] = idle_packets
        node.resume()
        result["resume"] = True
        packets = 0
        channels = {}
        sums = {}
        tows = []
        end = time.time() + seconds
        while time.time() < end:
            for p in node.getDataPackets(100):
                if p.descriptorSet() != 0x80:
                    continue
                packets += 1
                for d in p.data():
                    name = d.channelName()
                    channels[name] = channels.get(name, 0) + 1
                    if name.startswith("scaled"):
                        sums[name] = sums.get(name, 0.0) + d.as_float()
                    if name == "gpsCorrelTimestampTow":
                        tows.append(d.as_double())
        result["packets"] = packets
        result["channels"] = channels
        result["means"] = {k: v / max(channels[k], 1) for k, v in sums.items()}
        result["tow_first_last"] = [tows[0], tows[-1]] if tows else None
        connection.disconnect()
    except Exception as e:  # MSCL raises its own error types
        result["error"] = f"{type(e).__name__}: {e}"
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
