"""The STPW weights file (docs/pillars.md, "Weights file"): named float32 tensors and a CRC-32,
written and read as the Rust loader (pipeline/src/detect/pillars/weights.rs) does. Shared by
pillars.py and cluster_trees.py."""

import struct
import zlib
from pathlib import Path

import numpy as np

STPW_VERSION = 1


def write_stpw(path, tensors):
    """tensors: [(name, array)] in file order. Format: docs/pillars.md, "Weights file"."""
    data = bytearray(b"STPW")
    data += struct.pack("<II", STPW_VERSION, len(tensors))
    for name, array in tensors:
        encoded = name.encode("utf-8")
        data += struct.pack("<H", len(encoded)) + encoded
        data += struct.pack(f"<B{array.ndim}I", array.ndim, *array.shape)
        data += np.ascontiguousarray(array, dtype="<f4").tobytes()
    data += struct.pack("<I", zlib.crc32(data))
    Path(path).write_bytes(bytes(data))


def read_stpw(path):
    """The reverse of write_stpw, with every check the Rust loader makes; -> [(name, array)]."""
    data = Path(path).read_bytes()
    if data[:4] != b"STPW":
        raise ValueError(f"{path}: not an STPW file")
    (crc,) = struct.unpack_from("<I", data, len(data) - 4)
    if zlib.crc32(data[:-4]) != crc:
        raise ValueError(f"{path}: CRC-32 mismatch")
    version, count = struct.unpack_from("<II", data, 4)
    if version != STPW_VERSION:
        raise ValueError(f"{path}: version {version}")
    at, tensors = 12, []
    for _ in range(count):
        (length,) = struct.unpack_from("<H", data, at)
        name = data[at + 2 : at + 2 + length].decode("utf-8")
        at += 2 + length
        rank = data[at]
        shape = struct.unpack_from(f"<{rank}I", data, at + 1)
        at += 1 + 4 * rank
        size = int(np.prod(shape))
        tensors.append((name, np.frombuffer(data, "<f4", size, at).reshape(shape)))
        at += 4 * size
    if at != len(data) - 4:
        raise ValueError(f"{path}: {len(data) - 4 - at} stray bytes before the CRC")
    return tensors
