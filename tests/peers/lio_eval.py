"""Scores `starc lio` against ground truth with evo, next to peer odometries on the same scans.

    lio_eval.py --gt gt_robot.tum --ours 192.168.1.101.tum --scans 192.168.1.101_scans.bin \
        [--kiss-out kiss.tum] [--plot traj.png] [--title lab/robot] \
        [--peers kiss,genz,rko] [--peer-out-dir DIR] \
        [--imu avia.pcap --imu-device 192.168.1.101 | --imu imu.csv] [--extrinsics extrinsics.json] \
        [--lio-json lio.json]

Prints one JSON object: APE (translation RMSE/max, after an SE(3) Umeyama alignment, as
`evo_ape -a`, or of the first poses, as `--align_origin`, where a straight path leaves the SE(3)
fit undetermined; the first-pose alignment is also given on its own, `ape_origin_*`) and RPE
(translation error per 1 m travelled) for our trajectory and each peer's, and each peer's time per
scan (single thread where the library has the setting). Peers (`--peers`, default `kiss`, which
keeps the output that benches/lio.rs and tests/lio_cli.rs read):

- `kiss`: KISS-ICP (PyPI kiss-icp), LiDAR only, key `kiss_icp`;
- `genz`: GenZ-ICP (PyPI genz-icp), LiDAR only, key `genz_icp`;
- `rko`: RKO-LIO (PyPI rko_lio), LiDAR-inertial, key `rko_lio`. Needs the IMU the LiDAR was
  paired with: `--imu` a classic pcap (not pcapng) of the Avia's traffic (its IMU packets,
  data type 6, from `--imu-device`) or a CSV (`time_s,gyro xyz rad/s,accel xyz m/s^2`, as
  `starc sim` writes robot_imu_external.csv), and `T_lidar_imu` from `--extrinsics` (a
  `starc sim` run's extrinsics.json, key `--extrinsics-key`, default `robot_lidar_imu`; without
  it, the Avia's internal IMU offset). Its base frame is the LiDAR's, so its poses are the
  LiDAR's, as ours and the truth are.

KISS-ICP and GenZ-ICP deskew with their own constant-velocity model from the per-point times;
their pose is stamped at the scan time that scores best for them (start, middle or end), which the
output names. RKO-LIO deskews with the IMU and stamps its poses itself (`stamped_at: own`).
A peer other than KISS-ICP that fails gives `{"error": ...}` under its key instead of stopping the
run (RKO-LIO's RegistrationError, which stops its own pipeline, also gives the time it came and,
under `partial`, the scores of the poses before it). Each peer gets `ape_ratio_ours_to_peer`;
with `--lio-json` (`starc lio`'s summary) also our time per scan and `time_ratio_peer_to_ours`.
"""

import argparse
import json
import os
import struct
import sys
import time

import numpy as np
from evo.core import metrics, sync
from evo.core.geometry import GeometryException
from evo.core.trajectory import PoseTrajectory3D
from evo.tools import file_interface
from scipy.spatial.transform import Rotation

PEERS = {"kiss": ("kiss_icp", "KISS-ICP"), "genz": ("genz_icp", "GenZ-ICP"), "rko": ("rko_lio", "RKO-LIO")}
# T_lidar_imu of the Avia's internal IMU (the IMU's origin in the LiDAR frame), as `starc sim`'s
# extrinsics.json gives it and config/lio.toml's [extrinsics] (the inverse) says.
AVIA_LIDAR_IMU_M = (-0.04165, -0.02326, 0.0284)
STANDARD_GRAVITY_M_S2 = 9.80665


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


def register_frames(odom, scans_path):
    """Every scan of 100 points or more through a KISS-ICP-style `odom` (`register_frame` with
    per-point times normalised to [0, 1], `last_pose`): the scans' stamps, the poses and the
    registration times (s)."""
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


