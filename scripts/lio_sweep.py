#!/usr/bin/env python3
"""The robot's or the rig's LIO on many generated buildings, for one or more configs, in minutes.

    .venv/bin/python scripts/lio_sweep.py --seeds 0..83 --dev --config config/lio_robot.toml \
        [--config other.toml ...] [--side robot|rig] [--work /tmp/lio_sweep]
        [--starc target/release/starc] [--jobs 2]

Each building is generated and simulated once and kept under --work: `starc gen --seed S`,
`starc sim --sensors-only --no-camera --seed S` (the noise seed is the building's, as `starc eval`
does), the pcap cut to the robot's Avia (192.168.1.101; about 150 MB a building instead of 500)
and a base.toml for the scenario's wheels (as scripts/odometry_peers.py writes it). Then, per
config, `starc lio` with the base's wheels (robot_can.log), scored as `starc eval` scores the
robot (report.json `robot_pose_error.rmse_m`: translation RMSE after tying the first pose to the
truth's; the same figure to the digit on the buildings checked). `starc lio` with
config/lio_robot.toml and the wheels is the mission's robot LIO, so a config's effect on the
robot's odometry is measured without running the missions (84 buildings: about 2 minutes a
config on 2 cores, once the buildings exist).

`--side rig` runs the responder's Avia (192.168.2.102, its own IMU, no wheels) instead, scored
against gt_fpv.tum as report.json's `rig_lio_error` (the same tie at the first pose); the sides
are scripts/odometry_peers.py's. Both Avias' records are cut from one simulation, so a building
prepared for one side serves the other.

Prints per config: median RMSE, how many buildings under 3 cm, under 5 cm and over 10 cm (the
odometry issue's goals: 3 cm for the robot, 5 cm for the rig), p90, worst, mean; writes
`<work>/sweep_<side>_<config stem>.json` (seed: RMSE).
Seeds 1000 and up are the test set (report only); seeds under 1000 need `--dev`.
"""

import argparse
import json
import re
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from odometry_peers import SIDES, base_toml, parse_seeds  # noqa: E402
from pcap_records import read_pcap  # noqa: E402


def split_pcap(src, dsts):
    """Writes the classic-pcap (Ethernet, IPv4) records of each source address to its own file."""
    by_ip = {bytes(int(x) for x in ip.split(".")): dst for ip, dst in dsts.items()}
    outs = {ip: open(dst, "wb") for ip, dst in by_ip.items()}
    try:
        header, records = read_pcap(src)
        for o in outs.values():
            o.write(header)
        for _, rec, data in records:
            if len(data) >= 34 and (o := outs.get(data[26:30])):
                o.write(rec)
                o.write(data)
    finally:
        for o in outs.values():
            o.close()


def prepare(starc, work, seed, legs=None):
    """Generates and simulates one building once; returns its directory. `legs`: the responder's
    leg profile written into the scenario (`[responder] legs`), or the generator's."""
    d = work / str(seed)
    scenario = d / "scenario.toml"
    if all((d / f"{side}.pcap").exists() for side in SIDES):
        prepared = re.search(r'^legs = "(\w+)"$', scenario.read_text(), re.M)
        if (prepared and prepared.group(1)) != legs:
            sys.exit(f"{d} was prepared with other legs ({prepared and prepared.group(1)}, not {legs}): "
                     "give --work a directory of its own")
        return d
    (d / "sim").mkdir(parents=True, exist_ok=True)
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "check": True}
    subprocess.run([starc, "gen", "--seed", str(seed), "--out", scenario], **quiet)
    if legs:
        text = scenario.read_text()
        if "\n[responder]\n" not in text:
            sys.exit(f"{scenario}: no [responder] table to set legs in")
        scenario.write_text(text.replace("\n[responder]\n", f'\n[responder]\nlegs = "{legs}"\n', 1))
    subprocess.run([starc, "sim", scenario, "--sensors-only", "--no-camera", "--seed", str(seed),
                    "--out", d / "sim"], **quiet)
    split_pcap(d / "sim/avia.pcap", {s["ip"]: d / f"{side}.pcap.part" for side, s in SIDES.items()})
    for side in SIDES:
        (d / f"{side}.pcap.part").rename(d / f"{side}.pcap")
    for bulky in ["avia.pcap", "labels_robot.bin", "labels_fpv.bin"]:
        (d / "sim" / bulky).unlink(missing_ok=True)
    (d / "base.toml").write_text(base_toml(scenario)[0])
    return d


