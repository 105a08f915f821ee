#!/usr/bin/env python3
"""Our LIO next to KISS-ICP, GenZ-ICP and RKO-LIO on the same scans of generated buildings.

    .venv/bin/python scripts/odometry_peers.py [--seeds 1000..1023] [--dev] [--peers kiss,genz,rko] \
        [--work /tmp/odo_peers/work] [--out /tmp/odo_peers/results] [--starc target/release/starc]

For each building seed: `starc gen`, `starc sim --sensors-only --no-camera --seed S` (the noise
seed is the building's, as `starc eval` does), then `starc lio` on the robot's Avia
(192.168.1.101) with config/lio_robot.toml, once with the base's wheels (the run's robot_can.log,
decoded with a base.toml written from the scenario's wheel layout and motors, as the simulator's
base is: `WheelFeedback::plain`) and `--dump-scans`, once without; then tests/peers/lio_eval.py
with `--peers` on the dumped scans (RKO-LIO gets the Avia's internal IMU from the pcap and
T_lidar_imu from the run's extrinsics.json). The pcap and the other bulk files are deleted after
each building (`--keep` keeps them).

Writes, under --out: `<name>.json` per building (everything: our scores with and without the
wheels, our lio.json figures, the peers' scores and times), `<name>.png` (the paths and the
errors), `summary.json` and `summary.md` (one row per building, medians). A building whose
`<name>.json` already exists is not run again (`--force` runs it again); `--summary-only`
rebuilds the summary from the JSON files there.

Seeds 1000 and up are the test set (report only, never tune on them); seeds under 1000 are the
development set and need `--dev`. One run takes one set, as `starc eval` does; the output says
which. Everything runs under `nice -n 10`, one process at a time.
"""

import argparse
import datetime
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests/peers"))

ROBOT_IP = "192.168.1.101"
# Which Avia is scored (--side): its address, our LIO config, its truth, the extrinsics key of its
# internal IMU (RKO-LIO), and whether a base's wheels exist to fuse (the rig has none).
SIDES = {
    "robot": {"ip": ROBOT_IP, "config": "config/lio_robot.toml", "gt": "gt_robot.tum",
              "imu_key": "robot_lidar_imu", "wheels": True},
    "rig": {"ip": "192.168.2.102", "config": "config/lio_rig.toml", "gt": "gt_fpv.tum",
            "imu_key": "fpv_lidar_imu", "wheels": False},
}
PEER_KEYS = {"kiss": ("kiss_icp", "KISS-ICP"), "genz": ("genz_icp", "GenZ-ICP"), "rko": ("rko_lio", "RKO-LIO")}

# The simulator's bases (hil/src/sim/wheels.rs `default_geometry`), as config/base.toml's
# [kinematics]; wheels 1..n in kinematics order, none inverted, the drivers' default gear ratio
# and CiA 402 units: what eval/src/wheels.rs `sim_wheel_feedback` decodes robot_can.log with.
KINEMATICS = {
    "omni3": ('model = "omni3"\nwheel_radius_m = 0.05\ncenter_to_wheel_m = 0.2\n', 3),
    "omni4": ('model = "omni4"\nwheel_radius_m = 0.05\ncenter_to_wheel_m = 0.2\n', 4),
    "mecanum": ('model = "mecanum"\nwheel_radius_m = 0.076\nhalf_length_m = 0.2\nhalf_width_m = 0.2\n', 4),
}


def parse_seeds(text):
    seeds = []
    for part in text.split(","):
        part = part.strip()
        if ".." in part:
            lo, hi = part.split("..")
            seeds.extend(range(int(lo), int(hi) + 1))
        elif part:
            seeds.append(int(part))
    return seeds


def base_toml(scenario_path):
    """A base.toml for `starc lio --base-config` matching the scenario's simulated base."""
    with open(scenario_path, "rb") as f:
        robot = tomllib.load(f).get("robot", {})
    layout = robot.get("wheels", "omni3")
    motors = robot.get("motors", "c620")
    kin, n = KINEMATICS[layout]
    wheels = ", ".join(f"{{ id = {i} }}" for i in range(1, n + 1))
    text = (
        "# Written by scripts/odometry_peers.py: the simulator's base for this scenario.\n"
        '[can]\ntransport = "socketcan"\ninterface = "can0"\n\n'
        f"[kinematics]\n{kin}\n"
        "[limits]\nmax_vx_m_s = 1.0\nmax_vy_m_s = 1.0\nmax_wz_rad_s = 2.0\nmax_accel_m_s2 = 1.5\n"
        "max_alpha_rad_s2 = 4.0\nmax_wheel_rad_s = 30.0\n\n"
        f'[motors]\nprotocol = "{motors}"\nwheels = [{wheels}]\n'
    )
    return text, layout, motors


