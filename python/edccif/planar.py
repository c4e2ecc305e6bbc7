"""A 2-D mixed-sensor scenario of catalogue models, and its Monte Carlo study as
cells of a sweep (``docs/results.md``, the fusion front).

Six nodes on a circle of radius 10 m around a target turning in the plane
(``models.CoordinatedTurn2D``, state ``[x, y, vx, vy, ω]``, q1 = 0.5, q2 = 1e-4,
the default scenario's noise), ring topology with the max-degree weights,
200 steps of 0.1 s. The sensors alternate: range–bearing (σr = 0.1 m,
σb = 0.01 rad), bearing-only (σb = 0.01 rad) and position (σ = 0.1 m per axis),
so the measurement dimensions are 2, 1, 2, 2, 1, 2. The run r of a study is
simulated with seed ``seed + r`` (NumPy's PCG64): the target's motion with
process noise, every sensor's noisy measurement at every step, and the initial
estimate ``x0 + chol(P0) ξ``.

>>> cell = PlanarCell("edc-cif", None, None, None, "ring", runs=2, seed=0, steps=20)
>>> row = cell.run()
>>> row["scenario"], row["nodes"], row["state_dim"], 0.0 < row["trigger_rate"] < 1.0
('planar-6', 6, 5, True)
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _edccif, models
from .sweep import chi2_band

NAME = "planar-6"
NODES = 6
DT = 0.1
STEPS = 200
RADIUS = 10.0
X0 = np.array([5.0, 0.0, 0.0, 1.5, 0.3])
P0 = np.diag([0.01, 0.01, 0.01, 0.01, 1e-4])
Q1, Q2 = 0.5, 1e-4
SIGMA_R, SIGMA_B, SIGMA_P = 0.1, 0.01, 0.1


def sites(nodes: int = NODES) -> np.ndarray:
    """The sensors' positions, (nodes, 2), on the circle of radius 10 m."""
    a = 2 * np.pi * np.arange(nodes) / nodes
    return RADIUS * np.stack([np.cos(a), np.sin(a)], axis=1)


def sensors(nodes: int = NODES) -> List[Any]:
    """Range–bearing, bearing-only and position sensors in turn."""
    out: List[Any] = []
    for i, p in enumerate(sites(nodes)):
        kind = i % 3
        if kind == 0:
            out.append(models.RangeBearing(p, SIGMA_R, SIGMA_B))
        elif kind == 1:
            out.append(models.BearingOnly(p, SIGMA_B))
        else:
            out.append(models.Position([SIGMA_P, SIGMA_P]))
    return out


def noise_sigmas(nodes: int = NODES) -> List[np.ndarray]:
    """Each sensor's noise standard deviations."""
    s = [np.array([SIGMA_R, SIGMA_B]), np.array([SIGMA_B]), np.array([SIGMA_P, SIGMA_P])]
    return [s[i % 3] for i in range(nodes)]


def angle_components(nodes: int = NODES) -> List[Tuple[int, ...]]:
    """Which measurement components are angles (wrapped to (−π, π])."""
    a = [(1,), (0,), ()]
    return [a[i % 3] for i in range(nodes)]


def weights(topology: str, nodes: int = NODES) -> np.ndarray:
    """Max-degree combination weights of a ring, or 1/N on the complete graph
    (every node adapts with every contribution: the centralised filter)."""
    if topology == "complete":
        return np.full((nodes, nodes), 1.0 / nodes)
    if topology != "ring":
        raise _edccif.ParameterError(f"topology: expected ring or complete, got {topology!r}")
    w = np.zeros((nodes, nodes))
    for i in range(nodes):
        w[i, (i + 1) % nodes] = w[i, (i - 1) % nodes] = 1.0 / 3.0
        w[i, i] = 1.0 - w[i].sum()
    return w


def simulate(seed: int, steps: int = STEPS, nodes: int = NODES) -> Tuple[np.ndarray, List[np.ndarray], np.ndarray]:
    """One seeded run: the truth (T, 5), each node's measurements (T, m_i) and
    the initial estimate (5,)."""
    rng = np.random.default_rng(seed)
    motion = models.CoordinatedTurn2D(Q1, Q2)
    sens = sensors(nodes)
    sig = noise_sigmas(nodes)
    ang = angle_components(nodes)
    lq = np.linalg.cholesky(motion.Q(DT))
    x = X0.copy()
    truth = np.empty((steps, 5))
    z = [np.empty((steps, len(s))) for s in sig]
    for k in range(steps):
        x = motion.f(x[None, :], DT)[0] + lq @ rng.standard_normal(5)
        truth[k] = x
        for i, h in enumerate(sens):
            zi = h.h(x[None, :])[0] + sig[i] * rng.standard_normal(len(sig[i]))
            for a in ang[i]:
                zi[a] = np.arctan2(np.sin(zi[a]), np.cos(zi[a]))
            z[i][k] = zi
    x0 = X0 + np.linalg.cholesky(P0) @ rng.standard_normal(5)
    return truth, z, x0


