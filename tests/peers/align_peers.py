#!/usr/bin/env python3
"""Peers for STARC's aligner: small_gicp and Open3D point-to-plane ICP from the same seeds.

usage: align_peers.py DIR [--peers small_gicp,open3d] [--voxel 0.25] [--max-corr 1.0] [--iterations 30]

DIR holds what the Rust bench (or test) wrote:
  source.f64, target.f64   raw little-endian float64 x,y,z triples
  seeds.txt                one initial T_target_source per line: 16 numbers, row-major
Prints one JSON object per line: {"peer", "trial", "T" (16 numbers, row-major), "ms", "cpu_ms"}, and per
peer one {"peer", "prepare_ms"} line first. Each peer runs single-threaded; "ms" is the
registration call alone (the clouds are reduced and the target's normals and tree built once,
like STARC's prepared target; the source's reduction is timed into prepare_ms).
"""
import argparse
import json
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def load(d):
    src = np.fromfile(os.path.join(d, "source.f64"), dtype="<f8").reshape(-1, 3)
    tgt = np.fromfile(os.path.join(d, "target.f64"), dtype="<f8").reshape(-1, 3)
    seeds = []
    with open(os.path.join(d, "seeds.txt")) as f:
        for line in f:
            v = [float(x) for x in line.split()]
            if len(v) != 16:
                raise SystemExit(f"seeds.txt: expected 16 numbers per line, got {len(v)}")
            seeds.append(np.array(v).reshape(4, 4))
    return src, tgt, seeds


def emit(obj):
    sys.stdout.write(json.dumps(obj) + "\n")


def run_small_gicp(src, tgt, seeds, a):
    import small_gicp

    t0 = time.perf_counter()
    target, tree = small_gicp.preprocess_points(tgt, downsampling_resolution=a.voxel, num_threads=1)
    source, _ = small_gicp.preprocess_points(src, downsampling_resolution=a.voxel, num_threads=1)
    emit({"peer": "small_gicp", "prepare_ms": (time.perf_counter() - t0) * 1e3})
    for i, seed in enumerate(seeds):
        t, c = time.perf_counter(), time.thread_time()
        r = small_gicp.align(
            target,
            source,
            tree,
            seed,
            registration_type="PLANE_ICP",
            max_correspondence_distance=a.max_corr,
            num_threads=1,
            max_iterations=a.iterations,
        )
        ms, cpu_ms = (time.perf_counter() - t) * 1e3, (time.thread_time() - c) * 1e3
        T = np.asarray(r.T_target_source).reshape(-1).tolist()
        emit({"peer": "small_gicp", "trial": i, "T": T, "ms": ms, "cpu_ms": cpu_ms})


def run_open3d(src, tgt, seeds, a):
    import open3d as o3d

    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt)).voxel_down_sample(a.voxel)
    target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=12))
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src)).voxel_down_sample(a.voxel)
    emit({"peer": "open3d", "prepare_ms": (time.perf_counter() - t0) * 1e3})
    criteria = reg.ICPConvergenceCriteria(max_iteration=a.iterations)
    for i, seed in enumerate(seeds):
        t, c = time.perf_counter(), time.thread_time()
        r = reg.registration_icp(source, target, a.max_corr, seed, reg.TransformationEstimationPointToPlane(), criteria)
        ms, cpu_ms = (time.perf_counter() - t) * 1e3, (time.thread_time() - c) * 1e3
        T = np.asarray(r.transformation).reshape(-1).tolist()
        emit({"peer": "open3d", "trial": i, "T": T, "ms": ms, "cpu_ms": cpu_ms})


def main():
    p = argparse.ArgumentParser()
    p.add_argument("dir")
    p.add_argument("--peers", default="small_gicp,open3d")
    p.add_argument("--voxel", type=float, default=0.25)
    p.add_argument("--max-corr", type=float, default=1.0)
    p.add_argument("--iterations", type=int, default=30)
    a = p.parse_args()
    src, tgt, seeds = load(a.dir)
    runners = {"small_gicp": run_small_gicp, "open3d": run_open3d}
    for name in a.peers.split(","):
        if name not in runners:
            raise SystemExit(f"unknown peer {name!r}")
        runners[name](src, tgt, seeds, a)
        sys.stdout.flush()


if __name__ == "__main__":
    main()
