#!/usr/bin/env python3
"""Run `rig_diag` (every search a first alignment, beside one attempt from the truth) on the
buildings `scripts/lio_sweep.py` prepared, for one alignment config, two at a time.

    cargo build --release -p starc-pipeline --example rig_diag
    python3 scripts/rig_diag_sweep.py --seeds 0..35 --dev --out OUT [--work /tmp/lio_sweep]
        [--align-toml F] [--stop-after-s 12] [--jobs 2]

Each building needs `<work>/<seed>/` from `lio_sweep.py` (sim/, robot.pcap, rig.pcap: the
simulation's two Avia records). The two are merged back into one capture by time stamp, kept
as `<work>/<seed>/diag/avia.pcap` (about 300 MB) beside links to the simulation's files, and
`rig_diag` runs on that with NO_HINT=1 NEVER_APPLY=1, writing `OUT/<building>.txt`.
`--align-toml` is an `AlignConfig` table (config/align.toml's keys) for every search and the
attempt from the truth; `--stop-after-s` ends each run at its first search past that many
seconds of the rig (0: the whole run). The truth is read by `rig_diag`'s scoring lines only.

Then: `scripts/rig_diag_summary.py --within 10 OUT/*.txt` and `scripts/rig_diag_confirm.py
OUT/*.txt`. Seeds 1000 and up are the test set (report only); seeds under 1000 need `--dev`.
"""

import argparse
import heapq
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from odometry_peers import parse_seeds  # noqa: E402
from pcap_records import read_pcap  # noqa: E402


def merge_pcaps(out, first, second):
    """One capture of both files' records by time stamp (both written by one simulation, so
    they share a header)."""
    header, a = read_pcap(first)
    _, b = read_pcap(second)
    tmp = out.with_suffix(".part")
    with open(tmp, "wb") as w:
        w.write(header)
        for _, rec, data in heapq.merge(a, b, key=lambda r: r[0]):
            w.write(rec)
            w.write(data)
    tmp.rename(out)


def prepare(building):
    """`<building>/diag/`: the simulation's files and the merged capture; its scenario's name."""
    if not all((building / p).exists() for p in ("sim", "robot.pcap", "rig.pcap", "scenario.toml")):
        sys.exit(f"{building}: not prepared; run scripts/lio_sweep.py with the same --work and seeds first")
    diag = building / "diag"
    diag.mkdir(exist_ok=True)
    for f in (building / "sim").iterdir():
        link = diag / f.name
        if link.is_symlink() and not link.exists():
            link.unlink()  # the building was prepared again elsewhere
        if not link.exists():
            link.symlink_to(f.resolve())
    if not (diag / "avia.pcap").exists():
        merge_pcaps(diag / "avia.pcap", building / "robot.pcap", building / "rig.pcap")
    for line in (building / "scenario.toml").read_text().splitlines():
        if line.startswith("name = "):
            return diag, line.split('"')[1]
    return diag, building.name


def run(seed, a):
    diag, name = prepare(Path(a.work) / str(seed))
    env = dict(os.environ, NO_HINT="1", NEVER_APPLY="1")
    if a.align_toml:
        env["ALIGN_TOML"] = str(Path(a.align_toml).resolve())
    if a.stop_after_s > 0:
        env["STOP_AFTER_S"] = str(a.stop_after_s)
    out = Path(a.out) / f"{name}.txt"
    with open(out, "w") as f:
        done = subprocess.run([a.rig_diag, str(diag)], stdout=f, stderr=subprocess.DEVNULL, env=env)
    print(f"{name}: {'ok' if done.returncode == 0 else f'rig_diag failed ({done.returncode})'}", flush=True)
    return done.returncode


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", required=True, help="A..B (inclusive) or a comma list")
    ap.add_argument("--dev", action="store_true", help="allow development seeds (under 1000)")
    ap.add_argument("--work", default="/tmp/lio_sweep", help="lio_sweep.py's --work")
    ap.add_argument("--out", required=True)
    ap.add_argument("--align-toml")
    ap.add_argument("--stop-after-s", type=float, default=12.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--rig-diag", default=str(ROOT / "target/release/examples/rig_diag"))
    a = ap.parse_args()
    seeds = parse_seeds(a.seeds)
    if any(s < 1000 for s in seeds) and not a.dev:
        sys.exit("seeds under 1000 are development seeds: pass --dev")
    if not Path(a.rig_diag).exists():
        sys.exit(f"{a.rig_diag}: build it with cargo build --release -p starc-pipeline --example rig_diag")
    Path(a.out).mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(a.jobs) as pool:
        failed = sum(rc != 0 for rc in pool.map(lambda s: run(s, a), seeds))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