def kiss_icp(scans_path, threads=1):
    from kiss_icp.config import load_config
    from kiss_icp.kiss_icp import KissICP

    cfg = load_config(None)
    cfg.data.min_range = 0.5
    cfg.registration.max_num_threads = threads
    odom = KissICP(cfg)
    return register_frames(odom, scans_path)


def genz_icp(scans_path, deskew=True):
    """GenZ-ICP 0.3 with its defaults (= its `indoor` preset) but a 0.5 m minimum range and, by
    default, its deskew on (per-point times normalised to [0, 1], as KISS-ICP's). Its pybind
    takes no thread count: the registration is single-threaded (the Python config's
    `max_num_threads` is not passed on)."""
    from genz_icp.config import load_config
    from genz_icp.genz_icp import GenZICP

    cfg = load_config(None)
    cfg.data.min_range = 0.5
    cfg.data.deskew = deskew
    odom = GenZICP(cfg)
    return register_frames(odom, scans_path)


def read_imu_pcap(path, device):
    """The Livox IMU samples (data type 6) a classic pcap holds from `device` (source IPv4):
    (t_ns, gyro rad/s, acc m/s^2) sorted by time. The packet's stamp (PTP, device or PPS clock:
    nanoseconds; GPS: UTC) is the sample's time."""
    import mmap

    want = bytes(int(x) for x in device.split("."))
    out = []
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
        magic = m[:4]
        if magic in (b"\xd4\xc3\xb2\xa1", b"\x4d\x3c\xb2\xa1"):
            end = "<"
        elif magic in (b"\xa1\xb2\xc3\xd4", b"\xa1\xb2\x3c\x4d"):
            end = ">"
        else:
            raise SystemExit(f"{path}: not a classic pcap (pcapng: convert it, or give --imu a CSV)")
        linktype = struct.unpack_from(end + "I", m, 20)[0]
        at = 24
        size = len(m)
        rec = struct.Struct(end + "IIII")
        while at + 16 <= size:
            _, _, incl, _ = rec.unpack_from(m, at)
            at += 16
            pkt = m[at:at + incl] if incl < 200 else None
            at += incl
            if pkt is None:
                continue
            if linktype == 1:  # Ethernet, maybe one VLAN tag
                off, ethertype = 14, struct.unpack_from(">H", pkt, 12)[0]
                if ethertype == 0x8100:
                    off, ethertype = 18, struct.unpack_from(">H", pkt, 16)[0]
                if ethertype != 0x0800:
                    continue
            elif linktype == 101:  # raw IPv4
                off = 0
            else:
                raise SystemExit(f"{path}: link type {linktype} not read here")
            if len(pkt) < off + 20 or pkt[off] >> 4 != 4 or pkt[off + 9] != 17 or pkt[off + 12:off + 16] != want:
                continue
            body = pkt[off + (pkt[off] & 15) * 4 + 8:]
            if len(body) < 42 or body[0] != 5 or body[9] != 6:
                continue
            ts_type = body[8]
            if ts_type in (0, 1, 4):
                t_ns = struct.unpack_from("<Q", body, 10)[0]
            elif ts_type == 3:
                import datetime

                y, mo, d, h = body[10:14]
                us = struct.unpack_from("<I", body, 14)[0]
                base = datetime.datetime(2000 + y, mo, d, h, tzinfo=datetime.timezone.utc)
                t_ns = int(base.timestamp()) * 1_000_000_000 + us * 1000
            else:
                continue
            v = struct.unpack_from("<6f", body, 18)
            out.append((t_ns, v[0:3], tuple(a * STANDARD_GRAVITY_M_S2 for a in v[3:6])))
    out.sort(key=lambda s: s[0])
    return out


def read_imu_csv(path):
    """A CSV `time_s,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z` (SI, time in seconds)."""
    out = []
    with open(path) as f:
        for line in f:
            parts = line.strip().split(",")
            if len(parts) < 7:
                continue
            try:
                v = [float(p) for p in parts[:7]]
            except ValueError:  # the header
                continue
            whole, _, frac = parts[0].partition(".")
            t_ns = int(whole) * 1_000_000_000 + int((frac + "000000000")[:9]) if whole.isdigit() else int(v[0] * 1e9)
            out.append((t_ns, tuple(v[1:4]), tuple(v[4:7])))
    out.sort(key=lambda s: s[0])
    return out


