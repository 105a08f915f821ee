"""A Foxglove WebSocket client (PyPI `websockets`) for view/tests/view_foxglove.rs.

Connects with subprotocol foxglove.websocket.v1, reads serverInfo and advertise, then:
  receive URL N TOPIC...  subscribe to TOPICs, read until N message frames arrived per topic,
                          decode each payload with mcap_ros2's decoder built from the schema the
                          server advertised and with rosbags' ROS 2 Humble typestore, and print a
                          JSON summary; also sends a malformed request and an unsubscribe.
  stall URL SECONDS TOPIC subscribe, then stop reading for SECONDS (a slow client).
  noproto URL             connect without the subprotocol; print the HTTP status of the refusal.
  connect URL             connect with the subprotocol (the URL may carry ?token=); print 101 and
                          the serverInfo op, or the HTTP status of the refusal.
"""

import asyncio
import json
import struct
import sys

import websockets
from mcap_ros2._dynamic import generate_dynamic
from rosbags.typesys import Stores, get_typestore

SUBPROTOCOL = "foxglove.websocket.v1"


async def hello(ws):
    info = json.loads(await asyncio.wait_for(ws.recv(), 5))
    advertise = json.loads(await asyncio.wait_for(ws.recv(), 5))
    return info, advertise


def summarize(topic, msg):
    if topic.endswith("points"):
        return {
            "frame_id": msg.header.frame_id,
            "stamp": [msg.header.stamp.sec, msg.header.stamp.nanosec],
            "width": msg.width,
            "point_step": msg.point_step,
            "fields": [f.name for f in msg.fields],
            "first_xyz": list(struct.unpack_from("<fff", bytes(msg.data), 0)) if msg.width else [],
        }
    if topic.endswith("markers"):
        return {
            "markers": [
                {"ns": m.ns, "id": m.id, "type": m.type, "action": m.action, "x": m.pose.position.x, "text": m.text}
                for m in msg.markers
            ]
        }
    return {}


async def receive(url, n, topics):
    # max_queue=None: with a bounded queue, websockets stops reading the socket once frames it
    # was not asked for pile up, and then waits out its close timeout for our close reply.
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None, max_queue=None) as ws:
        info, advertise = await hello(ws)
        channels = {c["topic"]: c for c in advertise["channels"]}
        subs = {}
        request = []
        for i, topic in enumerate(topics):
            subs[100 + i] = topic
            request.append({"id": 100 + i, "channelId": channels[topic]["id"]})
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": request}))
        await ws.send("{not json")
        statuses = []
        humble = get_typestore(Stores.ROS2_HUMBLE)
        got = {t: [] for t in topics}
        while any(len(v) < n for v in got.values()):
            frame = await asyncio.wait_for(ws.recv(), 10)
            if isinstance(frame, str):
                statuses.append(json.loads(frame))
                continue
            op, sub_id, log_ns = struct.unpack_from("<BIQ", frame, 0)
            payload = frame[13:]
            topic = subs[sub_id]
            if len(got[topic]) >= n:
                continue
            ch = channels[topic]
            decoders = generate_dynamic(ch["schemaName"], ch["schema"])
            mine = decoders[ch["schemaName"]](payload)
            theirs = humble.deserialize_cdr(payload, ch["schemaName"])
            a, b = summarize(topic, mine), summarize(topic, theirs)
            got[topic].append({"op": op, "log_ns": log_ns, "msg": a, "humble_agrees": a == b})
        # Unsubscribe everything; the server must accept it quietly.
        await ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": list(subs)}))
        print(json.dumps({"server_info": info, "subprotocol": ws.subprotocol, "channels": advertise["channels"],
                          "statuses": statuses, "received": got}))


async def stall(url, seconds, topic):
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None, max_queue=1) as ws:
        _, advertise = await hello(ws)
        channel = next(c for c in advertise["channels"] if c["topic"] == topic)
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]}))
        print(json.dumps({"subscribed": True}), flush=True)
        await asyncio.sleep(seconds)


async def noproto(url):
    try:
        async with websockets.connect(url):
            print(json.dumps({"status": 101}))
    except websockets.exceptions.InvalidStatus as e:
        print(json.dumps({"status": e.response.status_code}))


async def connect(url):
    try:
        async with websockets.connect(url, subprotocols=[SUBPROTOCOL]) as ws:
            info, _ = await hello(ws)
            print(json.dumps({"status": 101, "op": info["op"]}))
    except websockets.exceptions.InvalidStatus as e:
        print(json.dumps({"status": e.response.status_code}))


def main():
    mode, url = sys.argv[1], sys.argv[2]
    if mode == "receive":
        asyncio.run(receive(url, int(sys.argv[3]), sys.argv[4:]))
    elif mode == "stall":
        asyncio.run(stall(url, float(sys.argv[3]), sys.argv[4]))
    elif mode == "noproto":
        asyncio.run(noproto(url))
    elif mode == "connect":
        asyncio.run(connect(url))
    else:
        sys.exit(f"unknown mode {mode}")


if __name__ == "__main__":
    main()