def matrix(row):
    x, y, z, w = row[4:8]
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, row[1:4]
    return m


def rmse_from_first_pose(est_tum, gt_tum):
    """Translation RMSE after tying the first estimated pose to the truth's at its time."""
    est, gt = np.loadtxt(est_tum, ndmin=2), np.loadtxt(gt_tum, ndmin=2)
    if len(est) == 0:
        return float("nan")
    hi = np.clip(np.searchsorted(gt[:, 0], est[:, 0]), 0, len(gt) - 1)
    lo = np.clip(hi - 1, 0, len(gt) - 1)
    near = np.where(abs(gt[lo, 0] - est[:, 0]) < abs(gt[hi, 0] - est[:, 0]), lo, hi)
    tie = matrix(gt[near[0]]) @ np.linalg.inv(matrix(est[0]))
    err = [np.linalg.norm((tie @ matrix(e))[:3, 3] - gt[j, 1:4]) for e, j in zip(est, near)]
    return float(np.sqrt(np.mean(np.square(err))))


def run_lio(starc, d, config, side):
    s = SIDES[side]
    out = d / f"lio_{side}_{Path(config).stem}"
    cmd = [starc, "lio", d / f"{side}.pcap", "--device", s["ip"], "--config", config, "--out", out]
    if s["wheels"]:
        cmd += ["--wheels", d / "sim/robot_can.log", "--base-config", d / "base.toml"]
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return rmse_from_first_pose(out / f"{s['ip']}.tum", d / "sim" / s["gt"])


def summary(name, rmse):
    v = sorted(rmse.values())
    n = len(v)
    return (f"{name}: {n} buildings, median {statistics.median(v) * 100:.2f} cm, under 3 cm "
            f"{sum(x < 0.03 for x in v)}, under 5 cm {sum(x < 0.05 for x in v)}, over 10 cm {sum(x > 0.1 for x in v)}, "
            f"p90 {v[int(0.9 * n)] * 100:.1f} cm, "
            f"worst {v[-1] * 100:.1f} cm, mean {statistics.mean(v) * 100:.2f} cm")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", required=True)
    ap.add_argument("--dev", action="store_true", help="allow development seeds (under 1000)")
    ap.add_argument("--config", action="append", required=True, help="a LIO config (repeat for more)")
    ap.add_argument("--side", choices=sorted(SIDES), default="robot", help="whose LIO (default: robot)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/lio_sweep"))
    ap.add_argument("--starc", default=str(ROOT / "target/release/starc"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--responder-legs", choices=["min_jerk", "walk"],
                    help="how the responder's legs speed up (scenario [responder] legs; default: the "
                         "generator's); buildings are prepared once, so give it a --work of its own")
    a = ap.parse_args()
    seeds = parse_seeds(a.seeds)
    if any(s < 1000 for s in seeds) and not a.dev:
        sys.exit("seeds under 1000 are the development set: pass --dev")
    if any(s < 1000 for s in seeds) and any(s >= 1000 for s in seeds):
        sys.exit("one run takes one set: development (under 1000) or test (1000 and up)")
    a.work.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(a.jobs) as ex:
        dirs = dict(zip(seeds, ex.map(lambda s: prepare(a.starc, a.work, s, a.responder_legs), seeds)))
        for config in a.config:
            rmse = dict(zip(seeds, ex.map(lambda s: run_lio(a.starc, dirs[s], config, a.side), seeds)))
            (a.work / f"sweep_{a.side}_{Path(config).stem}.json").write_text(json.dumps(rmse, indent=1))
            print(summary(Path(config).stem, rmse), flush=True)


if __name__ == "__main__":
    main()
