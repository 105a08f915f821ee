"""Trains, evaluates and exports the PointPillars person detector; docs/pillars.md is the contract.

    pillars.py train --data DATA [--train-seeds 0-49] [--val-seeds 50-59] --out runs/pillars.pt
        [--minutes M] [--epochs E] [--batch 8] [--lr 2e-3]
    pillars.py export --ckpt runs/pillars.pt --out-dir config/models
    pillars.py eval --data DATA --seeds 50-59 --ckpt runs/pillars.pt

DATA is `starc dataset` output: one `<family>-<seed>/` directory per building. Seeds of 1000 and
above are the held-out test set: training and validation refuse them, `eval` only reports.
`train` keeps the best checkpoint by validation F1 at --out and the last one next to it
(`<out>.last.pt`). `export` folds the batch norms and writes `pillars.stpw` (what the Rust
inference loads) with `pfn.onnx` and `backbone.onnx` (what its test compares against).
"""

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from stpw import read_stpw, write_stpw

# The pillar grid (docs/pillars.md, "Pillars"); written to the weights file as `grid`.
X_MIN, X_MAX = 0.0, 19.2
Y_MIN, Y_MAX = -9.6, 9.6
Z_MIN, Z_MAX = -0.3, 2.7
PILLAR_M = 0.2
GRID = 96
MAX_POINTS = 32
POINT_FEATURES = 8
PFN_CHANNELS = 32

# The head (docs/pillars.md, "The head").
CELL_M = 0.4
HEAD_GRID = 48
CLASSES = ("standing", "sitting", "crouching", "lying")
HEAD_CHANNELS = 12
VISIBLE_RETURNS = 30  # fewer returns than this: not visible, neither demanded nor trained on

# Layers in the order of the weights file; every one but h1 has a batch norm to fold.
LAYERS = ("pfn", "a0", "a1", "a2", "b0", "b1", "up", "h0", "h1")

TEST_SEED_MIN = 1000
HEATMAP_SIGMA_CELLS = 1.0
GAUSSIAN_RADIUS = 3  # cells: 3 sigma, beyond which the peak is below 0.012
HEATMAP_PRIOR_BIAS = -2.19  # sigmoid(-2.19) = 0.1: the focal loss starts from a low score everywhere
MATCH_RADIUS_M = 0.5
DEFAULT_MIN_SCORE = 0.3
PERSON_WINDOW_WEIGHT = 3.0


# ---------------------------------------------------------------------------------------------
# Pillars


