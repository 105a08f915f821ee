"""PyPI canopen (over python-can's slcan) against our mock CiA 402 drive.

Usage: cia402_canopen.py PORT NODE EDS
NMT reset and boot-up, SDO reads and writes (and an abort), heartbeat, PDO configuration read
back, the CiA 402 enable sequence with BaseNode402, a velocity target and the actual velocity.
Prints JSON with what each step saw.
"""
import json
import sys
import threading
import time

import canopen
from canopen.sdo import SdoAbortedError

port, node_id, eds = sys.argv[1], int(sys.argv[2]), sys.argv[3]
out = {}
network = canopen.Network()
network.connect(interface="slcan", channel=port, bitrate=1_000_000, sleep_after_open=0)
try:
    node = canopen.BaseNode402(node_id, eds)
    network.add_node(node)
    # Listen for the boot-up before asking for the reset: canopen's wait_for_bootup() only sees
    # a boot-up that arrives after it starts waiting, and a loaded machine can be slower than
    # the drive's answer.
    booted = threading.Event()
    network.subscribe(0x700 + node_id, lambda cob_id, data, ts: data[:1] == b"\x00" and booted.set())
    node.nmt.state = "RESET"
    if not booted.wait(10):
        raise SystemExit("no boot-up message within 10 s of the NMT reset")
    out["bootup"] = True
    out["device_type"] = node.sdo[0x1000].raw
    out["identity_vendor"] = node.sdo[0x1018][1].raw
    try:
        node.sdo.upload(0x2000, 0)
        out["abort_code"] = None
    except SdoAbortedError as e:
        out["abort_code"] = e.code
    try:
        node.sdo[0x6041].raw = 0
        out["read_only_abort"] = None
    except SdoAbortedError as e:
        out["read_only_abort"] = e.code
    node.sdo[0x1017].raw = 50
    node.sdo[0x1800][5].raw = 10
    node.nmt.wait_for_heartbeat(1)
    out["heartbeat_state"] = node.nmt.state
    node.setup_402_state_machine(read_pdos=True)
    out["tpdo1_cob_id"] = node.tpdo[1].cob_id
    out["tpdo1_mapped"] = [v.index for v in node.tpdo[1]]
    out["rpdo1_mapped"] = [v.index for v in node.rpdo[1]]
    node.nmt.state = "OPERATIONAL"
    node.nmt.wait_for_heartbeat(1)
    out["nmt_after_start"] = node.nmt.state
    node.op_mode = "PROFILED VELOCITY"
    out["op_mode"] = node.op_mode
    node.state = "SWITCHED ON"
    out["state_switched_on"] = node.state
    node.state = "OPERATION ENABLED"
    out["state_enabled"] = node.state
    out["statusword"] = node.statusword
    node.sdo[0x60FF].raw = 300
    time.sleep(0.6)
    out["velocity_actual_sdo"] = node.sdo[0x606C].raw
    out["velocity_actual_tpdo"] = node.tpdo_values.get(0x606C)
    node.state = "SWITCH ON DISABLED"
    out["state_disabled"] = node.state
finally:
    network.disconnect()
print(json.dumps(out))