def write_imu_csv(samples, path):
    with open(path, "w") as f:
        f.write("time_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2\n")
        for t_ns, g, a in samples:
            f.write(f"{t_ns // 1_000_000_000}.{t_ns % 1_000_000_000:09d},{g[0]:.9g},{g[1]:.9g},{g[2]:.9g},"
                    f"{a[0]:.9g},{a[1]:.9g},{a[2]:.9g}\n")


def lidar_t_imu(extrinsics_path, key):
    """T_lidar_imu (maps IMU-frame points into the LiDAR frame) as a 4x4 matrix."""
    T = np.eye(4)
    if extrinsics_path:
        with open(extrinsics_path) as f:
            e = json.load(f)[key]
        T[:3, :3] = Rotation.from_quat(e["quaternion_xyzw"]).as_matrix()
        T[:3, 3] = e["translation_m"]
    else:
        T[:3, 3] = AVIA_LIDAR_IMU_M
    return T


def rko_lio(scans_path, imu, T_lidar_imu, init_phase=True, voxel_m=None):
    """RKO-LIO 0.4 through its Python API (the same calls as its LIOPipeline and Sequencer): its
    defaults but a 0.5 m minimum range, one thread, and (by default) its initialization phase on
    (the robot stands still for its first 2 s); `voxel_m` replaces its 1 m map voxel. The base
    frame is the LiDAR's: the IMU enters with T_lidar_imu, the scans with the identity. Every IMU
    sample before a scan's end goes in before the scan; a scan's time is that of its
    register_scan call plus those samples' calls.
    """
    from rko_lio.config import LIOConfig
    from rko_lio.lio import LIO
    from rko_lio.rko_lio_pybind import InputError, RegistrationError

    cfg = LIOConfig(min_range=0.5, max_num_threads=1, initialization_phase=init_phase)
    if voxel_m:
        cfg.voxel_size = voxel_m
    lio = LIO(cfg)
    eye = np.eye(4)
    acc = np.array([s[2] for s in imu], dtype=np.float64)
    gyro = np.array([s[1] for s in imu], dtype=np.float64)
    t_imu = [s[0] for s in imu]
    nxt, times, dropped, failure, first_ns = 0, [], 0, None, None
    for start, end, pts, t in read_scans(scans_path):
        if len(pts) < 100:
            continue
        first_ns = start if first_ns is None else first_ns
        stamps_ns = start + np.round(t * 1e9).astype(np.int64)
        began = time.perf_counter()
        while nxt < len(t_imu) and t_imu[nxt] < end:
            lio.add_imu_measurement(acc[nxt], gyro[nxt], t_imu[nxt], T_lidar_imu)
            nxt += 1
        if nxt == 0:
            continue  # no IMU yet
        try:
            lio.register_scan(pts, stamps_ns, eye, int(start), int(end))
        except InputError as e:  # its pipeline drops such a scan and goes on
            dropped += 1
            if dropped <= 3:
                print(f"RKO-LIO dropped the scan at {end * 1e-9:.3f}: {e}", file=sys.stderr)
            continue
        except RegistrationError as e:  # its pipeline stops here
            failure = {"failed_at_s": (end - first_ns) * 1e-9, "failed_after_scans": len(times), "reason": str(e)}
            break
        times.append(time.perf_counter() - began)
    ts_ns, poses = lio.poses_with_timestamps()
    poses = np.asarray(poses)
    mats = []
    for p in poses:  # x, y, z, qx, qy, qz, qw
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(p[3:7]).as_matrix()
        T[:3, 3] = p[:3]
        mats.append(T)
    return [int(x) * 1e-9 for x in ts_ns], mats, times, dropped, failure


class PeerFailed(Exception):
    """A peer that stopped part way; `extra` holds what it did until then."""

    def __init__(self, message, extra):
        super().__init__(message)
        self.extra = extra