def run(cmd, log, **kw):
    """Runs `nice -n 10 cmd`, appending its output to `log`; returns (stdout, seconds)."""
    began = time.monotonic()
    with open(log, "a") as lf:
        lf.write(f"\n$ {' '.join(map(str, cmd))}\n")
        lf.flush()
        p = subprocess.run(["nice", "-n", "10", *map(str, cmd)], stdout=subprocess.PIPE, stderr=lf, text=True, **kw)
        lf.write(p.stdout if len(p.stdout) < 20000 else p.stdout[-20000:])
    if p.returncode != 0:
        raise RuntimeError(f"{cmd[0]} {cmd[1] if len(cmd) > 1 else ''} failed ({p.returncode}); see {log}")
    return p.stdout, time.monotonic() - began


def lio_device(lio_dir, ip):
    with open(lio_dir / "lio.json") as f:
        summary = json.load(f)
    dev = next(d for d in summary["devices"] if d["device"] == ip)
    keep = ("status", "scans_in", "scans_out", "health", "scans_refused", "times_lost", "time_per_scan_ms_median",
            "time_per_scan_ms_p99", "time_per_scan_ms_max", "points_per_scan_median", "map_points")
    out = {k: dev.get(k) for k in keep}
    out["peak_rss_mib"] = summary.get("peak_rss_mib")
    out["wall_s"] = summary.get("wall_s")
    return out


def one_building(seed, a, work_root, out_dir):
    work = work_root / f"seed-{seed}"
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    log = work / "log.txt"
    row = {"seed": seed, "set": "test" if seed >= 1000 else "development",
           "started_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "load_avg_1m_at_start": os.getloadavg()[0],
           "starc_built_utc": datetime.datetime.fromtimestamp(os.stat(a.starc).st_mtime, datetime.timezone.utc)
           .isoformat(timespec="seconds")}
    scenario = work / "scenario.toml"
    gen_out, _ = run([a.starc, "gen", "--seed", seed, "--out", scenario], log)
    with open(scenario, "rb") as f:
        sc = tomllib.load(f)
    row["name"] = sc["name"]
    row["family"] = re.sub(r"-\d+$", "", sc["name"])
    row["duration_s"] = sc.get("duration_s")
    text, layout, motors = base_toml(scenario)
    (work / "base.toml").write_text(text)
    row["base"] = {"wheels": layout, "motors": motors}

    _, row["sim_wall_s"] = run([a.starc, "sim", scenario, "--sensors-only", "--no-camera", "--seed", seed,
                                "--out", work], log)
    side = SIDES[a.side]
    ip, cfg = side["ip"], ROOT / side["config"]
    lio_w, lio_n = work / "lio", work / "lio_nowheels"
    wheels = ["--wheels", work / "robot_can.log", "--base-config", work / "base.toml"] if side["wheels"] else []
    run([a.starc, "lio", work / "avia.pcap", "--device", ip, "--config", cfg, *wheels, "--dump-scans",
         "--out", lio_w], log)
    if side["wheels"]:
        run([a.starc, "lio", work / "avia.pcap", "--device", ip, "--config", cfg, "--out", lio_n], log)
    # "wheels" names our run that the peers are compared with; the rig's is its only one.
    row["lio_wheels"] = lio_device(lio_w, ip)
    if side["wheels"]:
        row["lio_nowheels"] = lio_device(lio_n, ip)

    import lio_eval  # the same scoring as the peers'
    from evo.tools import file_interface

    gt_path = work / side["gt"]
    if side["wheels"]:
        gt = file_interface.read_tum_trajectory_file(str(gt_path))
        ours_n = file_interface.read_tum_trajectory_file(str(lio_n / f"{ip}.tum"))
        row["ours_nowheels"], _, _ = lio_eval.score(gt, ours_n)

    plot = out_dir / f"{row['name']}.png"
    cmd = [sys.executable, ROOT / "tests/peers/lio_eval.py", "--gt", gt_path,
           "--ours", lio_w / f"{ip}.tum", "--scans", lio_w / f"{ip}_scans.bin",
           "--peers", a.peers, "--peer-out-dir", work / "peers", "--lio-json", lio_w / "lio.json",
           "--plot", plot, "--title", f"{row['name']} / {a.side} (seed {seed}, {row['set']})"]
    if "rko" in a.peers:
        cmd += ["--imu", work / "avia.pcap", "--imu-device", ip, "--imu-csv-out", work / f"{a.side}_imu_internal.csv",
                "--extrinsics", work / "extrinsics.json", "--extrinsics-key", side["imu_key"]]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    line, row["eval_wall_s"] = run(cmd, log, env=env)
    row["eval"] = json.loads(next(x for x in reversed(line.splitlines()) if x.startswith("{")))
    row["ours_wheels"] = row["eval"]["ours"]
    row["side"] = a.side

    if not a.keep:
        for bulk in ("avia.pcap", "labels_robot.bin", "labels_fpv.bin", "robot_imu_external.mip"):
            (work / bulk).unlink(missing_ok=True)
        for d in (lio_w, lio_n):
            for f in d.glob("*"):
                if f.suffix in (".bin", ".pcd", ".ply"):
                    f.unlink()
    return row


