#!/usr/bin/env python3
"""Time one CKF predict + update step on the default model against peer libraries.

The model is the project's default (ALGORITHM.md §1, §6): a 7-state coordinated
turn (dt 0.1, q1 0.5, q2 1e-4) observed by one range/pitch/azimuth sensor at
(10, 0, 0) with sigma_r 0.1 m, sigma_a 0.01 rad. Every implementation filters the
same seeded 200-step measurement sequence from the same initial estimate;
repetitions are interleaved across implementations (round r times every peer
once, in a rotated order, then the Rust binary) and the medians are reported,
in microseconds per predict + update step on two clocks (the thread's CPU time
and wall time) and as a ratio to edccif's Rust CKF step (CPU time).

Implementations:

- ``edccif-rust``: ``edccif-timing --ckf-step --json`` (``cov_local`` with the
  CKF and no trigger), plus the 1-node C-CKF network step through
  ``AnyNetwork::step`` (the Rust side of the Python binding path).
- ``edccif-python``: ``edccif.Network(edccif.Scenario.paper(nodes=1),
  algorithm="c-ckf", x0=...)`` stepped with ``.step(z)``; skipped with a message
  when ``import edccif`` fails (build it with ``maturin develop --release``).
- ``filterpy``: ``filterpy.kalman.CubatureKalmanFilter``.
- ``stonesoup``: ``CubatureKalmanPredictor`` / ``CubatureKalmanUpdater`` when the
  installed version has them, else the unscented ones (the output says which).
- ``turbo-ckf``: ``turbo_ckf.TurboCKF`` with vectorised callbacks.

The script installs the optional peers with pip (``--no-install`` to skip) and
carries on without any peer that cannot be installed or imported.

Usage::

    python3 benchmarks/peers.py [--rounds 15] [--no-install] [--json OUT.json] [--timing-bin PATH]
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parent.parent
PEER_PACKAGES = {"filterpy": "filterpy", "stonesoup": "stonesoup", "turbo_ckf": "turbo-ckf"}

DT, Q1, Q2 = 0.1, 0.5, 1e-4
SIGMA_R, SIGMA_A = 0.1, 0.01
SENSOR = (10.0, 0.0, 0.0)
X0 = [5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]
P0_DIAG = [0.01] * 6 + [1e-4]
STEPS = 200
SEED = 2024


def pip_install(names: list[str]) -> dict[str, str]:
    """Install each missing package; returns {package: error} for failures."""
    failures = {}
    for module, dist in PEER_PACKAGES.items():
        if dist not in names:
            continue
        try:
            importlib.import_module(module)
            continue
        except Exception:
            pass
        r = subprocess.run(
            [sys.executable, "-m", "pip", "install", "--quiet", dist],
            capture_output=True,
            text=True,
        )
        if r.returncode != 0:
            failures[dist] = (r.stderr.strip().splitlines() or ["pip failed"])[-1]
    importlib.invalidate_caches()
    return failures


# --------------------------------------------------------------------------- model

def transition(x, dt=DT):
    """Coordinated turn (ALGORITHM.md §1) for a state (7,) or a batch (k, 7)."""
    import numpy as np

    x = np.asarray(x, dtype=float)
    px, py, pz, vx, vy, vz, w = (x[..., i] for i in range(7))
    wdt = w * dt
    small = np.abs(w) < 1e-9
    ws = np.where(small, 1.0, w)
    s = np.where(small, dt, np.sin(wdt) / ws)
    c = np.where(small, w * dt * dt / 2.0, (1.0 - np.cos(wdt)) / ws)
    cw, sw = np.cos(wdt), np.sin(wdt)
    return np.stack(
        [px + s * vx - c * vy, py + c * vx + s * vy, pz + dt * vz,
         cw * vx - sw * vy, sw * vx + cw * vy, vz, w],
        axis=-1,
    )


def process_noise(dt=DT):
    import numpy as np

    q = np.zeros((7, 7))
    blk = Q1 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    for a in range(3):
        idx = [a, a + 3]
        q[np.ix_(idx, idx)] = blk
    q[6, 6] = Q2 * dt
    return q


def measure(x):
    """[range, pitch, azimuth] of a state (7,) or a batch (k, 7)."""
    import numpy as np

    x = np.asarray(x, dtype=float)
    dx, dy, dz = x[..., 0] - SENSOR[0], x[..., 1] - SENSOR[1], x[..., 2] - SENSOR[2]
    h = np.hypot(dx, dy)
    return np.stack([np.sqrt(h * h + dz * dz), np.arctan2(dz, h), np.arctan2(dy, dx)], axis=-1)


def wrap(a):
    import numpy as np

    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


def measure_near(x, z):
    """``measure`` with the angles unwrapped next to measurement ``z``: lets a
    filter without circular means or wrapped residuals (FilterPy's CKF mean,
    turbo-ckf) handle the azimuth crossing ±π."""
    m = measure(x)
    m[..., 1:] = z[1:] + wrap(m[..., 1:] - z[1:])
    return m


def simulate(seed=SEED, steps=STEPS):
    """Seeded truth and measurements of ALGORITHM.md §6 for one sensor."""
    import numpy as np

    rng = np.random.default_rng(seed)
    lq = np.linalg.cholesky(process_noise())
    r_sd = np.array([SIGMA_R, SIGMA_A, SIGMA_A])
    x = np.array(X0)
    x0_hat = x + np.sqrt(P0_DIAG) * rng.standard_normal(7)
    zs = np.empty((steps, 3))
    truth = np.empty((steps, 7))
    for k in range(steps):
        x = transition(x) + lq @ rng.standard_normal(7)
        z = measure(x) + r_sd * rng.standard_normal(3)
        z[1:] = wrap(z[1:])
        zs[k] = z
        truth[k] = x
    return zs, x0_hat, truth


# --------------------------------------------------------------------------- peers
# Each factory returns (label, run_pass) where run_pass() filters the whole
# sequence once from the initial estimate and returns the final state estimate
# (checked against the truth, outside the timing, so that no peer is timed on a
# diverged run).

def make_filterpy(zs, x0):
    import numpy as np
    from filterpy.kalman import CubatureKalmanFilter

    def fx(x, dt):
        return transition(x, dt)

    def hx(x, z):
        return measure_near(x, z)

    def residual_z(z, zp):
        # FilterPy's CKF keeps x and zp as columns: answer in zp's shape.
        d = np.asarray(z, dtype=float).ravel() - np.asarray(zp, dtype=float).ravel()
        d[1:] = wrap(d[1:])
        return d.reshape(np.shape(zp))

    def run_pass():
        kf = CubatureKalmanFilter(dim_x=7, dim_z=3, dt=DT, hx=hx, fx=fx, residual_z=residual_z)
        kf.x = x0.copy()
        kf.P = np.diag(P0_DIAG)
        kf.Q = process_noise()
        kf.R = np.diag([SIGMA_R**2, SIGMA_A**2, SIGMA_A**2])
        for z in zs:
            kf.predict()
            kf.update(z, hx_args=(z,))
        return np.asarray(kf.x).ravel()

    import filterpy

    return f"filterpy {filterpy.__version__} CubatureKalmanFilter", run_pass


def make_stonesoup(zs, x0):
    import datetime

    import numpy as np
    import stonesoup
    from stonesoup.base import Property
    from stonesoup.models.base import TimeVariantModel
    from stonesoup.models.measurement.nonlinear import CartesianToElevationBearingRange
    from stonesoup.models.transition.nonlinear import GaussianTransitionModel
    from stonesoup.predictor import kalman as pk
    from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater import kalman as uk

    class CoordinatedTurn7(GaussianTransitionModel, TimeVariantModel):
        """ALGORITHM.md §1 coordinated turn, state [px, py, pz, vx, vy, vz, w]."""

        q1: float = Property(doc="position/velocity noise intensity")
        q2: float = Property(doc="turn-rate noise intensity")

        @property
        def ndim_state(self):
            return 7

        def function(self, state, noise=False, **kwargs):
            dt = kwargs["time_interval"].total_seconds()
            sv = np.asarray(state.state_vector, dtype=float)
            out = transition(sv.T, dt).T
            return StateVectors(out) if out.shape[1] > 1 else StateVector(out)

        def covar(self, time_interval=None, **kwargs):
            return CovarianceMatrix(process_noise(time_interval.total_seconds()))

    class ElevationBearingRangeNear(CartesianToElevationBearingRange):
        """Stone Soup's elevation/bearing/range model with its angles returned as
        plain numbers unwrapped next to ``ref`` (the current measurement): the
        cubature updater of Stone Soup 1.9 averages the points' bearings
        linearly, so the stock model diverges once the azimuth crosses ±π (it
        does near step 55 of this sequence)."""

        ref: StateVector = Property(default=None, doc="reference measurement")

        def function(self, state, noise=False, **kwargs):
            out = np.array(super().function(state, noise, **kwargs), dtype=float)
            if self.ref is not None:
                ref = np.asarray(self.ref, dtype=float).reshape(3, 1)
                out[:2] = ref[:2] + wrap(out[:2] - ref[:2])
            return StateVectors(out) if out.shape[1] > 1 else StateVector(out)

    cubature = hasattr(pk, "CubatureKalmanPredictor") and hasattr(uk, "CubatureKalmanUpdater")
    tm = CoordinatedTurn7(q1=Q1, q2=Q2)
    mm = ElevationBearingRangeNear(
        ndim_state=7, mapping=(0, 1, 2),
        noise_covar=CovarianceMatrix(np.diag([SIGMA_A**2, SIGMA_A**2, SIGMA_R**2])),
        translation_offset=StateVector(list(SENSOR)),
    )
    if cubature:
        predictor, updater = pk.CubatureKalmanPredictor(tm), uk.CubatureKalmanUpdater(mm)
        kind = "CubatureKalmanPredictor/Updater"
    else:
        predictor, updater = pk.UnscentedKalmanPredictor(tm), uk.UnscentedKalmanUpdater(mm)
        kind = "UnscentedKalmanPredictor/Updater (no cubature classes in this version)"
    t0 = datetime.datetime(2024, 1, 1)
    step = datetime.timedelta(seconds=DT)
    # Stone Soup orders the measurement [elevation, bearing, range].
    dets = [zs[k][[1, 2, 0]] for k in range(len(zs))]

    def run_pass():
        state = GaussianState(StateVector(x0), CovarianceMatrix(np.diag(P0_DIAG)), timestamp=t0)
        for k, z in enumerate(dets):
            t = t0 + (k + 1) * step
            pred = predictor.predict(state, timestamp=t)
            mm.ref = z
            det = Detection(StateVector(z), timestamp=t, measurement_model=mm)
            state = updater.update(SingleHypothesis(pred, det))
        return np.asarray(state.state_vector, dtype=float).ravel()

    return f"stonesoup {stonesoup.__version__} {kind}", run_pass


def make_turbo(zs, x0):
    import numpy as np
    import turbo_ckf

    def fx(points, dt):
        return transition(points, dt)

    def hx(points, z):
        return measure_near(points, z)

    def run_pass():
        kf = turbo_ckf.TurboCKF(dim_x=7, dim_z=3, dt=DT, hx=hx, fx=fx)
        kf.x = x0.copy()
        kf.P = np.diag(P0_DIAG)
        kf.Q = process_noise()
        kf.R = np.diag([SIGMA_R**2, SIGMA_A**2, SIGMA_A**2])
        for z in zs:
            kf.predict()
            kf.update(z, hx_args=(z,))
        return np.asarray(kf.x).ravel()

    version = getattr(turbo_ckf, "__version__", None)
    if version is None:
        from importlib.metadata import version as v

        version = v("turbo-ckf")
    return f"turbo-ckf {version} TurboCKF", run_pass


def make_edccif_python(zs, x0):
    import numpy as np

    import edccif

    sc = edccif.Scenario.paper(nodes=1)

    def run_pass():
        net = edccif.Network(sc, algorithm="c-ckf", x0=np.asarray(x0))
        est = None
        for z in zs:
            est = net.step(z.reshape(1, 3))
        return np.asarray(est, dtype=float).ravel()[:7]

    return "edccif (Python binding) Network c-ckf, 1 node", run_pass


# --------------------------------------------------------------------------- rust

def timing_binary(given: Path | None) -> Path | None:
    """Builds the timing binary with cargo and returns its path (or ``given``)."""
    if given is not None:
        return given if given.exists() else None
    cargo = shutil.which("cargo")
    if cargo is None:
        return None
    r = subprocess.run(
        [cargo, "build", "--release", "-q", "-p", "edccif-bench", "--bin", "edccif-timing"],
        cwd=ROOT, capture_output=True, text=True,
    )
    if r.returncode != 0:
        print(f"[edccif-rust] cargo build failed:\n{r.stderr[-2000:]}", file=sys.stderr)
        return None
    meta = subprocess.run(
        [cargo, "metadata", "--format-version", "1", "--no-deps"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )
    target = Path(json.loads(meta.stdout)["target_directory"])
    exe = target / "release" / ("edccif-timing.exe" if os.name == "nt" else "edccif-timing")
    return exe if exe.exists() else None


def rust_round(exe: Path) -> dict[str, float]:
    out = subprocess.run(
        [str(exe), "--ckf-step", "--json", "--reps", "3"],
        capture_output=True, text=True, check=True,
    )
    return json.loads(out.stdout)


# --------------------------------------------------------------------------- main

def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=15, help="interleaved rounds (default 15)")
    ap.add_argument("--no-install", action="store_true", help="do not pip-install missing peers")
    ap.add_argument("--json", type=Path, help="also write the results to this JSON file")
    ap.add_argument("--timing-bin", type=Path,
                    help="a prebuilt edccif-timing binary (default: cargo build it)")
    args = ap.parse_args()

    try:
        import numpy as np
    except ImportError:
        subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "numpy"], check=True)
        import numpy as np

    notes: list[str] = []
    if not args.no_install:
        for dist, err in pip_install(list(PEER_PACKAGES.values())).items():
            notes.append(f"{dist}: pip could not install it ({err}); skipped")

    zs, x0, truth = simulate()
    peers: dict[str, tuple[str, Callable[[], object]]] = {}
    final_error: dict[str, float] = {}
    factories = [
        ("filterpy", make_filterpy),
        ("stonesoup", make_stonesoup),
        ("turbo-ckf", make_turbo),
        ("edccif-python", make_edccif_python),
    ]
    for key, factory in factories:
        try:
            label, run_pass = factory(zs, x0)
            x_end = run_pass()  # warm-up, and proof that it runs
            err = float(np.linalg.norm(x_end[:3] - truth[-1, :3]))
            if not err < 1.0:
                raise RuntimeError(f"final position error {err:.3g} m: the filter diverged")
            final_error[key] = err
            peers[key] = (label, run_pass)
        except ImportError as e:
            if key == "edccif-python":
                notes.append(
                    f"edccif-python: `import edccif` failed ({e}); skipped. Build the binding with "
                    "`maturin develop --release` (or `pip install .`) to include it"
                )
            else:
                notes.append(f"{key}: import failed ({e}); skipped")
        except Exception as e:  # a peer that cannot run the model is reported, not fatal
            notes.append(f"{key}: failed on the default model ({type(e).__name__}: {e}); skipped")

    exe = timing_binary(args.timing_bin)
    if exe is None:
        notes.append("edccif-rust: the timing binary could not be built; ratios are not available")

    # Two clocks per sample: wall (perf_counter) and this thread's CPU time
    # (thread_time), which is not inflated when the OS deschedules the process
    # on a loaded machine. Ratios use the CPU clock.
    wall: dict[str, list[float]] = {k: [] for k in peers}
    cpu: dict[str, list[float]] = {k: [] for k in peers}
    rust_keys = {"edccif-rust": "ckf_step", "edccif-rust-network1": "network_1node_c_ckf_step"}
    if exe is not None:
        for k in rust_keys:
            wall[k], cpu[k] = [], []
    keys = list(peers)
    for r in range(args.rounds):
        order = keys[r % len(keys):] + keys[: r % len(keys)] if keys else []
        for k in order:
            c0, t0 = time.thread_time(), time.perf_counter()
            peers[k][1]()
            t1, c1 = time.perf_counter(), time.thread_time()
            n = len(zs)
            wall[k].append((t1 - t0) / n * 1e6)
            cpu[k].append((c1 - c0) / n * 1e6)
        if exe is not None:
            j = rust_round(exe)
            for k, field in rust_keys.items():
                wall[k].append(j[f"{field}_us"])
                cpu[k].append(j[f"{field}_cpu_us"])

    med_wall = {k: statistics.median(v) for k, v in wall.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    labels = {k: peers[k][0] for k in peers}
    if exe is not None:
        labels["edccif-rust"] = "edccif (Rust) cov_local CKF step"
        labels["edccif-rust-network1"] = "edccif (Rust) 1-node C-CKF AnyNetwork::step"
    base = med_cpu.get("edccif-rust")

    print(f"CKF predict+update step, default model, {STEPS}-step sequence, "
          f"medians of {args.rounds} interleaved rounds (Python {sys.version.split()[0]}); "
          "ratio = cpu time / edccif-rust cpu time")
    print(f"{'implementation':<22} {'cpu us/step':>12} {'wall us/step':>13} {'x edccif-rust':>14} "
          f"{'final pos err':>14}  details")
    for k in sorted(med_cpu, key=med_cpu.get):
        ratio = f"{med_cpu[k] / base:>13.1f}x" if base else f"{'-':>14}"
        err = f"{final_error[k]:>12.3f} m" if k in final_error else f"{'-':>14}"
        print(f"{k:<22} {med_cpu[k]:>12.2f} {med_wall[k]:>13.2f} {ratio} {err}  {labels[k]}")
    for n in notes:
        print(f"note: {n}")

    if args.json:
        args.json.write_text(json.dumps(
            {"cpu_us_per_step": med_cpu, "wall_us_per_step": med_wall, "labels": labels,
             "final_position_error_m": final_error,
             "rounds": args.rounds, "notes": notes},
            indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
