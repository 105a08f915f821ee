#!/usr/bin/env python3
"""Replay the rig's first-alignment confirmation over `rig_diag` outputs.

`rig_diag` (NEVER_APPLY=1 NO_HINT=1, one file per building) runs every search of a rig session
as a first alignment, one a second. This replays what `RigCore` would have applied from those
searches under a confirmation rule, without running the missions again:

    scripts/rig_diag_confirm.py OUT...                        the default rule (3 searches over 2 s)
    scripts/rig_diag_confirm.py --span 3 --min-searches 3 OUT...
    scripts/rig_diag_confirm.py --refusal-drops OUT...        a refused search drops the candidate
    scripts/rig_diag_confirm.py --rival-weak 4 5 OUT...       a search whose chosen attempt was refused
                                                              only by a rival place counts too, but
                                                              a candidate it joined needs 5 searches
                                                              over 4 s

A candidate is the search's result (the rig's odometry frame placed in the world); a later
search agrees when it places that frame within 0.3 m and 3 deg of it, as
`RigCoreConfig::{confirm_agree_m, confirm_agree_deg}`. The first candidate applied counts as
right when that search was within 10 cm and 1 deg of the truth. Prints the buildings placed
right by 10 s and by 30 s of the rig's run, and those placed wrong.
"""
import argparse
import math
import re
import sys

from rig_diag_summary import ATTEMPT, SEARCH, kind

FIT = re.compile(r'rms ([\d.]+|inf) inl ([\d.]+)')
SUMMARY = re.compile(
    r'SUMMARY t\s+([\d.]+) acc (true|false) err\s+([\d.]+) m\s+([\d.]+) deg world_t_odom\s+([-+\d.]+)\s+([-+\d.]+)\s+([-+\d.]+)'
)
# What a rival place refuses an attempt with (`Rejection::PartlyMappedRival`, `ElsewhereAsGood`).
RIVAL_REASONS = ('a place ', 'another place ')
AGREE_M, AGREE_DEG = 0.3, 3.0


def chosen(attempts):
    """The attempt `Registration` reports: accepted first, then the highest inlier ratio, then
    the lowest residual (the first of equals)."""
    best = None
    for a in attempts:
        if best is None or (a[0], a[1], -a[2]) > (best[0], best[1], -best[2]):
            best = a
    return best


def read(path):
    """One tuple per search: (t, 'accepted' | 'rival' | None, right, x, y, yaw_deg)."""
    searches, attempts = [], []
    with open(path) as f:
        for line in f:
            if SEARCH.match(line):
                attempts = []
                continue
            attempt = ATTEMPT.match(line)
            if attempt:
                fit = FIT.search(line)
                why = line.split('acc false', 1)[1] if 'acc false' in line else ''
                reasons = [r.strip() for r in why.split(';') if r.strip()]
                rival_only = bool(reasons) and all(r.startswith(RIVAL_REASONS) for r in reasons)
                attempts.append(('acc true' in line, float(fit[2]), float(fit[1]), rival_only))
                continue
            s = SUMMARY.search(line)
            if s:
                best = chosen(attempts)
                rival = best is not None and best[3]
                outcome = 'accepted' if s[2] == 'true' else ('rival' if rival else None)
                right = kind(float(s[3]), float(s[4])) == 'right'
                searches.append((float(s[1]), outcome, right, float(s[5]), float(s[6]), float(s[7])))
    return searches


def agree(a, b):
    turn = abs((a[5] - b[5] + 180.0) % 360.0 - 180.0)
    return math.hypot(a[3] - b[3], a[4] - b[4]) <= AGREE_M and turn <= AGREE_DEG


def replay(searches, span_s, min_searches, refusal_drops, weak):
    """(t, right) of the first candidate applied, or None."""
    cand = None  # (first t, last search, searches, rival-refused searches among them)
    for s in searches:
        t, outcome = s[0], s[1]
        if outcome is None or (outcome == 'rival' and weak is None):
            if refusal_drops:
                cand = None
            continue
        rival = 1 if outcome == 'rival' else 0
        cand = (cand[0], s, cand[2] + 1, cand[3] + rival) if cand and agree(cand[1], s) else (t, s, 1, rival)
        need_span, need_n = (span_s, min_searches) if cand[3] == 0 else weak
        if t - cand[0] >= need_span and cand[2] >= need_n:
            return t, s[2]
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--span', type=float, default=2.0, help='seconds the agreeing searches span (default 2)')
    ap.add_argument('--min-searches', type=int, default=3, help='agreeing searches at least (default 3)')
    ap.add_argument('--refusal-drops', action='store_true', help='a refused search drops the candidate')
    ap.add_argument('--rival-weak', nargs=2, type=float, metavar=('SPAN', 'N'))
    ap.add_argument('outputs', nargs='+')
    args = ap.parse_args()
    weak = (args.rival_weak[0], int(args.rival_weak[1])) if args.rival_weak else None
    by10, by30, wrong = [], [], []
    for path in args.outputs:
        name = path.rsplit('/', 1)[-1].removesuffix('.txt')
        applied = replay(read(path), args.span, args.min_searches, args.refusal_drops, weak)
        if applied is None:
            continue
        t, right = applied
        if not right:
            wrong.append(f'{name} at {t:.0f} s')
        elif t <= 10.0:
            by10.append(f'{name} at {t:.0f} s')
        if right and t <= 30.0:
            by30.append(name)
    print(f'{len(args.outputs)} buildings: right by 10 s {len(by10)}, by 30 s {len(by30)}, wrong {len(wrong)}')
    print('  right by 10 s:', ', '.join(sorted(by10)) or '-')
    print('  wrong:', ', '.join(sorted(wrong)) or '-')


if __name__ == '__main__':
    sys.exit(main())
