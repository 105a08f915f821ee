"""Times the PyPI `mcap` writer on the payloads of an existing recording (for the record bench).

Usage: mcap_write_bench.py SOURCE.mcap OUT.mcap
Loads every message of SOURCE into memory (not timed), then writes them to OUT with the
`mcap` writer, chunks of 4 MiB, without compression and with LZ4; prints the best of 3 each.
"""

import os
import sys
import time

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer


def main(src, out):
    schemas, channels, msgs = {}, {}, []
    with open(src, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            schemas[schema.id] = schema
            channels[channel.id] = channel
            msgs.append((channel.id, message.log_time, message.publish_time, message.sequence, message.data))
    payload = sum(len(m[4]) for m in msgs)
    for name, comp in (("none", CompressionType.NONE), ("lz4", CompressionType.LZ4)):
        best = float("inf")
        for _ in range(3):
            t = time.perf_counter()
            with open(out, "wb") as f:
                w = Writer(f, chunk_size=4 << 20, compression=comp)
                w.start(profile="ros2", library="python-mcap-bench")
                sid = {s.id: w.register_schema(s.name, s.encoding, s.data) for s in schemas.values()}
                cid = {c.id: w.register_channel(c.topic, c.message_encoding, sid[c.schema_id]) for c in channels.values()}
                for ch, log, pub, seq, data in msgs:
                    w.add_message(cid[ch], log, data, pub, seq)
                w.finish()
            best = min(best, time.perf_counter() - t)
        size = os.path.getsize(out)
        print(
            f"python mcap {name:<4}: best of 3 {best * 1e3:7.1f} ms = {len(msgs) / best:8.0f} msg/s, "
            f"payload {payload / 1e6 / best:6.0f} MB/s, file {size / 1e6:.1f} MB"
        )


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