def pillarize(xyz_m):
    """Points [N, 3] (model frame, m) -> (features [P, 32, 8], mask [P, 32], coords [P, 2] (iy, ix)).

    Pillars come ordered by (iy, ix); each keeps at most 32 points, spread over its points in the
    input (firing) order (docs/pillars.md).
    Arithmetic is float32, as in the Rust inference.
    """
    xyz = np.asarray(xyz_m, dtype=np.float32).reshape(-1, 3)
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    inside = (x >= X_MIN) & (x < X_MAX) & (y >= Y_MIN) & (y < Y_MAX) & (z >= Z_MIN) & (z < Z_MAX)
    xyz = xyz[inside]
    pillar_m = np.float32(PILLAR_M)
    ix = np.floor(xyz[:, 0] / pillar_m).astype(np.int64)
    iy = np.floor((xyz[:, 1] - np.float32(Y_MIN)) / pillar_m).astype(np.int64)
    # A float32 coordinate just below the upper crop edge can divide to exactly 96.
    np.clip(ix, 0, GRID - 1, out=ix)
    np.clip(iy, 0, GRID - 1, out=iy)

    key = iy * GRID + ix
    order = np.argsort(key, kind="stable")  # stable: window order survives inside a pillar
    sorted_key = key[order]
    pillar_keys, first_index, counts = np.unique(sorted_key, return_index=True, return_counts=True)
    pillar_count = len(pillar_keys)
    pillar_of_point = np.repeat(np.arange(pillar_count), counts)
    slot = np.arange(len(sorted_key)) - first_index[pillar_of_point]
    # A pillar with n > 32 points keeps those at floor(i n / 32), i = 0..31: spread over the
    # window, so that the Avia's rosette, which sweeps a pillar over time, is sampled whole.
    n = counts[pillar_of_point]
    pick = (slot * MAX_POINTS + n - 1) // n
    spread = (pick < MAX_POINTS) & ((pick * n) // MAX_POINTS == slot)
    kept = np.where(n <= MAX_POINTS, True, spread)
    slot = np.where(n <= MAX_POINTS, slot, pick)
    points = xyz[order][kept]
    pillar_of_point = pillar_of_point[kept]
    slot = slot[kept]

    kept_counts = np.minimum(counts, MAX_POINTS)
    kept_starts = np.concatenate(([0], np.cumsum(kept_counts)[:-1]))
    sums = np.add.reduceat(points, kept_starts, axis=0) if pillar_count else np.zeros((0, 3), np.float32)
    means = sums / kept_counts[:, None].astype(np.float32)

    pillar_iy = pillar_keys // GRID
    pillar_ix = pillar_keys % GRID
    centre_x = (pillar_ix.astype(np.float32) + np.float32(0.5)) * pillar_m
    centre_y = (pillar_iy.astype(np.float32) + np.float32(0.5)) * pillar_m + np.float32(Y_MIN)

    point_features = np.empty((len(points), POINT_FEATURES), np.float32)
    point_features[:, 0:3] = points
    point_features[:, 3:6] = points - means[pillar_of_point]
    point_features[:, 6] = points[:, 0] - centre_x[pillar_of_point]
    point_features[:, 7] = points[:, 1] - centre_y[pillar_of_point]

    features = np.zeros((pillar_count, MAX_POINTS, POINT_FEATURES), np.float32)
    mask = np.zeros((pillar_count, MAX_POINTS), np.float32)
    features[pillar_of_point, slot] = point_features
    mask[pillar_of_point, slot] = 1.0
    coords = np.stack([pillar_iy, pillar_ix], axis=1).astype(np.int64)
    return features, mask, coords


# ---------------------------------------------------------------------------------------------
# Model


class PillarNet(nn.Module):
    """The layers of docs/pillars.md. `folded=True` builds the exported form: every layer with a
    bias and no batch norms, so its state dict names are exactly the weights file's."""

    def __init__(self, folded=False):
        super().__init__()

        def norm(kind, channels):
            return nn.Identity() if folded else kind(channels)

        self.pfn = nn.Linear(POINT_FEATURES, PFN_CHANNELS, bias=folded)
        self.pfn_bn = norm(nn.BatchNorm1d, PFN_CHANNELS)
        self.a0 = nn.Conv2d(PFN_CHANNELS, 24, 3, stride=2, padding=1, bias=folded)
        self.a0_bn = norm(nn.BatchNorm2d, 24)
        self.a1 = nn.Conv2d(24, 24, 3, padding=1, bias=folded)
        self.a1_bn = norm(nn.BatchNorm2d, 24)
        self.a2 = nn.Conv2d(24, 24, 3, padding=1, bias=folded)
        self.a2_bn = norm(nn.BatchNorm2d, 24)
        self.b0 = nn.Conv2d(24, 48, 3, stride=2, padding=1, bias=folded)
        self.b0_bn = norm(nn.BatchNorm2d, 48)
        self.b1 = nn.Conv2d(48, 48, 3, padding=1, bias=folded)
        self.b1_bn = norm(nn.BatchNorm2d, 48)
        self.up = nn.ConvTranspose2d(48, 24, 2, stride=2, bias=folded)
        self.up_bn = norm(nn.BatchNorm2d, 24)
        self.h0 = nn.Conv2d(48, 32, 1, bias=folded)
        self.h0_bn = norm(nn.BatchNorm2d, 32)
        self.h1 = nn.Conv2d(32, HEAD_CHANNELS, 1)
        if not folded:
            with torch.no_grad():
                self.h1.bias[: len(CLASSES)].fill_(HEATMAP_PRIOR_BIAS)

    def pillar_features(self, point_features, point_pillar, pillar_count):
        """Kept points' features [M, 8] and pillar index [M] -> [P, 32]. Working on the kept points
        only (see `compact`) keeps padding out of the batch norm's statistics and saves the
        [P, 32, 32] activations that are mostly padding. The max starts from 0, which is harmless:
        the ReLU outputs are >= 0 and every pillar has a point."""
        per_point = F.relu(self.pfn_bn(self.pfn(point_features)))
        index = point_pillar[:, None].expand(-1, PFN_CHANNELS)
        return per_point.new_zeros(pillar_count, PFN_CHANNELS).scatter_reduce(0, index, per_point, "amax")

    def backbone(self, canvas):
        """[B, 32, 96, 96] -> [B, 12, 48, 48] raw head (logits for channels 0-3)."""
        a = F.relu(self.a0_bn(self.a0(canvas)))
        a = F.relu(self.a1_bn(self.a1(a)))
        a = F.relu(self.a2_bn(self.a2(a)))
        b = F.relu(self.b0_bn(self.b0(a)))
        b = F.relu(self.b1_bn(self.b1(b)))
        up = F.relu(self.up_bn(self.up(b)))
        h = F.relu(self.h0_bn(self.h0(torch.cat([a, up], dim=1))))
        return self.h1(h)

    def forward(self, point_features, point_pillar, coords, batch_size):
        """coords [P, 3]: (sample in batch, iy, ix) of each pillar."""
        pillars = self.pillar_features(point_features, point_pillar, len(coords))
        return self.backbone(scatter(pillars, coords, batch_size))


def compact(features, mask):
    """pillarize's padded form -> (kept points' features [M, 8], their pillar index [M])."""
    kept = mask > 0
    return features[kept], np.nonzero(kept)[0]


def scatter(pillar_features, coords, batch_size):
    """Pillar features [P, 32] at coords [P, 3] (sample, iy, ix) -> canvas [B, 32, 96, 96], zeros
    where no pillar."""
    canvas = pillar_features.new_zeros(batch_size, PFN_CHANNELS, GRID * GRID)
    canvas[coords[:, 0], :, coords[:, 1] * GRID + coords[:, 2]] = pillar_features
    return canvas.view(batch_size, PFN_CHANNELS, GRID, GRID)


def fold(model):
    """A PillarNet(folded=True) computing what `model` computes in eval mode: each batch norm's
    running statistics folded into the weight and bias before it (in float64, then rounded)."""
    folded = PillarNet(folded=True)
    state = {}
    for name in LAYERS[:-1]:
        layer, bn = getattr(model, name), getattr(model, name + "_bn")
        scale = bn.weight.double() / torch.sqrt(bn.running_var.double() + bn.eps)
        shift = bn.bias.double() - bn.running_mean.double() * scale
        # Output channels: dim 0 for linear and conv ([out, in, ...]), dim 1 for the transposed conv.
        out_dim = 1 if isinstance(layer, nn.ConvTranspose2d) else 0
        shape = [1] * layer.weight.dim()
        shape[out_dim] = -1
        state[name + ".weight"] = (layer.weight.double() * scale.view(shape)).float()
        state[name + ".bias"] = shift.float()
    state["h1.weight"] = model.h1.weight.detach().clone()
    state["h1.bias"] = model.h1.bias.detach().clone()
    folded.load_state_dict(state)
    return folded.eval()


# ---------------------------------------------------------------------------------------------
# Dataset


def parse_seeds(text):
    """'0-49' or '0-49,55,60-62' (inclusive) -> sorted list."""
    seeds = set()
    for part in text.split(","):
        low, _, high = part.strip().partition("-")
        seeds.update(range(int(low), int(high or low) + 1))
    return sorted(seeds)


class Building:
    def __init__(self, directory):
        self.points_cm = np.load(directory / "points.npy")
        self.windows = np.load(directory / "windows.npy")
        boxes = np.load(directory / "boxes.npy").reshape(-1, 10)
        # Boxes sorted by window, so a window's boxes are one slice.
        self.boxes = boxes[np.argsort(boxes[:, 0], kind="stable")]
        self.box_starts = np.searchsorted(self.boxes[:, 0], np.arange(len(self.windows) + 1))

    def window_boxes(self, index):
        """-> boxes [B, 10] of one window."""
        return self.boxes[self.box_starts[index] : self.box_starts[index + 1]]

    def window(self, index):
        """-> (points [N, 3] float32 m, boxes [B, 10])."""
        start, count = self.windows[index]
        xyz = self.points_cm[start : start + count].astype(np.float32) / np.float32(100.0)
        return xyz, self.window_boxes(index)


def load_buildings(data_dir, seeds, allow_test):
    wanted = set(seeds)
    test_seeds = sorted(seed for seed in wanted if seed >= TEST_SEED_MIN)
    if not allow_test and test_seeds:
        raise SystemExit(
            f"seed {test_seeds[0]}: seeds {TEST_SEED_MIN} and above are the held-out test set, "
            "not for training or validation"
        )
    buildings = []
    for directory in sorted(Path(data_dir).iterdir()):
        family, _, seed = directory.name.rpartition("-")
        if not directory.is_dir() or not family or not seed.isdigit() or int(seed) not in wanted:
            continue
        meta = json.loads((directory / "meta.json").read_text())
        if not allow_test and str(meta.get("set", "")).lower() == "test":
            raise SystemExit(f"{directory}: meta.json says it is in the test set")
        buildings.append(Building(directory))
    if not buildings:
        raise SystemExit(f"{data_dir}: no building directories for seeds {seeds[0]}-{seeds[-1]}")
    return buildings


def augment(xyz, boxes, rng):
    """A random mirror y -> -y, turn about the sensor's vertical of +-10 deg and floor-height
    error of +-5 cm, applied to points and boxes alike."""
    xyz, boxes = xyz.copy(), boxes.copy()
    if rng.random() < 0.5:
        xyz[:, 1] *= -1
        boxes[:, 2] *= -1
        boxes[:, 7] *= -1
    angle = rng.uniform(-math.radians(10), math.radians(10))
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]], np.float32)
    xyz[:, :2] = xyz[:, :2] @ rotation.T
    boxes[:, 1:3] = boxes[:, 1:3] @ rotation.T
    boxes[:, 7] += angle
    dz = np.float32(rng.uniform(-0.05, 0.05))
    xyz[:, 2] += dz
    boxes[:, 3] += dz
    return xyz, boxes


