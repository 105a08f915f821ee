"""The rig's LIO on generated buildings, scored with evo.

    .venv/bin/python scripts/rig_lio_ape.py RUN_DIR [--config config/lio.toml] [--label NAME]
        [--starc target/release/starc] [--out DIR]

RUN_DIR is a `starc eval --keep` output (each building's avia.pcap and gt_fpv.tum). For each
building: `starc lio avia.pcap --device 192.168.2.102` (the rig's Avia, its internal IMU, the
given config), then `evo_ape tum gt_fpv.tum OURS -a` (translation RMSE after an SE(3) Umeyama
fit). Prints one line per building (APE RMSE and max, and the LIO's health counts) and the
median, how many buildings are under 5 cm (the odometry issue's goal for the rig: 95 %) and
over 10 cm; with --out, writes `<label>.json` there.
"""

import argparse
import json
import pathlib
import re
import statistics
import subprocess
import sys

RIG_IP = "192.168.2.102"


def ape(gt, ours, evo_ape):
    """APE translation RMSE and max (m) after an SE(3) fit, from evo's text output."""
    out = subprocess.run([evo_ape, "tum", str(gt), str(ours), "-a"], capture_output=True, text=True, check=True)
    vals = dict(re.findall(r"^\s*(rmse|max)\s+([0-9.eE+-]+)", out.stdout, re.M))
    return float(vals["rmse"]), float(vals["max"])


def one(building, a, work):
    out = work / building.name
    out.mkdir(parents=True, exist_ok=True)
    cmd = [a.starc, "lio", str(building / "avia.pcap"), "--device", RIG_IP, "--out", str(out)]
    if a.config:
        cmd += ["--config", a.config]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        return {"name": building.name, "error": run.stderr.strip()[-300:]}
    rmse, worst = ape(building / "gt_fpv.tum", out / f"{RIG_IP}.tum", a.evo_ape)
    health = re.search(r"health: (.*?);", run.stdout + run.stderr)
    return {"name": building.name, "ape_rmse_m": rmse, "ape_max_m": worst, "health": health.group(1) if health else ""}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run_dir", type=pathlib.Path)
    p.add_argument("--config", help="LIO config for the rig (default: starc lio's defaults, config/lio.toml)")
    p.add_argument("--label", default="rig")
    p.add_argument("--starc", default="target/release/starc")
    p.add_argument("--evo-ape", default=str(pathlib.Path(sys.executable).parent / "evo_ape"))
    p.add_argument("--work", type=pathlib.Path, default=pathlib.Path("/tmp/rig_lio_ape"))
    p.add_argument("--out", type=pathlib.Path)
    a = p.parse_args()
    buildings = sorted(d for d in a.run_dir.iterdir() if (d / "avia.pcap").exists() and (d / "gt_fpv.tum").exists())
    if not buildings:
        sys.exit(f"no building with avia.pcap and gt_fpv.tum under {a.run_dir} (run starc eval with --keep)")
    rows = []
    for i, b in enumerate(buildings, 1):
        row = one(b, a, a.work / a.label)
        rows.append(row)
        if "error" in row:
            print(f"[{i}/{len(buildings)}] {b.name}: failed: {row['error']}", flush=True)
        else:
            print(f"[{i}/{len(buildings)}] {b.name}: APE RMSE {row['ape_rmse_m'] * 100:.1f} cm, "
                  f"max {row['ape_max_m'] * 100:.1f} cm; {row['health']}", flush=True)
    scored = [r["ape_rmse_m"] for r in rows if "ape_rmse_m" in r]
    if not scored:
        sys.exit("no building was scored")
    summary = {
        "label": a.label,
        "config": a.config,
        "buildings": len(rows),
        "scored": len(scored),
        "median_ape_rmse_m": statistics.median(scored) if scored else None,
        "under_5cm": sum(v < 0.05 for v in scored),
        "over_10cm": sum(v > 0.10 for v in scored),
    }
    print(f"{a.label}: median APE RMSE {summary['median_ape_rmse_m'] * 100:.1f} cm over {len(scored)} buildings; "
          f"under 5 cm in {summary['under_5cm']}, over 10 cm in {summary['over_10cm']}")
    if a.out:
        a.out.mkdir(parents=True, exist_ok=True)
        (a.out / f"{a.label}.json").write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
