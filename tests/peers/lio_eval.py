"""Scores `starc lio` against ground truth with evo, next to KISS-ICP on the same scans.

    lio_eval.py --gt gt_robot.tum --ours 192.168.1.101.tum --scans 192.168.1.101_scans.bin \
        [--kiss-out kiss.tum] [--plot traj.png] [--title lab/robot]

Prints one JSON object: APE (translation RMSE/max, after an SE(3) Umeyama alignment, as
`evo_ape -a`, or of the first poses, as `--align_origin`, where a straight path leaves the SE(3)
fit undetermined) and RPE (translation error per 1 m travelled) for our trajectory and KISS-ICP's,
and KISS-ICP's time per scan (single thread). KISS-ICP deskews with its own constant-velocity
model from the per-point times; its pose is stamped at the scan time that scores best for it
(start, middle or end), which the output names.
"""

import argparse
import json
import struct
import sys
import time

import numpy as np
from evo.core import metrics, sync
from evo.core.geometry import GeometryException
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface
from kiss_icp.config import load_config
from kiss_icp.kiss_icp import KissICP
from scipy.spatial.transform import Rotation


def read_scans(path):
    """Yields (start_ns, end_ns, points Nx3 float64, times Nx1 seconds after start)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"STARCSCN" or struct.unpack_from("<I", data, 8)[0] != 1:
        raise SystemExit(f"{path}: not a STARCSCN version 1 file")
    at = 12
    while at + 20 <= len(data):
        start, end, n = struct.unpack_from("<QQI", data, at)
        at += 20
        block = np.frombuffer(data, dtype="<f4", count=4 * n, offset=at).reshape(n, 4)
        at += 16 * n
        yield start, end, block[:, :3].astype(np.float64), block[:, 3].astype(np.float64)


def kiss_icp(scans_path, threads=1):
    cfg = load_config(None)
    cfg.data.min_range = 0.5
    cfg.registration.max_num_threads = threads
    odom = KissICP(cfg)
    stamps, poses, times = [], [], []
    for start, end, pts, t in read_scans(scans_path):
        if len(pts) < 100:
            continue
        span = max(t.max() - t.min(), 1e-9)
        began = time.perf_counter()
        odom.register_frame(pts, (t - t.min()) / span)
        times.append(time.perf_counter() - began)
        stamps.append((start, end))
        poses.append(odom.last_pose.copy())
    return stamps, poses, times


def trajectory(stamps_s, poses):
    xyz = np.array([p[:3, 3] for p in poses])
    quat_xyzw = Rotation.from_matrix(np.array([p[:3, :3] for p in poses])).as_quat()
    quat_wxyz = np.roll(quat_xyzw, 1, axis=1)
    return PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=quat_wxyz, timestamps=np.array(stamps_s))


def score(gt, est):
    ref, est = sync.associate_trajectories(gt, est, max_diff=0.006)
    est = PoseTrajectory3D(
        positions_xyz=est.positions_xyz.copy(),
        orientations_quat_wxyz=est.orientations_quat_wxyz.copy(),
        timestamps=est.timestamps.copy(),
    )
    try:
        est.align(ref, correct_scale=False)
        alignment = "se3"
    except GeometryException:
        # A straight-line path leaves the SE(3) fit rank-deficient: align the first poses instead.
        est.align_origin(ref)
        alignment = "origin"
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    out = {
        "alignment": alignment,
        "poses": int(ref.num_poses),
        "ape_rmse_m": float(ape.get_statistic(metrics.StatisticsType.rmse)),
        "ape_max_m": float(ape.get_statistic(metrics.StatisticsType.max)),
    }
    try:
        rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1.0, delta_unit=metrics.Unit.meters, all_pairs=False)
        rpe.process_data((ref, est))
        out["rpe_rmse_m_per_m"] = float(rpe.get_statistic(metrics.StatisticsType.rmse))
    except Exception as e:  # too short a path for 1 m pairs
        out["rpe_rmse_m_per_m"] = None
        out["rpe_note"] = str(e)
    return out, ref, est


def plot(a, ref, est_ours, ours_score, est_kiss, kiss_score):
    """Top: the path seen from above; bottom: the position error over time (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 7.0), gridspec_kw={"height_ratios": [3, 2]})
    top.plot(ref.positions_xyz[:, 0], ref.positions_xyz[:, 1], "k-", lw=2.5, label="ground truth")
    top.plot(est_ours.positions_xyz[:, 0], est_ours.positions_xyz[:, 1], "r-", lw=1.2,
             label=f"starc lio (APE {ours_score['ape_rmse_m'] * 100:.1f} cm)")
    top.plot(est_kiss.positions_xyz[:, 0], est_kiss.positions_xyz[:, 1], "b--", lw=1.0,
             label=f"KISS-ICP (APE {kiss_score['ape_rmse_m'] * 100:.1f} cm)")
    # Equal axes, but never thinner than 3 m: a straight path would otherwise be a sliver.
    xs = np.concatenate([ref.positions_xyz[:, 0], est_ours.positions_xyz[:, 0]])
    ys = np.concatenate([ref.positions_xyz[:, 1], est_ours.positions_xyz[:, 1]])
    cx, cy = (xs.max() + xs.min()) / 2, (ys.max() + ys.min()) / 2
    half = max(xs.max() - xs.min(), ys.max() - ys.min(), 3.0) / 2 + 0.5
    top.set_xlim(cx - half, cx + half)
    top.set_ylim(cy - half, cy + half)
    top.set_aspect("equal")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.set_title(a.title)
    top.legend(loc="best", fontsize=8)
    for est, style, name in ((est_ours, "r-", "starc lio"), (est_kiss, "b--", "KISS-ICP")):
        r, e = sync.associate_trajectories(ref, est, max_diff=0.006)
        err = np.linalg.norm(r.positions_xyz - e.positions_xyz, axis=1)
        bottom.semilogy(e.timestamps - ref.timestamps[0], np.maximum(err, 1e-4), style, lw=1.0, label=name)
    bottom.set_xlabel("time (s)")
    bottom.set_ylabel("position error (m)")
    bottom.grid(True, which="both", alpha=0.3)
    bottom.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(a.plot, dpi=80)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gt", required=True)
    ap.add_argument("--ours", required=True)
    ap.add_argument("--scans", required=True)
    ap.add_argument("--kiss-out")
    ap.add_argument("--plot")
    ap.add_argument("--title", default="")
    a = ap.parse_args()

    gt = file_interface.read_tum_trajectory_file(a.gt)
    ours = file_interface.read_tum_trajectory_file(a.ours)
    ours_score, ref_ours, est_ours = score(gt, ours)

    stamps, poses, times = kiss_icp(a.scans)
    best = None
    for name, frac in (("start", 0.0), ("middle", 0.5), ("end", 1.0)):
        ts = [(s + frac * (e - s)) * 1e-9 for s, e in stamps]
        try:
            sc, ref, est = score(gt, trajectory(ts, poses))
        except Exception as e:
            print(f"KISS-ICP stamped at the {name}: {e}", file=sys.stderr)
            continue
        if best is None or sc["ape_rmse_m"] < best[1]["ape_rmse_m"]:
            best = (name, sc, ref, est, ts)
    if best is None:
        raise SystemExit("KISS-ICP gave no trajectory that evo could associate with the truth")
    stamp_name, kiss_score, _, est_kiss, kiss_ts = best
    if a.kiss_out:
        file_interface.write_tum_trajectory_file(a.kiss_out, trajectory(kiss_ts, poses))
    times_ms = np.array(times) * 1e3
    result = {
        "title": a.title,
        "ours": ours_score,
        "kiss_icp": dict(kiss_score, stamped_at=stamp_name, scans=len(times),
                         time_ms_median=float(np.median(times_ms)), time_ms_p99=float(np.percentile(times_ms, 99))),
    }
    if a.plot:
        plot(a, ref_ours, est_ours, ours_score, est_kiss, kiss_score)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
