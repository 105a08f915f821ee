"""python-can on one end of a pty pair reads what our base driver sends on the other, and
answers as three C620 ESCs standing still (feedback at 200 Hz) so the driver keeps running.

Usage: read_base_frames.py PORT SECONDS READY_FILE
(READY_FILE is created once the port is open and feedback flows.)
Prints JSON: frames per id and the current commands seen (first, strongest, last).
"""
import json
import struct
import sys
import time

import can

port, seconds, ready = sys.argv[1], float(sys.argv[2]), sys.argv[3]
bus = can.Bus(interface="slcan", channel=port, bitrate=1_000_000, sleep_after_open=0)
counts, first, strongest, last = {}, None, None, None
start = time.monotonic()
next_feedback = start
try:
    while time.monotonic() - start < seconds:
        if ready and time.monotonic() - start > 0.05:
            open(ready, "w").close()
            ready = None
        if time.monotonic() >= next_feedback:
            for esc in (1, 2, 3):
                data = struct.pack(">Hhhb", 100 * esc, 0, 0, 31) + b"\x00"
                bus.send(can.Message(arbitration_id=0x200 + esc, is_extended_id=False, data=data))
            next_feedback += 0.005
        msg = bus.recv(timeout=0.001)
        if msg is None:
            continue
        counts[msg.arbitration_id] = counts.get(msg.arbitration_id, 0) + 1
        if msg.arbitration_id == 0x200 and len(msg.data) == 8:
            currents = list(struct.unpack(">4h", bytes(msg.data)))
            first = first or currents
            if strongest is None or sum(map(abs, currents)) > sum(map(abs, strongest)):
                strongest = currents
            last = currents
finally:
    bus.shutdown()
print(json.dumps({"counts": {hex(k): v for k, v in counts.items()}, "first": first, "strongest": strongest, "last": last}))
