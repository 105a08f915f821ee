"""The reference the Rust PointPillars inference is tested against: the exported ONNX pair run
with onnxruntime (docs/pillars.md is the contract; pillars.py export writes the models).

    onnx_reference.py --models config/models --io DIR

Reads DIR/features.npy (float32 [P, 32, 8]), DIR/mask.npy (float32 [P, 32]) and DIR/coords.npy
(int64 [P, 2]: iy, ix); runs pfn.onnx, scatters its output to a [1, 32, 96, 96] canvas (zeros
where no pillar), runs backbone.onnx; writes DIR/pillar_features.npy (float32 [P, 32]) and
DIR/head.npy (float32 [1, 12, 48, 48], raw logits). Needs only numpy and onnxruntime.
"""

import argparse
import time
from pathlib import Path

import numpy as np
import onnxruntime

GRID = 96
MAX_POINTS = 32
POINT_FEATURES = 8
PFN_CHANNELS = 32


def session(path):
    options = onnxruntime.SessionOptions()
    # One thread: the reference should not depend on how the work is split.
    options.intra_op_num_threads = 1
    return onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def load_inputs(io):
    features = np.load(io / "features.npy").astype(np.float32, copy=False)
    mask = np.load(io / "mask.npy").astype(np.float32, copy=False)
    coords = np.load(io / "coords.npy").astype(np.int64, copy=False)
    pillars = len(features)
    if features.shape != (pillars, MAX_POINTS, POINT_FEATURES):
        raise SystemExit(f"features.npy: shape {features.shape}, want [P, {MAX_POINTS}, {POINT_FEATURES}]")
    if mask.shape != (pillars, MAX_POINTS):
        raise SystemExit(f"mask.npy: shape {mask.shape}, want [{pillars}, {MAX_POINTS}]")
    if coords.shape != (pillars, 2):
        raise SystemExit(f"coords.npy: shape {coords.shape}, want [{pillars}, 2]")
    if pillars and (coords.min() < 0 or coords.max() >= GRID):
        raise SystemExit(f"coords.npy: a pillar outside the {GRID} x {GRID} grid")
    if len(np.unique(coords[:, 0] * GRID + coords[:, 1])) != pillars:
        raise SystemExit("coords.npy: two pillars at the same cell")
    return features, mask, coords


def run(pfn, backbone, features, mask, coords):
    """-> (pillar features [P, 32], head [1, 12, 48, 48])."""
    if len(features):
        (pillar_features,) = pfn.run(["pillar_features"], {"features": features, "mask": mask[:, :, None]})
    else:
        pillar_features = np.zeros((0, PFN_CHANNELS), np.float32)  # an empty window: nothing to run
    canvas = np.zeros((1, PFN_CHANNELS, GRID, GRID), np.float32)
    canvas[0][:, coords[:, 0], coords[:, 1]] = pillar_features.T
    (head,) = backbone.run(["head"], {"canvas": canvas})
    return pillar_features, head


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", required=True, type=Path, help="directory with pfn.onnx and backbone.onnx")
    parser.add_argument("--io", required=True, type=Path, help="directory with the inputs; outputs go there too")
    parser.add_argument("--repeat", type=int, default=0, help="also time N runs and print the median (ms)")
    args = parser.parse_args()

    features, mask, coords = load_inputs(args.io)
    pfn, backbone = session(args.models / "pfn.onnx"), session(args.models / "backbone.onnx")
    pillar_features, head = run(pfn, backbone, features, mask, coords)
    if args.repeat > 0:
        times = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            run(pfn, backbone, features, mask, coords)
            times.append((time.perf_counter() - start) * 1e3)
        print(f"onnxruntime (1 thread): median {np.median(times):.3f} ms over {args.repeat} runs")

    np.save(args.io / "pillar_features.npy", pillar_features.astype(np.float32, copy=False))
    np.save(args.io / "head.npy", head.astype(np.float32, copy=False))


if __name__ == "__main__":
    main()
