"""Classic-pcap records, for the scripts that cut and merge the simulator's captures."""

import struct


def read_pcap(path):
    """A classic pcap's 24-byte header, and its records as ((seconds, sub-seconds), record
    header, data), read as they are iterated."""
    f = open(path, "rb")
    header = f.read(24)
    order = "<" if struct.unpack("<I", header[:4])[0] in (0xA1B2C3D4, 0xA1B23C4D) else ">"

    def records():
        with f:
            while len(rec := f.read(16)) == 16:
                sec, sub, incl, _ = struct.unpack(order + "IIII", rec)
                yield (sec, sub), rec, f.read(incl)

    return header, records()
