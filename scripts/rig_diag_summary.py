#!/usr/bin/env python3
"""Summarise `rig_diag` outputs (one file per building, NEVER_APPLY=1 NO_HINT=1).

    scripts/rig_diag_summary.py OUT...                  per building: searches, the attempt from
                                                        the truth right, searches right / wrong
    scripts/rig_diag_summary.py --timeline OUT...       per building, one character a search:
                                                        the attempt from the truth right (T) or
                                                        not (.), and the search right (R), wrong
                                                        (W) or refused (.)
    scripts/rig_diag_summary.py --settle N OUT...       where the attempt from the truth settles in each
                                                        building's first N searches, one character a
                                                        search: accepted right (A), right but refused
                                                        (s), near (n), far (x); then per family (the
                                                        name before the dash) the counts, and the
                                                        buildings where most settle near
    scripts/rig_diag_summary.py --rivals K M OUT...     replay the rival rule on the rivals each
                                                        accepted attempt recorded (run rig_diag with
                                                        correlative_rival_min_known = 1 to record
                                                        them without refusing): a search is refused
                                                        when a rival has at least K of the window on
                                                        known cells and fits within M of the result

A search is right within 10 cm and 1 deg of the truth, near within 0.5 m and 3 deg, far beyond.
"""
import argparse
import collections
import re
import sys

SEARCH = re.compile(r'== t\s+([\d.]+) s')
ATTEMPT = re.compile(r'\s+att\d+ .*err\s+([\d.]+) m\s+([\d.]+) deg')
HERE = re.compile(r'\s+known here: share ([\d.]+) score ([-\d.]+)')
RIVAL = re.compile(r'\s+rival\s+([\d.]+) m\s+([\d.]+) deg .*known ([\d.]+) on known ([-\d.]+)')
TRUTH = re.compile(r'\s+from truth: settles ([\d.]+) m ([\d.]+) deg .*\| acc (true|false)')
SETTLE_CHAR = {'right': 's', 'near': 'n', 'far': 'x'}
SUMMARY = re.compile(r'\s+SUMMARY t\s+[\d.]+ acc (true|false) err\s+([\d.]+) m\s+([\d.]+) deg')


def kind(m, deg):
    if m < 0.1 and deg < 1.0:
        return 'right'
    return 'near' if m < 0.5 and deg < 3.0 else 'far'


def read(path):
    """Per search: the truth attempt right?, the search's outcome, and the judged attempts."""
    searches, judged, cur = [], [], None
    for line in open(path):
        if (m := SEARCH.match(line)):
            searches.append({'t': float(m[1]), 'truth_right': False, 'outcome': None})
        elif (m := ATTEMPT.match(line)):
            cur = {'kind': kind(float(m[1]), float(m[2])), 'here': None, 'rivals': []}
        elif (m := HERE.match(line)) and cur is not None:
            cur['here'] = float(m[2])
            judged.append(cur)
        elif (m := RIVAL.match(line)) and cur is not None and cur['here'] is not None:
            cur['rivals'].append((float(m[3]), float(m[4])))
        elif (m := TRUTH.match(line)) and searches:
            settled = kind(float(m[1]), float(m[2]))
            searches[-1]['truth_right'] = m[3] == 'true' and settled == 'right'
            searches[-1]['truth_settle'] = 'A' if searches[-1]['truth_right'] else SETTLE_CHAR[settled]
            searches[-1]['truth_accepted'] = m[3] == 'true'
        elif (m := SUMMARY.match(line)) and searches and m[1] == 'true':
            searches[-1]['outcome'] = kind(float(m[2]), float(m[3]))
    return searches, judged


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--rivals', nargs=2, type=float, metavar=('K', 'M'))
    ap.add_argument('--timeline', action='store_true')
    ap.add_argument('--settle', type=int, metavar='N')
    ap.add_argument('--within', type=float, metavar='S')
    ap.add_argument('outputs', nargs='+')
    a = ap.parse_args()
    if a.settle:
        return settle(a.settle, a.outputs)
    if a.within:
        return within(a.within, a.outputs)
    total = collections.Counter()
    for path in a.outputs:
        searches, judged = read(path)
        if a.timeline:
            truth = ''.join('T' if s['truth_right'] else '.' for s in searches)
            found = ''.join({'right': 'R', None: '.'}.get(s['outcome'], 'W') for s in searches)
            print(f'{path}\n  truth  {truth}\n  search {found}')
            continue
        c = collections.Counter(searches=len(searches), truth_right=sum(s['truth_right'] for s in searches))
        if a.rivals:
            k, margin = a.rivals
            for j in judged:
                refused = any(known >= k and fit >= j['here'] - margin for known, fit in j['rivals'])
                c[j['kind'] + (' refused' if refused else ' kept')] += 1
        else:
            c.update(s['outcome'] for s in searches if s['outcome'])
        total.update(c)
        print(path, dict(c))
    if not a.timeline:
        print('all', dict(total))


def settle(first, outputs):
    """Where the attempt from the truth settles in each building's first searches, by family."""
    families = collections.defaultdict(collections.Counter)
    for path in outputs:
        searches, _ = read(path)
        row = ''.join(s.get('truth_settle', '-') for s in searches[:first])
        name = path.rsplit('/', 1)[-1].rsplit('.', 1)[0]
        print(f'{name:16s} {row}')
        family = families[name.split('-')[0]]
        family.update(row)
        family['buildings'] += 1
        family['mostly near'] += row.count('n') > len(row) / 2
    for name, c in sorted(families.items()):
        print(f"{name:10s} buildings {c['buildings']:2d}: A {c['A']:3d} s {c['s']:3d} n {c['n']:3d} x {c['x']:3d}"
              f"  buildings mostly near {c['mostly near']}")


def within(seconds, outputs):
    """The attempt from the truth and the search, over each rig's searches up to `seconds`."""
    families = collections.defaultdict(collections.Counter)
    for path in outputs:
        searches, _ = read(path)
        name = path.rsplit('/', 1)[-1].rsplit('.', 1)[0]
        family = families[name.split('-')[0]]
        for s in (s for s in searches if s['t'] <= seconds and 'truth_settle' in s):
            ends = s['truth_settle']
            family['N' if ends in 'nx' and s['truth_accepted'] else ends] += 1
            family[{None: 'refused', 'right': 'search right'}.get(s['outcome'], 'search wrong')] += 1
    total = collections.Counter()
    print(f'searches in the first {seconds:g} s; the attempt from the truth: accepted right A, right but refused s, '
          'accepted off N, near refused n, far refused x')
    for name, c in sorted(families.items()) + [('all', total)]:
        if name != 'all':
            total.update(c)
        truth = '  '.join(f'{k} {c[k]:3d}' for k in 'AsNnx')
        print(f"{name:10s} {truth}  | search right {c['search right']:3d} wrong {c['search wrong']:3d}"
              f" refused {c['refused']:3d}")


if __name__ == '__main__':
    sys.exit(main())
