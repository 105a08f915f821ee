#!/usr/bin/env python3
"""Trains the learned cluster scorer of the geometric detector ([detect] kind = "trees") and
writes config/models/cluster_trees.stpw.

Input: the cluster tables of `starc dataset --clusters` (DATA/<family>-<seed>/clusters.npy: per
cluster the detector's input vector, then the truth columns of eval/src/clusters.rs).
Development buildings only: seeds 0-49 and 70-89 and 60 extra halls (200-259, made with
`--family hall`) train, 50-69 validate; a test seed (1000 and up, or a meta.json that says
"test") is refused.

    starc dataset --seeds 0..89 --every 2 --clusters --no-points --out DATA
    starc dataset --seeds 200..259 --family hall --every 2 --clusters --no-points --out DATA
    python scripts/train/cluster_trees.py --data DATA --out config/models/cluster_trees.stpw \
        --reference config/models/cluster_trees_reference.npy

The trees are scikit-learn's HistGradientBoostingClassifier (four classes: not a person,
standing, sitting or crouching, lying). The export flattens them into node tables; before
writing, it checks that evaluating those tables gives scikit-learn's probabilities on every
validation row.
"""

import argparse
import collections
import json
import re
import sys
import time
from pathlib import Path

import numpy as np
from sklearn.ensemble import HistGradientBoostingClassifier

from stpw import read_stpw, write_stpw

INPUTS = 76  # pipeline/src/detect/trees/inputs.rs
POSTURE, SHARE_ON, COVERAGE, RETURNS, APART, WINDOW, CX, CY, RULE_SCORE = range(INPUTS, INPUTS + 9)
COLUMNS = INPUTS + 9  # eval/src/clusters.rs
VISIBLE_RETURNS = 30
TEST_SEED_MIN = 1000
CLASSES = ("none", "standing", "low", "lying")


def parse_seeds(text):
    seeds = set()
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds.update(range(int(lo), int(hi or lo) + 1))
    return seeds


def load(data_dir, seeds):
    rows, names = [], []
    for path in sorted(Path(data_dir).glob("*/clusters.npy")):
        building = path.parent.name
        m = re.fullmatch(r"([a-z]+)-(\d+)", building)
        if not m or int(m.group(2)) not in seeds:
            continue
        meta = json.loads((path.parent / "meta.json").read_text())
        if int(m.group(2)) >= TEST_SEED_MIN or meta.get("set") == "test":
            sys.exit(f"{path}: a test building; training and validation take development seeds only")
        table = np.load(path)
        if table.ndim != 2 or table.shape[1] != COLUMNS:
            sys.exit(f"{path}: {table.shape}, expected rows of {COLUMNS} (made by another version?)")
        rows.append(table)
        names += [building] * len(table)
    if not rows:
        sys.exit(f"no cluster tables for those seeds in {data_dir}")
    return np.concatenate(rows), np.array(names)


def family_weights(names, balance):
    """Per row, (its family's share of the buildings in `names`)^-balance, normalised to a mean
    of 1 over the buildings: a family given many extra buildings (`starc dataset --family`)
    then adds variety without outweighing the others."""
    buildings = sorted(set(names))
    family = {b: b.split("-")[0] for b in buildings}
    count = collections.Counter(family.values())
    per_building = {b: (count[f] / len(buildings)) ** -balance for b, f in family.items()}
    mean = np.mean(list(per_building.values()))
    return np.array([per_building[n] / mean for n in names])


def targets(table):
    """0 (not a person) or the posture of the person the cluster would be taken for: mostly
    their points, or most of them with its centre where the scorer matches them (within 0.5 m
    of their box centre: a sitting person merged with their chair)."""
    person = (table[:, SHARE_ON] >= 0.5) | ((table[:, COVERAGE] >= 0.5) & (table[:, APART] <= 0.5))
    return np.where(person, table[:, POSTURE], 0).astype(int)


def usable(table):
    """Rows trained and scored on: a cluster that is a barely visible person is neither a
    person the evaluation demands nor a false positive, so it teaches nothing."""
    return (targets(table) == 0) | (table[:, RETURNS] >= VISIBLE_RETURNS)


def report(name, p_person, table, thresholds):
    y = targets(table) > 0
    print(f"{name}: {int(y.sum())} person clusters of {len(y)}")
    for t in thresholds:
        det = p_person >= t
        tp, fp, fn = int((det & y).sum()), int((det & ~y).sum()), int((~det & y).sum())
        prec, rec = tp / max(tp + fp, 1), tp / max(tp + fn, 1)
        print(f"  p >= {t:.2f}: precision {prec:.3f} recall {rec:.3f} (TP {tp}, FP {fp}, missed {fn})")
    t = targets(table)
    at = 0.5
    per = ", ".join(f"{CLASSES[k]} {float((p_person[t == k] >= at).mean()):.3f} of {int((t == k).sum())}"
                    for k in range(1, len(CLASSES)) if (t == k).any())
    print(f"  recall per posture at p >= {at}: {per}")
    rules = table[:, RULE_SCORE] >= 0.5
    tp, fp = int((rules & y).sum()), int((rules & ~y).sum())
    print(f"  the rules (score >= 0.5): precision {tp / max(tp + fp, 1):.3f} recall {tp / max(int(y.sum()), 1):.3f}")