def centre_cells(boxes):
    """-> (in_head mask [B], row [B], col [B]) of each box centre's head cell."""
    cx, cy = boxes[:, 1], boxes[:, 2]
    in_head = (cx >= X_MIN) & (cx < X_MAX) & (cy >= Y_MIN) & (cy < Y_MAX)
    col = np.clip(np.floor(cx / CELL_M), 0, HEAD_GRID - 1).astype(np.int64)
    row = np.clip(np.floor((cy - Y_MIN) / CELL_M), 0, HEAD_GRID - 1).astype(np.int64)
    return in_head, row, col


def make_targets(boxes):
    """CenterPoint-lite targets for one window's boxes.

    -> heatmap [4, 48, 48] (1 at a visible person's centre cell on its class channel, a Gaussian
    around it), ignore [48, 48] (no heatmap loss: around barely visible people), regression
    [8, 48, 48] (channels 4-11 of the head, set at centre cells only), centre [48, 48] (bool).
    """
    heatmap = np.zeros((len(CLASSES), HEAD_GRID, HEAD_GRID), np.float32)
    ignore = np.zeros((HEAD_GRID, HEAD_GRID), bool)
    regression = np.zeros((HEAD_CHANNELS - len(CLASSES), HEAD_GRID, HEAD_GRID), np.float32)
    centre = np.zeros((HEAD_GRID, HEAD_GRID), bool)
    in_head, rows, cols = centre_cells(boxes)
    for box, inside, r, c in zip(boxes, in_head, rows, cols):
        returns = box[9]
        if not inside or returns <= 0:
            continue  # outside the grid, or no returns at all: nothing in the input shows it
        if returns < VISIBLE_RETURNS:
            ignore[max(r - 1, 0) : r + 2, max(c - 1, 0) : c + 2] = True
            continue
        r0, r1 = max(r - GAUSSIAN_RADIUS, 0), min(r + GAUSSIAN_RADIUS + 1, HEAD_GRID)
        c0, c1 = max(c - GAUSSIAN_RADIUS, 0), min(c + GAUSSIAN_RADIUS + 1, HEAD_GRID)
        squared = (np.arange(r0, r1)[:, None] - r) ** 2 + (np.arange(c0, c1)[None, :] - c) ** 2
        peak = np.exp(-squared / (2 * HEATMAP_SIGMA_CELLS**2)).astype(np.float32)
        area = heatmap[int(box[8]), r0:r1, c0:c1]
        np.maximum(area, peak, out=area)  # the larger where two people's peaks overlap
        cx, cy, cz, length, width, height, yaw = box[1:8]
        regression[:, r, c] = (
            cx / CELL_M - c,
            (cy - Y_MIN) / CELL_M - r,
            cz,
            math.log(max(length, 1e-3)),
            math.log(max(width, 1e-3)),
            math.log(max(height, 1e-3)),
            math.sin(2 * yaw),
            math.cos(2 * yaw),
        )
        centre[r, c] = True
    ignore &= ~centre  # a visible person's own peak is always trained, even next to a hidden one
    return heatmap, ignore, regression, centre


