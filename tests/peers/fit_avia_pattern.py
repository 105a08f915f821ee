#!/usr/bin/env python3
"""Fits the simulator's Risley-prism model of the Avia scan pattern to a real Avia frame.

Usage: python3 tests/peers/fit_avia_pattern.py [../shared/data/livox/avia_frame.pcd]
Needs numpy and scipy (not part of CI: the fitted constants live in hil/src/sim/pattern.rs and
hil/tests/avia_pattern.rs checks them against the same frame).

The frame holds 24,000 firings in firing order (point i fired at i * 4167 ns, line i % 6), with
zeros where nothing returned. Each real return gives the beam direction at a known time. The model:
    w(t)  = a e^{i(2 pi f1 t + p1)} + (1 - a) e^{i(2 pi f2 t + p2)}       (two prisms)
    az    = cx + Ax Re(w) (1 + k |w|^2) + du[line]
    el    = cy + Ay Im(w) (1 + k |w|^2) + dv[line]
A grid over the prism rates finds the basin; least squares (soft L1) refines everything.
"""
import sys
import numpy as np
from scipy.optimize import least_squares

path = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/livox/avia_frame.pcd"
raw = open(path, "rb").read()
start = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
rec = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<f4"), ("tag", "u1"), ("line", "u1")])
a = np.frombuffer(raw[start:start + 24000 * rec.itemsize], dtype=rec)
x, y, z = (a[k].astype(float) for k in "xyz")
keep = (x != 0) | (y != 0) | (z != 0)
t = (np.arange(len(a)) * 4167e-9)[keep]
line = (np.arange(len(a)) % 6)[keep]
az = np.degrees(np.arctan2(y, x))[keep]
el = np.degrees(np.arctan2(z, np.hypot(x, y)))[keep]


def model(q, t, line):
    f1, f2, p1, p2, ax, ay, cx, cy, wa, k = q[:10]
    offs = np.vstack([[0, 0], q[10:].reshape(5, 2)])
    w = wa * np.exp(1j * (2 * np.pi * f1 * t + p1)) + (1 - wa) * np.exp(1j * (2 * np.pi * f2 * t + p2))
    s = 1 + k * np.abs(w) ** 2
    return cx + ax * w.real * s + offs[line, 0], cy + ay * w.imag * s + offs[line, 1]


def residual(q):
    m_az, m_el = model(q, t, line)
    return np.concatenate([m_az - az, m_el - el])


rng = np.random.default_rng(0)
best = None
for f1 in np.arange(40, 200, 6):
    for ratio in (-0.3, -0.4, -0.5, -0.6, -0.7, -0.8, -0.9, -1.1, -1.3, -1.5):
        q0 = np.array([f1, f1 * ratio, *rng.uniform(0, 6.28, 2), 35, 38, 0, 0, 0.5, 0.0] + [0] * 10)
        r = least_squares(residual, q0, max_nfev=200)
        cost = np.sqrt(np.mean(r.fun ** 2))
        if best is None or cost < best[0]:
            best = (cost, r.x)
r = least_squares(residual, best[1], loss="soft_l1", f_scale=0.5)
err = np.hypot(*(m - d for m, d in zip(model(r.x, t, line), (az, el))))
names = "f1_hz f2_hz p1_rad p2_rad amp_az_deg amp_el_deg centre_az_deg centre_el_deg weight rim_stretch".split()
for n, v in zip(names, r.x[:10]):
    print(f"{n:15} {v: .4f}")
print("line offsets (az, el) deg:", np.round(r.x[10:].reshape(5, 2), 4).tolist())
print(f"{len(t)} returns: angular error median {np.median(err):.2f} deg, p90 {np.percentile(err, 90):.2f} deg")