@dataclass(frozen=True)
class PlanarCell:
    """One Monte Carlo study of the planar scenario: a sweep cell
    (``edccif.sweep.run_sweep`` runs it like the built-in scenario's cells)."""

    algorithm: str
    trigger: Optional[str]
    threshold: Optional[float]
    fusion: Optional[str]
    topology: str
    runs: int = 100
    seed: int = 0
    steps: int = STEPS

    @property
    def cell_id(self) -> str:
        d = asdict(self)
        d["scenario"] = NAME
        d["version"] = _edccif.__version__
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]

    def options(self) -> Dict[str, Any]:
        o: Dict[str, Any] = {}
        if self.trigger is not None:
            o["trigger"] = self.trigger
        if self.threshold is not None:
            o["delta"] = self.threshold
        if self.fusion is not None:
            o["fusion"] = self.fusion
        return o

    def run(self) -> Dict[str, Any]:
        """The cell's row (the columns of ``edccif.sweep.COLUMNS``)."""
        t0 = time.perf_counter()
        motion = models.CoordinatedTurn2D(Q1, Q2)
        sens = sensors()
        w = weights(self.topology)
        sq = np.zeros((self.steps, NODES))
        sqv = np.zeros((self.steps, NODES))
        nees = 0.0
        measured = triggered = 0
        s2e = e2s = e2e = 0
        bad = 0
        for r in range(self.runs):
            truth, z, x0 = simulate(self.seed + r, self.steps)
            net = _edccif.ModelNetwork(motion, sens, self.algorithm, x0=x0, P0=P0, weights=w, dt=DT,
                                       **self.options())
            res = net.run(z)
            e = res.estimates - truth[:, None, :]
            if not np.isfinite(e).all():
                bad += 1
                continue
            sq += (e[:, :, :2] ** 2).sum(axis=2)
            sqv += (e[:, :, 2:4] ** 2).sum(axis=2)
            nees += float(np.einsum("tki,tkij,tkj->", e, np.linalg.inv(res.covariances), e))
            measured += int(res.measured.sum())
            triggered += int(res.triggered.sum())
            v = res.values_sent
            s2e += v["sensor_to_estimator"]
            e2s += v.get("estimator_to_sensor", 0)
            e2e += v["estimator_to_estimator"]
        good = self.runs - bad
        if good == 0:
            raise _edccif.NonFiniteError(f"{NAME}: every run of {self.options()} had a non-finite estimate")
        per_step = 1.0 / (good * self.steps)
        lo, hi = chi2_band(5 * self.runs, self.runs)
        nees_avg = nees * per_step / NODES
        return {
            "cell_id": self.cell_id,
            "scenario": NAME,
            "algorithm": self.algorithm,
            "trigger": self.trigger,
            "threshold": self.threshold,
            "fusion": self.fusion,
            "nodes": NODES,
            "topology": self.topology,
            "loss": 0.0,
            "seed": self.seed,
            "runs": self.runs,
            "steps": self.steps,
            "state_dim": 5,
            "pos_rmse": float(np.sqrt(sq / good).mean()),
            "vel_rmse": float(np.sqrt(sqv / good).mean()),
            "nees": nees_avg,
            "nees_lo": lo,
            "nees_hi": hi,
            "nees_in_band": bool(lo <= nees_avg <= hi),
            "trigger_rate": triggered / measured if measured else 0.0,
            "floats_s2e": s2e * per_step,
            "floats_e2s": e2s * per_step,
            "floats_e2e": e2e * per_step,
            "floats_total": (s2e + e2s + e2e) * per_step,
            "guard_fallbacks": 0,
            "non_finite_runs": bad,
            "wall_s": time.perf_counter() - t0,
        }


@dataclass
class PlanarGrid:
    """A grid of :class:`PlanarCell` (``run_sweep`` takes it like a ``Grid``):
    algorithm × trigger × threshold × fusion × topology."""

    algorithms: Sequence[str] = ("edc-cif",)
    triggers: Sequence[Optional[str]] = (None,)
    thresholds: Dict[Optional[str], Sequence[Optional[float]]] = None  # type: ignore[assignment]
    fusions: Sequence[Optional[str]] = (None,)
    topologies: Sequence[str] = ("ring",)
    runs: int = 100
    seed: int = 0
    steps: int = STEPS

    def cells(self) -> List[PlanarCell]:
        out = []
        for topo in self.topologies:
            for alg in self.algorithms:
                for trig in self.triggers:
                    ths = list((self.thresholds or {}).get(trig, [None])) or [None]
                    for th in ths:
                        for fus in self.fusions:
                            out.append(PlanarCell(alg, trig, th, fus, topo, self.runs, self.seed, self.steps))
        return out