class WindowDataset(torch.utils.data.Dataset):
    """One sample per detection window of the given buildings."""

    def __init__(self, buildings, train):
        self.buildings = buildings
        self.train = train
        self.index = [(b, w) for b, building in enumerate(buildings) for w in range(len(building.windows))]
        # Most windows show nobody: training draws those with a visible person this many times
        # as often, so that each batch holds people to learn from.
        self.weights = [
            PERSON_WINDOW_WEIGHT if (buildings[b].window_boxes(w)[:, 9] >= VISIBLE_RETURNS).any() else 1.0
            for b, w in self.index
        ]

    def __len__(self):
        return len(self.index)

    def __getitem__(self, i):
        building, window = self.index[i]
        xyz, boxes = self.buildings[building].window(window)
        if self.train:
            # torch gives every worker and epoch its own initial seed; numpy's generator must not
            # repeat the same augmentation in each.
            xyz, boxes = augment(xyz, boxes, np.random.default_rng([torch.initial_seed(), i]))
        features, mask, coords = pillarize(xyz)
        # Only the kept points travel to the model: the padded form is mostly zeros.
        point_features, point_pillar = compact(features, mask)
        heatmap, ignore, regression, centre = make_targets(boxes)
        return point_features, point_pillar, coords, heatmap, ignore, regression, centre, boxes