def failed_cell(t, p):
    if not t.get(f"{p}_error"):
        return "-"
    at = t.get(f"{p}_failed_at_s")
    return "failed" if at is None else f"failed at {at:.0f} s"


def fmt_cm(v):
    return "-" if v is None else f"{v * 100:.1f}"


def fmt(v, spec):
    return "-" if v is None else format(v, spec)


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


SIDE_TEXT = {
    "robot": "The robot's Avia (192.168.1.101), `starc sim --sensors-only --no-camera --seed S`; ours is "
             "`starc lio --config config/lio_robot.toml` with the base's wheels (W) and without (no W).",
    "rig": "The rig's Avia (192.168.2.102, the responder's helmet or handheld rig), `starc sim --sensors-only "
           "--no-camera --seed S`; ours is `starc lio --config config/lio_rig.toml` (no wheels), the truth "
           "gt_fpv.tum. RKO-LIO gets the rig's internal IMU (`fpv_lidar_imu`).",
}


def summarize(rows, peers, out_dir, meta):
    peer_list = [p for p in ("kiss", "genz", "rko") if p in peers]
    side = meta.get("side", "robot")
    wheels = SIDES[side]["wheels"]
    table = []
    for r in sorted(rows, key=lambda r: r["seed"]):
        e = r.get("eval", {})
        ours_w = r["ours_wheels"]["ape_rmse_m"]
        t = {"seed": r["seed"], "name": r["name"], "set": r["set"], "ours_wheels_ape_m": ours_w,
             "ours_wheels_ms": r["lio_wheels"]["time_per_scan_ms_median"],
             "alignment": r["ours_wheels"]["alignment"]}
        if wheels:
            t["ours_nowheels_ape_m"] = r["ours_nowheels"]["ape_rmse_m"]
            t["ours_nowheels_ms"] = r["lio_nowheels"]["time_per_scan_ms_median"]
        for p in peer_list:
            key = PEER_KEYS[p][0]
            pe = e.get(key, {})
            ape = pe.get("ape_rmse_m")
            ms = pe.get("time_ms_median")
            t[f"{p}_ape_m"] = ape
            t[f"{p}_ms"] = ms
            t[f"{p}_error"] = pe.get("error")
            t[f"{p}_failed_at_s"] = pe.get("failed_at_s")
            t[f"ours_to_{p}_ape"] = ours_w / ape if ape else None
            if wheels:
                t[f"ours_nowheels_to_{p}_ape"] = t["ours_nowheels_ape_m"] / ape if ape else None
            t[f"ours_to_{p}_time"] = t["ours_wheels_ms"] / ms if ms else None
        table.append(t)
    keys = [k for k in table[0] if k not in ("seed", "name", "set", "alignment")
            and not k.endswith(("_error", "_failed_at_s"))] if table else []
    medians = {k: median([t[k] for t in table]) for k in keys}

    names = {p: PEER_KEYS[p][1] for p in peer_list}
    sets = sorted({t["set"] for t in table})
    md = [f"# starc lio next to {', '.join(names.values())}: {len(table)} generated buildings ({', '.join(sets)} set)",
          "",
          f"Made by `scripts/odometry_peers.py --side {side}` ({meta['when']}, seeds {meta['seeds']}, "
          f"starc {meta['starc']}). " + SIDE_TEXT[side] + " The peers "
          "run on the very scans ours ran on (`--dump-scans`), scored by tests/peers/lio_eval.py with evo: APE "
          "translation RMSE after an SE(3) Umeyama fit (`evo_ape -a`; the first-pose fit where a straight path "
          "leaves it undetermined). Ratios are ours / peer (below 1: ours smaller). Times are per 100 ms scan, "
          "medians, one thread, on a 2-core machine shared with other work (ours: lio.json, the filter's time "
          "per scan; peers: their Python register call, RKO-LIO's with its IMU calls).",
          "",
          "## Accuracy (APE RMSE, cm)",
          ""]
    if wheels:
        head = ["building", "ours W", "ours no W"] + [names[p] for p in peer_list] + \
            [f"W / {names[p]}" for p in peer_list] + [f"no W / {names[p]}" for p in peer_list]
    else:
        head = ["building", "ours"] + [names[p] for p in peer_list] + [f"ours / {names[p]}" for p in peer_list]
    md.append("| " + " | ".join(head) + " |")
    md.append("|" + "---|" * len(head))

    def acc_row(label, t):
        cells = [label, fmt_cm(t["ours_wheels_ape_m"])] + ([fmt_cm(t["ours_nowheels_ape_m"])] if wheels else [])
        cells += [fmt_cm(t[f"{p}_ape_m"]) if t.get(f"{p}_ape_m") is not None else failed_cell(t, p) for p in peer_list]
        cells += [fmt(t[f"ours_to_{p}_ape"], ".3f") for p in peer_list]
        if wheels:
            cells += [fmt(t[f"ours_nowheels_to_{p}_ape"], ".3f") for p in peer_list]
        return "| " + " | ".join(cells) + " |"

    for t in table:
        md.append(acc_row(f"{t['name']} ({t['seed']})" + (" [origin fit]" if t["alignment"] != "se3" else ""), t))
    if table:
        md.append(acc_row("**median**", medians))
    md += ["", "## Time per scan (ms, median)", ""]
    ours = ["ours W", "ours no W"] if wheels else ["ours"]
    head = ["building", *ours] + [names[p] for p in peer_list] + [f"{ours[0]} / {names[p]}" for p in peer_list]
    md.append("| " + " | ".join(head) + " |")
    md.append("|" + "---|" * len(head))

    def time_row(label, t):
        cells = [label, fmt(t["ours_wheels_ms"], ".2f")] + ([fmt(t["ours_nowheels_ms"], ".2f")] if wheels else [])
        cells += [fmt(t[f"{p}_ms"], ".2f") for p in peer_list]
        cells += [fmt(t[f"ours_to_{p}_time"], ".2f") for p in peer_list]
        return "| " + " | ".join(cells) + " |"

    for t in table:
        md.append(time_row(f"{t['name']} ({t['seed']})", t))
    if table:
        md.append(time_row("**median**", medians))
    finished = ", ".join(f"{names[p]} {sum(1 for t in table if t[f'{p}_ape_m'] is not None)}" for p in peer_list)
    md += ["", f"Medians are over the buildings a peer finished ({finished} of {len(table)}); a peer's time "
           "counts the scans it took until it failed. Peers run with their defaults but a 0.5 m minimum range "
           "(KISS-ICP 1.3, GenZ-ICP 0.3 with its deskew on, RKO-LIO 0.4 with its initialization phase, "
           "base frame = the LiDAR's, the Avia's internal IMU at 200 Hz)."]
    failed = [(t["name"], p, t[f"{p}_error"]) for t in table for p in peer_list if t.get(f"{p}_error")]
    if failed:
        md += ["", "## Peers that failed", ""] + [f"- {n}, {names[p]}: {err}" for n, p, err in failed]
    missing = meta.get("failed_buildings") or []
    if missing:
        md += ["", "## Buildings that failed", ""] + [f"- seed {s}: {err}" for s, err in missing]
    (out_dir / "summary.md").write_text("\n".join(md) + "\n")
    (out_dir / "summary.json").write_text(json.dumps({"meta": meta, "rows": table, "medians": medians}, indent=1))
    return "\n".join(md)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="1000..1023", help="e.g. 1000..1023, 1000..1007 or 3,5 (default: the test set)")
    ap.add_argument("--dev", action="store_true", help="allow development seeds (under 1000)")
    ap.add_argument("--peers", default="kiss,genz,rko")
    ap.add_argument("--work", default="/tmp/odo_peers/work", help="scratch; each building's folder is emptied first")
    ap.add_argument("--out", default="/tmp/odo_peers/results")
    ap.add_argument("--starc", default=str(ROOT / "target/release/starc"))
    ap.add_argument("--keep", action="store_true", help="keep the pcap, the scans and the maps")
    ap.add_argument("--force", action="store_true", help="run buildings again whose JSON exists")
    ap.add_argument("--summary-only", action="store_true")
    ap.add_argument("--side", choices=sorted(SIDES), default="robot",
                    help="whose Avia: the robot's (with and without its wheels) or the rig's (default: robot)")
    a = ap.parse_args()

    seeds = parse_seeds(a.seeds)
    dev = [s for s in seeds if s < 1000]
    if dev and not a.dev:
        raise SystemExit(f"seeds {dev} are development seeds: pass --dev (test seeds are 1000 and up)")
    if dev and len(dev) != len(seeds):
        raise SystemExit("one run takes one set: development seeds (under 1000) or test seeds (1000 and up)")
    for p in a.peers.split(","):
        if p not in PEER_KEYS:
            raise SystemExit(f"unknown peer {p!r}")
    out_dir, work_root = Path(a.out), Path(a.work)
    out_dir.mkdir(parents=True, exist_ok=True)
    starc_rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    built = datetime.datetime.fromtimestamp(os.stat(a.starc).st_mtime, datetime.timezone.utc)
    starc_rev += f", binary built {built:%Y-%m-%d %H:%M:%S} UTC"
    meta = {"when": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "seeds": a.seeds,
            "set": "development" if dev else "test", "peers": a.peers, "starc": f"{a.starc} (HEAD {starc_rev})",
            "failed_buildings": [], "side": a.side}
    rows = []
    for seed in seeds:
        done = sorted(out_dir.glob(f"*-{seed}.json"))
        if done and (a.summary_only or not a.force):
            rows.append(json.loads(done[0].read_text()))
            continue
        if a.summary_only:
            continue
        began = time.monotonic()
        try:
            row = one_building(seed, a, work_root, out_dir)
        except Exception as e:
            print(f"seed {seed}: {e}", file=sys.stderr)
            meta["failed_buildings"].append((seed, str(e)))
            continue
        row["wall_s"] = time.monotonic() - began
        (out_dir / f"{row['name']}.json").write_text(json.dumps(row, indent=1))
        rows.append(row)
        e = row["eval"]
        peers = ", ".join(f"{PEER_KEYS[p][1]} {fmt_cm(e.get(PEER_KEYS[p][0], {}).get('ape_rmse_m'))}"
                          for p in a.peers.split(","))
        ours = (f"{fmt_cm(row['ours_wheels']['ape_rmse_m'])} cm with wheels, "
                f"{fmt_cm(row['ours_nowheels']['ape_rmse_m'])} without" if SIDES[a.side]["wheels"]
                else f"{fmt_cm(row['ours_wheels']['ape_rmse_m'])} cm")
        print(f"{row['name']} (seed {seed}, {a.side}): ours {ours}; {peers} cm; {row['wall_s']:.0f} s", flush=True)
    if not a.keep and work_root.exists() and not a.summary_only:
        for d in work_root.glob("seed-*"):
            for bulk in ("avia.pcap", "labels_robot.bin", "labels_fpv.bin"):
                (d / bulk).unlink(missing_ok=True)
    print(summarize(rows, a.peers.split(","), out_dir, meta))


if __name__ == "__main__":
    main()
