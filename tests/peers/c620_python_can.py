"""python-can's slcan interface drives our mock C620 ESCs: current commands out, feedback in.

Usage: c620_python_can.py PORT SECONDS
Sends 0x200 with +4 A (ESC 1), -2 A (ESC 2), 0 (ESC 3) every 10 ms, reads every frame, and prints
JSON: frames per id, the last feedback of each ESC, and the measured feedback rate.
"""
import json
import struct
import sys
import time

import can

port, seconds = sys.argv[1], float(sys.argv[2])
# sleep_after_open: python-can waits 2 s after opening the port by default.
bus = can.Bus(interface="slcan", channel=port, bitrate=1_000_000, sleep_after_open=0)
raw = [round(a / 20 * 16384) for a in (4.0, -2.0, 0.0, 0.0)]
command = can.Message(arbitration_id=0x200, is_extended_id=False, data=struct.pack(">4h", *raw))
counts, last, first_at, last_at = {}, {}, {}, {}
start = time.monotonic()
next_send = start
try:
    while time.monotonic() - start < seconds:
        now = time.monotonic()
        if now >= next_send:
            bus.send(command)
            next_send += 0.010
        msg = bus.recv(timeout=0.002)
        if msg is None or msg.is_extended_id:
            continue
        counts[msg.arbitration_id] = counts.get(msg.arbitration_id, 0) + 1
        if 0x201 <= msg.arbitration_id <= 0x208 and len(msg.data) >= 7:
            angle, rpm, current = struct.unpack(">Hhh", bytes(msg.data[:6]))
            esc = msg.arbitration_id - 0x200
            last[esc] = {"angle": angle, "rotor_rpm": rpm, "current_raw": current, "temperature_c": msg.data[6]}
            first_at.setdefault(esc, now)
            last_at[esc] = now
finally:
    bus.shutdown()
rates = {
    str(esc): (counts[0x200 + esc] - 1) / (last_at[esc] - first_at[esc])
    for esc in last
    if last_at[esc] > first_at[esc]
}
print(json.dumps({"counts": {hex(k): v for k, v in counts.items()}, "last": {str(k): v for k, v in last.items()},
                  "feedback_hz": rates, "command_raw": raw}))