def collate(samples):
    point_features, point_pillars, coords, heatmaps, ignores, regressions, centres, boxes = zip(*samples)
    # Pillar indices run on across the batch; each pillar's coords gain its sample's index.
    first_pillar = np.cumsum([0] + [len(c) for c in coords[:-1]])
    return {
        "point_features": torch.from_numpy(np.concatenate(point_features)),
        "point_pillar": torch.from_numpy(np.concatenate([p + first for p, first in zip(point_pillars, first_pillar)])),
        "coords": torch.from_numpy(
            np.concatenate([np.column_stack([np.full(len(c), b, np.int64), c]) for b, c in enumerate(coords)])
        ),
        "heatmap": torch.from_numpy(np.stack(heatmaps)),
        "ignore": torch.from_numpy(np.stack(ignores)),
        "regression": torch.from_numpy(np.stack(regressions)),
        "centre": torch.from_numpy(np.stack(centres)),
        "boxes": list(boxes),
        "batch_size": len(samples),
    }


def loader(dataset, batch, shuffle, workers):
    sampler = torch.utils.data.WeightedRandomSampler(dataset.weights, len(dataset)) if shuffle else None
    return torch.utils.data.DataLoader(
        dataset,
        batch_size=batch,
        sampler=sampler,
        num_workers=workers,
        collate_fn=collate,
        persistent_workers=workers > 0 and shuffle,
        drop_last=shuffle,  # a batch of one would break the batch norms' statistics
    )


# ---------------------------------------------------------------------------------------------
# Loss


def losses(head, batch):
    """-> dict of the loss parts: CenterNet focal loss (alpha 2, beta 4) on the heatmap and L1 on
    the regressions at centre cells, both divided by the number of visible people."""
    logits = head[:, : len(CLASSES)]
    target = batch["heatmap"]
    is_peak = target >= 1.0
    score = torch.sigmoid(logits)
    positive = -((1 - score) ** 2) * F.logsigmoid(logits)
    negative = -((1 - target) ** 4) * score**2 * F.logsigmoid(-logits)
    per_cell = torch.where(is_peak, positive, negative) * (~batch["ignore"]).unsqueeze(1)
    centre = batch["centre"]
    people = centre.sum().clamp(min=1).float()

    error = (head[:, len(CLASSES) :] - batch["regression"]).abs() * centre.unsqueeze(1)
    error = error.sum(dim=(0, 2, 3)) / people  # per regression channel
    return {
        "heatmap": per_cell.sum() / people,
        "offset": error[0:2].sum(),
        "z": error[2],
        "size": error[3:6].sum(),
        "yaw": error[6:8].sum(),
    }


# ---------------------------------------------------------------------------------------------
# Decoding and the validation report


def decode(head, min_score):
    """Raw head [B, 12, 48, 48] -> per sample an array [K, 4]: x, y, score, class of each peak (the
    largest score of its 3 x 3 neighbourhood over all classes, at least min_score)."""
    score, cls = torch.sigmoid(head[:, : len(CLASSES)]).max(dim=1)
    is_peak = (score == F.max_pool2d(score, 3, stride=1, padding=1)) & (score >= min_score)
    detections = []
    for b in range(head.shape[0]):
        rows, cols = torch.nonzero(is_peak[b], as_tuple=True)
        x = CELL_M * (cols.float() + head[b, 4, rows, cols])
        y = Y_MIN + CELL_M * (rows.float() + head[b, 5, rows, cols])
        detections.append(torch.stack([x, y, score[b, rows, cols], cls[b, rows, cols].float()], dim=1).numpy())
    return detections


def match(detections_xy, people_xy):
    """One-to-one pairs (detection, person) within MATCH_RADIUS_M, nearest first."""
    if len(detections_xy) == 0 or len(people_xy) == 0:
        return []
    distance = np.linalg.norm(detections_xy[:, None, :] - people_xy[None, :, :], axis=2)
    det, person = np.nonzero(distance < MATCH_RADIUS_M)
    pairs, used_det, used_person = [], set(), set()
    for k in np.argsort(distance[det, person], kind="stable"):
        if det[k] not in used_det and person[k] not in used_person:
            used_det.add(det[k])
            used_person.add(person[k])
            pairs.append((det[k], person[k]))
    return pairs