def trajectory(stamps_s, poses):
    xyz = np.array([p[:3, 3] for p in poses])
    quat_xyzw = Rotation.from_matrix(np.array([p[:3, :3] for p in poses])).as_quat()
    quat_wxyz = np.roll(quat_xyzw, 1, axis=1)
    return PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=quat_wxyz, timestamps=np.array(stamps_s))


def _copy(t):
    return PoseTrajectory3D(
        positions_xyz=t.positions_xyz.copy(),
        orientations_quat_wxyz=t.orientations_quat_wxyz.copy(),
        timestamps=t.timestamps.copy(),
    )


def _ape(ref, est):
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return float(ape.get_statistic(metrics.StatisticsType.rmse)), float(ape.get_statistic(metrics.StatisticsType.max))


def score(gt, est):
    ref, est = sync.associate_trajectories(gt, est, max_diff=0.006)
    origin = _copy(est)
    origin.align_origin(ref)
    est = _copy(est)
    try:
        est.align(ref, correct_scale=False)
        alignment = "se3"
    except GeometryException:
        # A straight-line path leaves the SE(3) fit rank-deficient: align the first poses instead.
        est = origin
        alignment = "origin"
    rmse, worst = _ape(ref, est)
    o_rmse, o_worst = _ape(ref, origin)
    out = {
        "alignment": alignment,
        "poses": int(ref.num_poses),
        "ape_rmse_m": rmse,
        "ape_max_m": worst,
        "ape_origin_rmse_m": o_rmse,
        "ape_origin_max_m": o_worst,
    }
    try:
        rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=1.0, delta_unit=metrics.Unit.meters, all_pairs=False)
        rpe.process_data((ref, est))
        out["rpe_rmse_m_per_m"] = float(rpe.get_statistic(metrics.StatisticsType.rmse))
    except Exception as e:  # too short a path for 1 m pairs
        out["rpe_rmse_m_per_m"] = None
        out["rpe_note"] = str(e)
    return out, ref, est


def best_stamping(gt, stamps, poses, label):
    """Scores the poses stamped at the scans' start, middle and end; the best of the three."""
    best = None
    for name, frac in (("start", 0.0), ("middle", 0.5), ("end", 1.0)):
        ts = [(s + frac * (e - s)) * 1e-9 for s, e in stamps]
        try:
            sc, ref, est = score(gt, trajectory(ts, poses))
        except Exception as e:
            print(f"{label} stamped at the {name}: {e}", file=sys.stderr)
            continue
        if best is None or sc["ape_rmse_m"] < best[1]["ape_rmse_m"]:
            best = (name, sc, ref, est, ts)
    return best


def timing(times):
    ms = np.array(times) * 1e3
    return {"scans": len(times), "time_ms_median": float(np.median(ms)), "time_ms_p99": float(np.percentile(ms, 99))}


def plot(a, gt, ref, est_ours, ours_score, peers):
    """Top: the path seen from above; bottom: the position error over time (log scale).
    `ref`: the truth at our poses; `peers`: (label, aligned est, score, style) each, whose stamps
    may differ from ours (start, middle or end of a scan): their errors are against `gt`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 7.0), gridspec_kw={"height_ratios": [3, 2]})
    top.plot(ref.positions_xyz[:, 0], ref.positions_xyz[:, 1], "k-", lw=2.5, label="ground truth")
    top.plot(est_ours.positions_xyz[:, 0], est_ours.positions_xyz[:, 1], "r-", lw=1.2,
             label=f"starc lio (APE {ours_score['ape_rmse_m'] * 100:.1f} cm)")
    for label, est, sc, style in peers:
        top.plot(est.positions_xyz[:, 0], est.positions_xyz[:, 1], style, lw=1.0,
                 label=f"{label} (APE {sc['ape_rmse_m'] * 100:.1f} cm)")
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
    for est, style, name in [(est_ours, "r-", "starc lio")] + [(e, s, l) for l, e, _, s in peers]:
        r, e = sync.associate_trajectories(gt, est, max_diff=0.006)
        err = np.linalg.norm(r.positions_xyz - e.positions_xyz, axis=1)
        bottom.semilogy(e.timestamps - ref.timestamps[0], np.maximum(err, 1e-4), style, lw=1.0, label=name)
    bottom.set_xlabel("time (s)")
    bottom.set_ylabel("position error (m)")
    bottom.grid(True, which="both", alpha=0.3)
    bottom.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(a.plot, dpi=80)


class StdoutToStderr:
    """Sends file descriptor 1 to stderr while a peer runs: RKO-LIO's C++ logs (spdlog) and
    GenZ-ICP's profiler print to stdout, where only the JSON line may go."""

    def __enter__(self):
        sys.stdout.flush()
        self.saved = os.dup(1)
        os.dup2(2, 1)
        return self

    def __exit__(self, *exc):
        sys.stdout.flush()
        os.dup2(self.saved, 1)
        os.close(self.saved)
        return False


