"""Per-step cost of a model written in Python against the same catalogue model.

A single `edccif.CKF` on the paper's model (coordinated turn, range/pitch/azimuth,
n = 7, m = 3) runs `predict(); update(z)` over a 200-step seeded sequence with:

1. the catalogue models (`models.CoordinatedTurn`, `models.RangePitchAzimuth`);
2. `models.CustomMotion` / `models.CustomMeasurement` whose callables are the same
   equations written in vectorised NumPy (what a user would write);
3. custom models whose callables call the catalogue's batch evaluators
   (`ct.f`, `rpa.h`): the bare cost of the callback path;
4. for reference, FilterPy's `CubatureKalmanFilter` with per-point Python f/h
   (skipped when FilterPy is not installed).

Prints the median per-step time and its spread (interquartile range, min-max) over
the repetitions, and the overhead of 2 and 3 against 1.

Usage: python3 benchmarks/custom_model_overhead.py [--reps 21]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import edccif
from edccif import models


def ct_numpy(X, dt):
    w = X[:, 6]
    wdt = w * dt
    s, c = np.sin(wdt), np.cos(wdt)
    small = np.abs(w) < 1e-9
    ws = np.where(small, 1.0, w)
    sf = np.where(small, dt, s / ws)
    cf = np.where(small, w * dt * dt / 2, (1 - c) / ws)
    vx, vy = X[:, 3], X[:, 4]
    out = X.copy()
    out[:, 0] += sf * vx - cf * vy
    out[:, 1] += cf * vx + sf * vy
    out[:, 2] += dt * X[:, 5]
    out[:, 3] = c * vx - s * vy
    out[:, 4] = s * vx + c * vy
    return out


def rpa_numpy(sensor):
    def h(X):
        d = X[:, :3] - sensor
        rho = np.hypot(d[:, 0], d[:, 1])
        return np.column_stack([np.sqrt(rho**2 + d[:, 2] ** 2), np.arctan2(d[:, 2], rho), np.arctan2(d[:, 1], d[:, 0])])

    return h


def per_step(make, z, reps):
    """Median, quartiles, min, max of the per-step time (s) over `reps` runs."""
    times = []
    for _ in range(reps):
        f = make()
        t0 = time.perf_counter()
        for zk in z:
            f.predict()
            f.update(zk)
        times.append((time.perf_counter() - t0) / len(z))
    q = statistics.quantiles(times, n=4)
    return statistics.median(times), q[0], q[2], min(times), max(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=21)
    args = ap.parse_args()
    sc = edccif.Scenario.paper(nodes=4)
    _, zz, x0 = sc.simulate(seed=0)
    z = zz[:, 0]
    mo, me = sc.motion, sc.measurement
    sensor = sc.sensors[0]
    ct = models.CoordinatedTurn(mo["q1"], mo["q2"])
    rpa = models.RangePitchAzimuth(sensor, me["sigma_r"], me["sigma_a"])
    numpy_ct = models.CustomMotion(ct_numpy, ct.Q, n=7)
    numpy_rpa = models.CustomMeasurement(rpa_numpy(sensor), rpa.R, m=3, n=7, angles=[1, 2])
    via_ct = models.CustomMotion(ct.f, ct.Q, n=7)
    via_rpa = models.CustomMeasurement(rpa.h, rpa.R, m=3, n=7, angles=[1, 2])
    p0, dt = sc.p0, sc.dt
    cases = [
        ("catalogue models", lambda: edccif.CKF(ct, rpa, x0, p0, dt=dt)),
        ("custom, NumPy callables", lambda: edccif.CKF(numpy_ct, numpy_rpa, x0, p0, dt=dt)),
        ("custom, callables = catalogue .f/.h", lambda: edccif.CKF(via_ct, via_rpa, x0, p0, dt=dt)),
    ]
    try:
        from filterpy.kalman import CubatureKalmanFilter

        def make_fp():
            f = CubatureKalmanFilter(
                7, 3, dt, hx=lambda x: rpa_numpy(sensor)(x[None])[0], fx=lambda x, dt: ct_numpy(x[None], dt)[0]
            )
            f.x, f.P, f.Q, f.R = x0.copy(), p0.copy(), ct.Q(dt), rpa.R
            return f

        zc = z.reshape(len(z), 3, 1)
        cases.append(("FilterPy CKF, per-point NumPy f/h", (make_fp, zc)))
    except ImportError:
        pass
    print(f"single CKF, paper model (n=7, m=3), {len(z)} steps, {args.reps} repetitions; per step predict()+update(z):")
    print(f"  {'case':38s} {'median':>10s} {'IQR':>21s} {'min-max':>21s}")
    base = None
    for name, make in cases:
        zs = z
        if isinstance(make, tuple):
            make, zs = make
        med, q1, q3, lo, hi = per_step(make, zs, args.reps)
        base = base or med
        extra = "" if med == base else f"   +{1e6 * (med - base):7.1f} us ({med / base:5.1f}x)"
        print(
            f"  {name:38s} {1e6 * med:8.1f} us  [{1e6 * q1:7.1f}, {1e6 * q3:7.1f}] us"
            f"  [{1e6 * lo:7.1f}, {1e6 * hi:7.1f}] us{extra}"
        )


if __name__ == "__main__":
    main()