class Report:
    """Precision and recall over visible people (returns >= 30). A detection left unmatched but
    within the match radius of a barely visible person is not a false positive: the evaluation
    does not demand those people, nor does it punish finding them."""

    def __init__(self):
        self.windows = self.true_positives = self.false_positives = self.false_negatives = 0
        self.on_hidden = self.class_right = 0
        self.people_by_class = np.zeros(len(CLASSES), np.int64)
        self.found_by_class = np.zeros(len(CLASSES), np.int64)

    def add(self, detections, boxes):
        self.windows += 1
        in_head, _, _ = centre_cells(boxes)
        visible = boxes[in_head & (boxes[:, 9] >= VISIBLE_RETURNS)]
        hidden = boxes[in_head & (boxes[:, 9] < VISIBLE_RETURNS)]
        pairs = match(detections[:, :2], visible[:, 1:3])
        matched = {d for d, _ in pairs}
        for d, p in pairs:
            self.found_by_class[int(visible[p, 8])] += 1
            self.class_right += int(detections[d, 3]) == int(visible[p, 8])
        self.people_by_class += np.bincount(visible[:, 8].astype(np.int64), minlength=len(CLASSES))
        self.true_positives += len(pairs)
        self.false_negatives += len(visible) - len(pairs)
        for d in range(len(detections)):
            if d in matched:
                continue
            to_hidden = np.linalg.norm(hidden[:, 1:3] - detections[d, :2], axis=1)
            if len(hidden) and to_hidden.min() < MATCH_RADIUS_M:
                self.on_hidden += 1
            else:
                self.false_positives += 1

    def metrics(self):
        precision = self.true_positives / max(self.true_positives + self.false_positives, 1)
        recall = self.true_positives / max(self.true_positives + self.false_negatives, 1)
        f1 = 2 * precision * recall / max(precision + recall, 1e-12)
        return {"precision": precision, "recall": recall, "f1": f1}

    def summary(self):
        m = self.metrics()
        by_class = ", ".join(
            f"{name} {found / max(people, 1):.3f} ({people})"
            for name, found, people in zip(CLASSES, self.found_by_class, self.people_by_class)
        )
        return (
            f"{self.windows} windows, {self.people_by_class.sum()} visible people: precision "
            f"{m['precision']:.3f} recall {m['recall']:.3f} F1 {m['f1']:.3f} (tp {self.true_positives}, "
            f"fp {self.false_positives}, fn {self.false_negatives}; {self.on_hidden} detections of barely "
            f"visible people not counted)\n  recall by true class: {by_class}\n  class right on "
            f"{self.class_right / max(self.true_positives, 1):.3f} of the matches"
        )


@torch.no_grad()
def evaluate(model, data, min_score):
    model.eval()
    report = Report()
    for sample in data:
        head = model(sample["point_features"], sample["point_pillar"], sample["coords"], sample["batch_size"])
        for detections, boxes in zip(decode(head, min_score), sample["boxes"]):
            report.add(detections, boxes)
    return report


# ---------------------------------------------------------------------------------------------
# train


def learning_rate(peak, progress):
    """Linear warm-up over the first 3 %, then a cosine down to 1 % of the peak. `progress` (0-1)
    is the larger of the epoch and time fractions, so a --minutes run decays too."""
    warmup = 0.03
    if progress < warmup:
        return peak * max(progress / warmup, 0.01)
    cosine = 0.5 * (1 + math.cos(math.pi * min((progress - warmup) / (1 - warmup), 1.0)))
    return peak * (0.01 + 0.99 * cosine)


def save(path, model, epoch, metrics, args):
    torch.save({"model": model.state_dict(), "epoch": epoch, "val": metrics, "args": vars(args)}, path)


def train(args):
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    train_seeds, val_seeds = parse_seeds(args.train_seeds), parse_seeds(args.val_seeds)
    if set(train_seeds) & set(val_seeds):
        raise SystemExit("training and validation seeds overlap")
    train_set = WindowDataset(load_buildings(args.data, train_seeds, allow_test=False), train=True)
    val_set = WindowDataset(load_buildings(args.data, val_seeds, allow_test=False), train=False)
    print(
        f"train: {len(train_set.buildings)} buildings, {len(train_set)} windows; "
        f"val: {len(val_set.buildings)} buildings, {len(val_set)} windows"
    )
    train_data = loader(train_set, args.batch, shuffle=True, workers=args.workers)
    val_data = loader(val_set, args.batch, shuffle=False, workers=args.workers)
    if len(train_data) == 0:
        raise SystemExit(f"fewer training windows ({len(train_set)}) than one batch ({args.batch})")

    model = PillarNet()
    optimizer = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    epochs = args.epochs if args.epochs is not None else (None if args.minutes else 20)
    total_steps = epochs * len(train_data) if epochs else None
    budget_s = args.minutes * 60 if args.minutes else None
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    last_path = out.with_suffix(".last.pt")

    started = time.monotonic()
    step, epoch, best_f1, out_of_time = 0, 0, -1.0, False
    while not out_of_time and (epochs is None or epoch < epochs):
        model.train()
        running, interval_start, interval_samples = {}, time.monotonic(), 0
        for i, batch in enumerate(train_data):
            elapsed = time.monotonic() - started
            if budget_s is not None and elapsed >= budget_s:
                out_of_time = True
                break
            progress = max(step / total_steps if total_steps else 0.0, elapsed / budget_s if budget_s else 0.0)
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(args.lr, progress)
            head = model(batch["point_features"], batch["point_pillar"], batch["coords"], batch["batch_size"])
            parts = losses(head, batch)
            loss = sum(parts.values())
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 10.0)
            optimizer.step()
            step += 1
            interval_samples += batch["batch_size"]
            for name, value in parts.items():
                running[name] = running.get(name, 0.0) + value.item()
            if (i + 1) % args.log_every == 0 or i + 1 == len(train_data):
                rate = interval_samples / (time.monotonic() - interval_start)
                count = (i % args.log_every) + 1
                loss_text = " ".join(f"{name} {value / count:.3f}" for name, value in running.items())
                print(
                    f"epoch {epoch + 1} step {i + 1}/{len(train_data)} lr {optimizer.param_groups[0]['lr']:.2e} "
                    f"{loss_text} | {rate:.1f} samples/s, ETA {eta(step, total_steps, started, budget_s)}",
                    flush=True,
                )
                running, interval_start, interval_samples = {}, time.monotonic(), 0
        epoch += 1
        report = evaluate(model, val_data, args.min_score)
        metrics = report.metrics()
        print(f"epoch {epoch} val: {report.summary()}", flush=True)
        save(last_path, model, epoch, metrics, args)
        if metrics["f1"] > best_f1:
            best_f1 = metrics["f1"]
            save(out, model, epoch, metrics, args)
            print(f"  best so far: saved {out}", flush=True)
    minutes = (time.monotonic() - started) / 60
    print(f"done after {epoch} epochs, {step} steps, {minutes:.1f} min; best val F1 {best_f1:.3f}")


