#!/usr/bin/env python3
"""Reads an .lvx file with PyPI `livox-lvx` and prints what it saw as JSON.

Used by drivers/livox/tests/capture.rs to cross-check STARC's .lvx writer against an independent
reader. Usage: lvx_check.py FILE. On a parse error prints {"error": "..."} (exit status 0), so the
caller can assert on what the peer refuses.
"""

import json
import sys

from lvx import LvxFileReader
from lvx.lvx import LvxParseError


def main() -> int:
    path = sys.argv[1]
    result = {}
    try:
        with open(path, "rb") as fp:
            reader = LvxFileReader(fp)
            header = reader.header
            result["version"] = list(header.version)
            result["magic"] = header.magic_code
            result["frame_duration"] = header.frame_duration
            result["devices"] = header.device_count
            result["device_sn"] = [
                d.lidar_broadcast_code.rstrip(b"\0").decode("ascii", "replace") for d in header.devices
            ]
            frames = packages = points = 0
            first_xyz = None
            for frame in reader:
                frames += 1
                for package in frame.packages:
                    packages += 1
                    points += len(package.points)
                    if first_xyz is None and package.data_type in (0, 2):
                        p = package.points[0]
                        first_xyz = [p.x, p.y, p.z]
            result.update(frames=frames, packages=packages, points=points, first_point_xyz=first_xyz)
    except LvxParseError as e:
        result["error"] = str(e)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
