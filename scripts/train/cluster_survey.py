#!/usr/bin/env python3
"""Where the learned cluster scorer loses people: per person and window, whether the survey has
a cluster that is that person, and whether the trees take it.

Input: the cluster tables of `starc dataset --clusters` (development seeds only; a test seed is
refused, as in cluster_trees.py) and a trees file (the shipped one by default).

    python scripts/train/cluster_survey.py --data DATA --seeds 50-59

Each person-window (a person with at least 30 returns in a surveyed window) falls in one class:
- found: a cluster the training would call that person (cluster_trees.targets) is shown to the
  trees (not over 3 x 1.5 m) and gets at least --min-score;
- rejected: such a cluster is shown but scores lower;
- not shown: the only such clusters are too big to be shown;
- no cluster: no cluster is that person (merged into something bigger and off their centre, or
  split into pieces that are mostly something else).
It also counts "clean" person-windows: a cluster mostly theirs and holding at least half of
their points exists. The survey applies none of the detector's rules on top of the trees (the
ceiling contact, the field-of-view cut, one person per 0.5 m), so comparing "found" with the
mission's recall (`starc eval`) on the same buildings shows what those rules cost.
"""

import argparse
import collections
from pathlib import Path

import numpy as np

import cluster_trees as ct
from stpw import read_stpw

MAX_LENGTH_M, MAX_WIDTH_M = 3.0, 1.5  # pipeline/src/detect/trees/mod.rs
LENGTH, WIDTH = 2, 3  # input columns (pipeline/src/detect/trees/inputs.rs)
POSTURES = {1: "standing", 2: "sitting or crouching", 3: "lying"}
CLASSES = ("found", "rejected", "not shown", "no cluster")


def person_windows(table, names):
    """Row indices of each (building, window, person), people with enough returns only. A
    person is told apart in a window by their posture and returns (the table has no label)."""
    visible = (table[:, ct.POSTURE] > 0) & (table[:, ct.RETURNS] >= ct.VISIBLE_RETURNS)
    groups = collections.defaultdict(list)
    for i in np.flatnonzero(visible):
        key = (names[i], int(table[i, ct.WINDOW]), int(table[i, ct.POSTURE]), int(table[i, ct.RETURNS]))
        groups[key].append(i)
    return {k: np.array(v) for k, v in groups.items()}


def classify(rows, table, p, min_score):
    person = rows[ct.targets(table[rows]) > 0]
    shown = person[(table[person, LENGTH] <= MAX_LENGTH_M) & (table[person, WIDTH] <= MAX_WIDTH_M)]
    if len(shown):
        return "found" if p[shown].max() >= min_score else "rejected"
    return "not shown" if len(person) else "no cluster"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a `starc dataset --clusters` directory")
    ap.add_argument("--seeds", default="50-59", help="development seeds, inclusive ranges")
    ap.add_argument("--trees", default=str(Path(__file__).resolve().parents[2] / "config/models/cluster_trees.stpw"))
    ap.add_argument("--min-score", type=float, default=0.7, help="the detector's trees.min_score")
    args = ap.parse_args()

    table, names = ct.load(args.data, ct.parse_seeds(args.seeds))
    p = 1.0 - ct.predict_tables(read_stpw(args.trees), table[:, : ct.INPUTS].astype(np.float32))[:, 0]
    counts = collections.defaultdict(collections.Counter)
    for (building, _, posture, _), rows in person_windows(table, names).items():
        c = classify(rows, table, p, args.min_score)
        clean = ((table[rows, ct.SHARE_ON] >= 0.5) & (table[rows, ct.COVERAGE] >= 0.5)).any()
        for key in (("all", "all"), ("posture", POSTURES[posture]), ("building", building)):
            counts[key][c] += 1
            counts[key]["clean"] += int(clean)
    print(f"{args.data}, seeds {args.seeds}, trees {args.trees}, p >= {args.min_score}")
    print(f"{'':28s} {'person-windows':>14s} " + " ".join(f"{c:>10s}" for c in CLASSES) + f" {'clean':>8s}")
    for key in sorted(counts, key=lambda k: ({"all": 0, "posture": 1, "building": 2}[k[0]], k[1])):
        n = sum(counts[key][c] for c in CLASSES)
        shares = " ".join(f"{counts[key][c] / n:10.3f}" for c in CLASSES)
        print(f"{key[1]:28s} {n:14d} {shares} {counts[key]['clean'] / n:8.3f}")


if __name__ == "__main__":
    main()