def eta(step, total_steps, started, budget_s):
    elapsed = time.monotonic() - started
    left = []
    if total_steps:
        left.append(elapsed / max(step, 1) * (total_steps - step))
    if budget_s is not None:
        left.append(budget_s - elapsed)
    if not left:
        return "?"
    minutes = max(min(left), 0) / 60
    return f"{minutes:.1f} min"


# ---------------------------------------------------------------------------------------------
# export


def grid_tensor():
    return np.array([X_MIN, X_MAX, Y_MIN, Y_MAX, Z_MIN, Z_MAX, PILLAR_M, MAX_POINTS], np.float32)


class PfnExport(nn.Module):
    """The ONNX form of the pillar feature net: features [P, 32, 8], mask [P, 32, 1] ->
    [P, 32] = max over points of relu(linear(x)) * mask. Multiplying by the mask instead of
    gathering the kept points keeps the graph to MatMul, Add, Relu, Mul and ReduceMax."""

    def __init__(self, folded):
        super().__init__()
        self.pfn = folded.pfn

    def forward(self, features, mask):
        return (F.relu(self.pfn(features)) * mask).amax(dim=1)


class BackboneExport(nn.Module):
    def __init__(self, folded):
        super().__init__()
        self.net = folded

    def forward(self, canvas):
        return self.net.backbone(canvas)


def load_model(ckpt_path):
    checkpoint = torch.load(ckpt_path, map_location="cpu", weights_only=True)
    model = PillarNet()
    model.load_state_dict(checkpoint["model"])
    return model.eval(), checkpoint


def random_window(rng, count=30000):
    """Points spread over the crop with some dense clusters, so that pillars fill up to 32."""
    spread = rng.uniform([X_MIN, Y_MIN, Z_MIN], [X_MAX, Y_MAX, Z_MAX], (count, 3))
    clusters = rng.uniform([1, -8, 0], [18, 8, 1.5], (40, 3))
    dense = clusters[rng.integers(0, len(clusters), count)] + rng.normal(0, 0.15, (count, 3))
    return np.concatenate([spread, dense]).astype(np.float32)