def ours_time_ms(lio_json, ours_path):
    """Our median time per scan from `starc lio`'s lio.json: the device named like our TUM file."""
    with open(lio_json) as f:
        summary = json.load(f)
    name = os.path.basename(ours_path)[: -len(".tum")] if ours_path.endswith(".tum") else None
    devices = summary.get("devices", [])
    dev = next((d for d in devices if d.get("device") == name), devices[0] if len(devices) == 1 else None)
    return None if dev is None else dev.get("time_per_scan_ms_median")


def run_peer(p, a, gt):
    """Runs one peer on the scans and scores it: (entry, score, aligned estimate, stamps, poses)."""
    label = PEERS[p][1]
    if p == "rko":
        if not a.imu:
            raise RuntimeError("RKO-LIO needs the IMU: give --imu (pcap with --imu-device, or CSV)")
        if a.imu.endswith(".csv"):
            imu = read_imu_csv(a.imu)
        else:
            if not a.imu_device:
                raise RuntimeError("--imu is a capture: name the Avia with --imu-device")
            imu = read_imu_pcap(a.imu, a.imu_device)
        if len(imu) < 100:
            raise RuntimeError(f"only {len(imu)} IMU samples in {a.imu}")
        if a.imu_csv_out:
            write_imu_csv(imu, a.imu_csv_out)
        ts, poses, times, dropped, failure = rko_lio(a.scans, imu, lidar_t_imu(a.extrinsics, a.extrinsics_key),
                                                     init_phase=not a.rko_no_init_phase, voxel_m=a.rko_voxel)
        about = dict(stamped_at="own", imu_samples=len(imu), scans_dropped=dropped,
                     init_phase=not a.rko_no_init_phase, voxel_m=a.rko_voxel or 1.0)
        if failure:
            # Scored up to the failure, under `partial`: not comparable with a whole run's APE.
            partial = None
            if len(poses) >= 10:
                try:
                    partial = score(gt, trajectory(ts, poses))[0]
                except Exception as e:
                    partial = {"error": str(e)}
            extra = dict(failure, partial=partial, **about, **(timing(times) if times else {}))
            raise PeerFailed(f"RegistrationError at {failure['failed_at_s']:.1f} s: {failure['reason']}", extra)
        if len(poses) < 2:
            raise RuntimeError(f"RKO-LIO gave {len(poses)} poses")
        sc, _, est = score(gt, trajectory(ts, poses))
        entry = dict(sc, **about, **timing(times))
        return entry, sc, est, ts, poses
    if p == "kiss":
        stamps, poses, times = kiss_icp(a.scans)
    else:
        stamps, poses, times = genz_icp(a.scans, not a.genz_no_deskew)
    best = best_stamping(gt, stamps, poses, label)
    if best is None:
        raise RuntimeError(f"{label} gave no trajectory that evo could associate with the truth")
    stamp_name, sc, _, est, ts = best
    entry = dict(sc, stamped_at=stamp_name, **timing(times))
    if p == "genz":
        entry["deskew"] = not a.genz_no_deskew
    return entry, sc, est, ts, poses


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gt", required=True)
    ap.add_argument("--ours", required=True)
    ap.add_argument("--scans", required=True)
    ap.add_argument("--kiss-out", help="write KISS-ICP's trajectory (TUM) here")
    ap.add_argument("--plot")
    ap.add_argument("--title", default="")
    ap.add_argument("--peers", default="kiss", help="comma-separated: kiss, genz, rko (default kiss; none: ours only)")
    ap.add_argument("--peer-out-dir", help="write each peer's trajectory as <key>.tum here")
    ap.add_argument("--imu", help="RKO-LIO's IMU: a classic pcap of the Avia (with --imu-device) or a CSV")
    ap.add_argument("--imu-device", help="the Avia whose IMU packets to take from the --imu pcap")
    ap.add_argument("--imu-csv-out", help="also write the IMU samples read from --imu as a CSV")
    ap.add_argument("--extrinsics", help="a starc sim run's extrinsics.json for T_lidar_imu")
    ap.add_argument("--extrinsics-key", default="robot_lidar_imu")
    ap.add_argument("--genz-no-deskew", action="store_true", help="GenZ-ICP without its deskew (its preset)")
    ap.add_argument("--rko-no-init-phase", action="store_true", help="RKO-LIO without its initialization phase")
    ap.add_argument("--rko-voxel", type=float, help="RKO-LIO's map voxel in m (its default: 1.0)")
    ap.add_argument("--lio-json", help="starc lio's lio.json: adds our time per scan and the time ratios")
    a = ap.parse_args()

    peers = [p.strip() for p in a.peers.split(",") if p.strip() and p.strip() != "none"]
    for p in peers:
        if p not in PEERS:
            raise SystemExit(f"unknown peer {p!r}: choose from {', '.join(PEERS)}")

    gt = file_interface.read_tum_trajectory_file(a.gt)
    ours = file_interface.read_tum_trajectory_file(a.ours)
    ours_score, ref_ours, est_ours = score(gt, ours)
    ours_ms = ours_time_ms(a.lio_json, a.ours) if a.lio_json else None
    if ours_ms is not None:
        ours_score["time_ms_median"] = ours_ms

    result = {"title": a.title, "ours": ours_score}
    plotted = []
    styles = {"kiss": "b--", "genz": "g-.", "rko": "m:"}
    for p in peers:
        key, label = PEERS[p]
        try:
            with StdoutToStderr():
                entry, sc, est, traj_ts, poses = run_peer(p, a, gt)
        except Exception as e:
            if p == "kiss":
                raise SystemExit(str(e))
            print(f"{label}: {e}", file=sys.stderr)
            result[key] = dict({"error": str(e) if isinstance(e, PeerFailed) else f"{type(e).__name__}: {e}"},
                               **getattr(e, "extra", {}))
            continue
        if p == "kiss" and a.kiss_out:
            file_interface.write_tum_trajectory_file(a.kiss_out, trajectory(traj_ts, poses))
        if a.peer_out_dir:
            os.makedirs(a.peer_out_dir, exist_ok=True)
            file_interface.write_tum_trajectory_file(os.path.join(a.peer_out_dir, f"{key}.tum"), trajectory(traj_ts, poses))
        if entry["ape_rmse_m"] > 0:
            entry["ape_ratio_ours_to_peer"] = ours_score["ape_rmse_m"] / entry["ape_rmse_m"]
        if ours_ms:
            entry["time_ratio_peer_to_ours"] = entry["time_ms_median"] / ours_ms
        result[key] = entry
        plotted.append((label, est, sc, styles[p]))
    if a.plot:
        plot(a, gt, ref_ours, est_ours, ours_score, plotted)
    print(json.dumps(result))
    # RKO-LIO's profiler prints its figures when the process exits: to stderr, after the JSON.
    sys.stdout.flush()
    os.dup2(2, 1)


if __name__ == "__main__":
    main()
