#!/usr/bin/env python3
"""KISS-Matcher (global) and small_gicp (fine stage) on the rig's first-alignment searches.

usage: align_window_peers.py DUMP_DIR [--voxel 0.3] [--json OUT]

DUMP_DIR holds one folder per search, as `DUMP_DIR=... NEVER_APPLY=1 NO_HINT=1 cargo run
--release -p starc-pipeline --example rig_diag -- RUN` writes them:
  source.f64   the rig's window as STARC registers it (little-endian f64 x, y, z), its frame
  target.f64   the robot's map at that time, in the robot's world
  truth.txt    the window frame's true pose in the world: 16 numbers, row-major
  ours.json    what STARC's search did: accepted, error_m, error_deg, ms

Each search is registered from nothing by KISS-Matcher (PyPI kiss-matcher, FPFH + ROBIN +
GNC-TLS; each in a process of its own, since it can crash), then refined by small_gicp
point-to-plane ICP from its result. A result is right
within 10 cm and 1 deg of the truth. KISS-Matcher has no acceptance test beyond its `valid`
flag, so its "accepted" is every valid result. Prints a table per building and in all.
Single-threaded, like STARC's search.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

RIGHT_M, RIGHT_DEG = 0.10, 1.0


def load(d):
    src = np.fromfile(os.path.join(d, "source.f64"), dtype="<f8").reshape(-1, 3)
    tgt = np.fromfile(os.path.join(d, "target.f64"), dtype="<f8").reshape(-1, 3)
    truth = np.loadtxt(os.path.join(d, "truth.txt")).reshape(4, 4)
    with open(os.path.join(d, "ours.json")) as f:
        ours = json.load(f)
    return src, tgt, truth, ours


def error(T, truth):
    d = np.linalg.inv(truth) @ T
    m = float(np.linalg.norm(d[:3, 3]))
    c = np.clip((np.trace(d[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return m, float(np.degrees(np.arccos(c)))


def kiss_matcher_here(d, voxel):
    """KISS-Matcher on one search, in this process: prints T (16 numbers), valid, ms as JSON."""
    import kiss_matcher as km

    src, tgt, _, _ = load(d)
    t0 = time.perf_counter()
    m = km.KISSMatcher(km.KISSMatcherConfig(voxel))
    r = m.estimate(src.astype(np.float32), tgt.astype(np.float32))
    T = np.eye(4)
    T[:3, :3] = np.asarray(r.rotation)
    T[:3, 3] = np.asarray(r.translation).reshape(3)
    ms = (time.perf_counter() - t0) * 1e3
    print(json.dumps({"T": T.reshape(-1).tolist(), "valid": bool(r.valid), "ms": ms}))


def kiss_matcher(d, voxel):
    """KISS-Matcher in a process of its own: kiss-matcher 1.0.2 crashes (SIGSEGV) on some small
    windows (a few hundred points), which then count as refused."""
    r = subprocess.run([sys.executable, __file__, d, "--one", "--voxel", str(voxel)],
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        return np.eye(4), False, float("nan"), True
    out = json.loads(r.stdout)
    return np.array(out["T"]).reshape(4, 4), out["valid"], out["ms"], False


def small_gicp_from(src, tgt, T0):
    import small_gicp

    t0 = time.perf_counter()
    target, tree = small_gicp.preprocess_points(tgt, downsampling_resolution=0.25, num_threads=1)
    source, _ = small_gicp.preprocess_points(src, downsampling_resolution=0.25, num_threads=1)
    r = small_gicp.align(target, source, tree, T0, registration_type="PLANE_ICP",
                         max_correspondence_distance=1.0, num_threads=1, max_iterations=30)
    return np.asarray(r.T_target_source), (time.perf_counter() - t0) * 1e3


def verdict(accepted, m, deg):
    if not accepted:
        return "refused"
    return "right" if m <= RIGHT_M and deg <= RIGHT_DEG else "wrong"


def main():
    p = argparse.ArgumentParser()
    p.add_argument("dump")
    p.add_argument("--voxel", type=float, default=0.3)
    p.add_argument("--json")
    p.add_argument("--one", action="store_true", help="KISS-Matcher on the one search DUMP_DIR (internal)")
    a = p.parse_args()
    if a.one:
        kiss_matcher_here(a.dump, a.voxel)
        return
    rows = []
    dirs = sorted(d for d in glob.glob(os.path.join(a.dump, "*")) if os.path.exists(os.path.join(d, "ours.json")))
    if not dirs:
        raise SystemExit(f"no searches in {a.dump}")
    for i, d in enumerate(dirs):
        src, tgt, truth, ours = load(d)
        T, valid, km_ms, crashed = kiss_matcher(d, a.voxel)
        km_m, km_deg = error(T, truth)
        Tf, gicp_ms = small_gicp_from(src, tgt, T) if valid and len(src) > 0 else (T, float("nan"))
        f_m, f_deg = error(Tf, truth)
        name = os.path.basename(d)
        rows.append({
            "search": name,
            "building": name.rsplit("_t", 1)[0],
            "ours": verdict(ours["accepted"], ours["error_m"], ours["error_deg"]),
            "ours_ms": ours["ms"],
            "kiss_matcher": verdict(valid, km_m, km_deg),
            "kiss_matcher_m": km_m,
            "kiss_matcher_ms": km_ms,
            "kiss_matcher_crashed": crashed,
            "kiss_matcher_small_gicp": verdict(valid, f_m, f_deg),
            "small_gicp_ms": gicp_ms,
        })
        sys.stderr.write(f"\r{i + 1}/{len(dirs)} {name}          ")
    sys.stderr.write("\n")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    methods = ["ours", "kiss_matcher", "kiss_matcher_small_gicp"]
    buildings = sorted({r["building"] for r in rows})
    print("| building | searches | " + " | ".join(f"{m}: right / wrong" for m in methods) + " |")
    print("|---|---|" + "---|" * len(methods))
    for b in buildings + ["all"]:
        sel = [r for r in rows if b == "all" or r["building"] == b]
        cells = []
        for m in methods:
            right = sum(r[m] == "right" for r in sel)
            wrong = sum(r[m] == "wrong" for r in sel)
            cells.append(f"{right} / {wrong}")
        print(f"| {b} | {len(sel)} | " + " | ".join(cells) + " |")
    for key in ["ours_ms", "kiss_matcher_ms", "small_gicp_ms"]:
        v = np.array([r[key] for r in rows if np.isfinite(r[key])])
        print(f"{key}: median {np.median(v):.1f} ms, p90 {np.percentile(v, 90):.1f} ms (n = {len(v)})")
    print(f"kiss_matcher crashed on {sum(r['kiss_matcher_crashed'] for r in rows)} searches (counted refused)")


if __name__ == "__main__":
    main()