def export(args):
    import onnxruntime

    torch.set_num_threads(args.threads)
    model, checkpoint = load_model(args.ckpt)
    folded = fold(model)
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    folded_state = folded.state_dict()
    tensors = [("grid", grid_tensor())]
    for name in LAYERS:
        for part in ("weight", "bias"):
            tensors.append((f"{name}.{part}", folded_state[f"{name}.{part}"].numpy()))
    stpw_path = out_dir / "pillars.stpw"
    write_stpw(stpw_path, tensors)

    rng = np.random.default_rng(0)
    trace_features, trace_mask, _ = pillarize(random_window(rng, 5000))
    pfn_path, backbone_path = out_dir / "pfn.onnx", out_dir / "backbone.onnx"
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the torch.export one, which needs
        # onnxscript; for two static graphs this small the old one is simpler and exact.
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            PfnExport(folded),
            (torch.from_numpy(trace_features), torch.from_numpy(trace_mask)[:, :, None]),
            str(pfn_path),
            input_names=["features", "mask"],
            output_names=["pillar_features"],
            dynamic_axes={"features": {0: "P"}, "mask": {0: "P"}, "pillar_features": {0: "P"}},
            opset_version=17,
            dynamo=False,
        )
        torch.onnx.export(
            BackboneExport(folded),
            (torch.zeros(1, PFN_CHANNELS, GRID, GRID),),
            str(backbone_path),
            input_names=["canvas"],
            output_names=["head"],
            opset_version=17,
            dynamo=False,
        )

    # Check on a window with another pillar count than the trace's (P is dynamic).
    features, mask, coords = pillarize(random_window(rng))
    point_features, point_pillar = (torch.from_numpy(a) for a in compact(features, mask))
    coords_t = torch.from_numpy(np.column_stack([np.zeros(len(coords), np.int64), coords]))
    with torch.no_grad():
        unfolded_head = model(point_features, point_pillar, coords_t, 1).numpy()
        folded_pillars = folded.pillar_features(point_features, point_pillar, len(coords))
        canvas = scatter(folded_pillars, coords_t, 1)
        folded_head = folded.backbone(canvas).numpy()
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = args.threads
    pfn_session = onnxruntime.InferenceSession(str(pfn_path), options, providers=["CPUExecutionProvider"])
    backbone_session = onnxruntime.InferenceSession(str(backbone_path), options, providers=["CPUExecutionProvider"])
    onnx_pillars = pfn_session.run(None, {"features": features, "mask": mask[:, :, None]})[0]
    onnx_head = backbone_session.run(None, {"canvas": canvas.numpy()})[0]
    stored = read_stpw(stpw_path)

    checks = {
        "fold (eval model vs folded, head)": np.abs(unfolded_head - folded_head).max(),
        "pfn.onnx vs folded torch": np.abs(onnx_pillars - folded_pillars.numpy()).max(),
        "backbone.onnx vs folded torch": np.abs(onnx_head - folded_head).max(),
        "pillars.stpw vs folded weights": max(np.abs(a - b).max() for (_, a), (_, b) in zip(stored, tensors)),
    }
    print(f"exported {args.ckpt} (epoch {checkpoint['epoch']}, val {checkpoint['val']}) to {out_dir}")
    print(f"check window: {len(features)} pillars, head range [{folded_head.min():.2f}, {folded_head.max():.2f}]")
    for what, diff in checks.items():
        print(f"  max abs diff, {what}: {diff:.3g}")
    names_ok = [n for n, _ in stored] == [n for n, _ in tensors]
    if not names_ok or max(checks.values()) > 1e-3:
        raise SystemExit("export check failed")


# ---------------------------------------------------------------------------------------------
# eval


def evaluate_command(args):
    torch.set_num_threads(args.threads)
    model, checkpoint = load_model(args.ckpt)
    dataset = WindowDataset(load_buildings(args.data, parse_seeds(args.seeds), allow_test=True), train=False)
    data = loader(dataset, args.batch, shuffle=False, workers=args.workers)
    report = evaluate(model, data, args.min_score)
    print(f"{args.ckpt} (epoch {checkpoint['epoch']}) on seeds {args.seeds}, min score {args.min_score}:")
    print(f"  {report.summary()}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)

    def common(command):
        command.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")

    def data_options(command):
        command.add_argument("--batch", type=int, default=8)
        command.add_argument("--workers", type=int, default=1, help="data loader processes")
        command.add_argument("--min-score", type=float, default=DEFAULT_MIN_SCORE, help="peak score for a detection")

    train_parser = commands.add_parser("train", help="train a checkpoint")
    train_parser.add_argument("--data", required=True)
    train_parser.add_argument("--train-seeds", default="0-49")
    train_parser.add_argument("--val-seeds", default="50-59")
    train_parser.add_argument("--out", required=True, help="best checkpoint (the last goes to <out>.last.pt)")
    train_parser.add_argument("--minutes", type=float, help="stop after this long (then validate and save)")
    train_parser.add_argument("--epochs", type=int, help="default 20, or unlimited with --minutes")
    train_parser.add_argument("--lr", type=float, default=2e-3)
    train_parser.add_argument("--seed", type=int, default=0)
    train_parser.add_argument("--log-every", type=int, default=50, help="steps between progress lines")
    data_options(train_parser)
    common(train_parser)

    export_parser = commands.add_parser("export", help="fold batch norms; write pillars.stpw, pfn.onnx, backbone.onnx")
    export_parser.add_argument("--ckpt", required=True)
    export_parser.add_argument("--out-dir", required=True)
    common(export_parser)

    eval_parser = commands.add_parser("eval", help="validation report on any seeds (test seeds too)")
    eval_parser.add_argument("--data", required=True)
    eval_parser.add_argument("--seeds", required=True)
    eval_parser.add_argument("--ckpt", required=True)
    data_options(eval_parser)
    common(eval_parser)

    args = parser.parse_args()
    {"train": train, "export": export, "eval": evaluate_command}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