def flatten(clf):
    """Node tables of every tree, children after their parent: (feature, threshold, left,
    right, value), tree roots and classes, base logits."""
    feature, threshold, left, right, value, roots, classes = [], [], [], [], [], [], []
    for stage in clf._predictors:
        for k, predictor in enumerate(stage):
            nodes = predictor.nodes
            offset = len(feature)
            roots.append(offset)
            classes.append(k)
            for n in nodes:
                leaf = bool(n["is_leaf"])
                feature.append(-1 if leaf else int(n["feature_idx"]))
                threshold.append(0.0 if leaf else float(n["num_threshold"]))
                left.append(0 if leaf else offset + int(n["left"]))
                right.append(0 if leaf else offset + int(n["right"]))
                value.append(float(n["value"]) if leaf else 0.0)
    base = np.asarray(clf._baseline_prediction, np.float64).reshape(-1)
    return feature, threshold, left, right, value, roots, classes, base


def predict_tables(tensors, x):
    """The Rust model's evaluation, in numpy (the export's self-check)."""
    t = dict(tensors)
    feature, threshold = t["node_feature"].astype(int), t["node_threshold"]
    left, right, value = t["node_left"].astype(int), t["node_right"].astype(int), t["node_value"]
    logits = np.tile(t["base"].astype(np.float64), (len(x), 1))
    for root, k in zip(t["tree_root"].astype(int), t["tree_class"].astype(int)):
        at = np.full(len(x), root)
        while True:
            inner = feature[at] >= 0
            if not inner.any():
                break
            f = np.where(inner, feature[at], 0)
            go_left = x[np.arange(len(x)), f] <= threshold[at]
            at = np.where(inner, np.where(go_left, left[at], right[at]), at)
        logits[:, k] += value[at]
    e = np.exp(logits - logits.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def export(clf, out, x_check):
    feature, threshold, left, right, value, roots, classes, base = flatten(clf)
    if len(base) != len(CLASSES):
        sys.exit(f"the classifier has {len(base)} classes, the detector reads {len(CLASSES)}")
    for i, (l, r) in enumerate(zip(left, right)):
        if feature[i] >= 0 and (l <= i or r <= i):
            sys.exit(f"node {i}: a child before its parent")
    f32 = lambda v: np.asarray(v, np.float32)  # noqa: E731
    tensors = [
        ("inputs", f32([INPUTS])),
        ("base", f32(base)),
        ("tree_root", f32(roots)),
        ("tree_class", f32(classes)),
        ("node_feature", f32(feature)),
        ("node_threshold", f32(threshold)),
        ("node_left", f32(left)),
        ("node_right", f32(right)),
        ("node_value", f32(value)),
    ]
    write_stpw(out, tensors)
    back = read_stpw(out)
    x32 = x_check.astype(np.float32)
    diff = np.abs(predict_tables(back, x32) - clf.predict_proba(x32)).max()
    print(f"{out}: {len(roots)} trees, {len(feature)} nodes, {Path(out).stat().st_size} bytes;"
          f" tables against scikit-learn on {len(x32)} rows: max |dp| {diff:.2e}")
    if diff > 1e-4:
        sys.exit("the exported tables do not reproduce the classifier")
    return back


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, help="a `starc dataset --clusters` directory")
    ap.add_argument("--train-seeds", default="0-49,70-89,200-259")
    ap.add_argument("--val-seeds", default="50-69")
    ap.add_argument("--out", required=True, help="the .stpw to write")
    ap.add_argument("--iterations", type=int, default=200)
    ap.add_argument("--leaves", type=int, default=63)
    ap.add_argument("--learning-rate", type=float, default=0.1)
    ap.add_argument("--positive-weight", type=float, default=3.0,
                    help="weight of a person cluster against 1 for the rest (about 1 in 20 is a person)")
    ap.add_argument("--family-balance", type=float, default=0.5,
                    help="weigh each building by (its family's share of the training buildings)^-B: 0 "
                         "weighs every building alike, 1 gives every family the same total weight")
    ap.add_argument("--reference", help="also write rows and their probabilities here (.npy) for the Rust test")
    args = ap.parse_args()

    train, train_names = load(args.data, parse_seeds(args.train_seeds))
    val, _ = load(args.data, parse_seeds(args.val_seeds))
    keep = usable(train)
    train, train_names, val = train[keep], train_names[keep], val[usable(val)]
    started = time.time()
    clf = HistGradientBoostingClassifier(
        max_iter=args.iterations,
        learning_rate=args.learning_rate,
        max_leaf_nodes=args.leaves,
        l2_regularization=1.0,
        early_stopping=False,
        random_state=0,
    )
    y = targets(train)
    weight = np.where(y > 0, args.positive_weight, 1.0) * family_weights(train_names, args.family_balance)
    clf.fit(train[:, :INPUTS].astype(np.float32), y, sample_weight=weight)
    print(f"trained on {len(train)} clusters in {time.time() - started:.0f} s")
    thresholds = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
    p_val = 1.0 - clf.predict_proba(val[:, :INPUTS].astype(np.float32))[:, 0]
    report("validation", p_val, val, thresholds)
    export(clf, args.out, val[:, :INPUTS])
    if args.reference:
        # Half people, half not, spread over the validation buildings.
        pick = [np.flatnonzero(m)[np.linspace(0, m.sum() - 1, 32).astype(int)]
                for m in (targets(val) > 0, targets(val) == 0)]
        rows = val[np.concatenate(pick), :INPUTS].astype(np.float32)
        np.save(args.reference, np.concatenate([rows, clf.predict_proba(rows).astype(np.float32)], axis=1))
    summary = {"train_clusters": len(train), "val_clusters": len(val), "iterations": args.iterations,
               "leaves": args.leaves, "learning_rate": args.learning_rate, "positive_weight": args.positive_weight,
               "family_balance": args.family_balance}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
