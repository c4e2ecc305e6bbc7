"""Consistency (NEES) of a 2-D, 5-node network of mixed bearing-only and
range-bearing sensors with non-uniform timestamps, over 50 seeded runs.

Models (numpy, ``edccif.models.Custom*``): constant velocity in the plane (state
``[x, y, vx, vy]``, white-acceleration intensity q, ``Q(dt)`` over each step's own
dt); nodes 0, 2, 4 range-bearing (σr = 0.5 m, σb = 0.01 rad), nodes 1, 3
bearing-only (σb = 0.01 rad), on a circle of radius 30 m; node 3 measures every
other step only. Steps dt ~ U[0.05, 0.2] s, 80 steps, start error ~ N(0, P0).

NEES ε = (x̂ − x)ᵀ P⁻¹ (x̂ − x) of every node's fused estimate, averaged over the
R = 50 runs at each step. For a consistent filter each step's average lies in
the two-sided 95 % band of χ²(nR)/R, n = 4: [162.728/50, 241.058/50] =
[3.255, 4.821] (χ² quantiles of 200 degrees of freedom).

Row: EDC-CIF (the paper's method: event-triggered CIF, δ = 0.04, diffusion with
covariance intersection). On the complete graph every node adapts with every
contribution, so each node holds the whole network's information and the NEES
sits in the band. On a ring the CI combination is conservative by design (it
averages information it cannot prove independent): the NEES falls below the
band's centre; the second test states that too.
"""

import numpy as np
import pytest

import edccif
from edccif import models

N_STATE, RUNS, STEPS = 4, 50, 80
BAND = (162.728 / RUNS, 241.058 / RUNS)  # χ²(200) 2.5 % and 97.5 % quantiles / R
Q_INT = 0.05
SIG_R, SIG_B = 0.5, 0.01
ANG = 2 * np.pi * np.arange(5) / 5
SENSORS = 30.0 * np.stack([np.cos(ANG), np.sin(ANG)], axis=1)
P0 = np.diag([1.0, 1.0, 0.25, 0.25])


def F(dt):
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    return f


def Q(dt):
    q = np.zeros((4, 4))
    for a in range(2):
        q[a, a] = dt**3 / 3
        q[a, a + 2] = q[a + 2, a] = dt**2 / 2
        q[a + 2, a + 2] = dt
    return Q_INT * q


def bearing(s):
    return lambda X: np.arctan2(X[:, 1] - s[1], X[:, 0] - s[0])[:, None]


def range_bearing(s):
    def h(X):
        d = X[:, :2] - s
        return np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])], axis=1)

    return h


def network_models():
    cv = models.CustomMotion(lambda X, dt: X @ F(dt).T, Q=Q, n=4)
    sensors = []
    for i, s in enumerate(SENSORS):
        if i % 2 == 0:
            sensors.append(models.CustomMeasurement(range_bearing(s), np.diag([SIG_R**2, SIG_B**2]),
                                                    m=2, n=4, angles=(1,)))
        else:
            sensors.append(models.CustomMeasurement(bearing(s), np.array([[SIG_B**2]]), m=1, n=4,
                                                    angles=(0,)))
    return cv, sensors


def simulate(seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.05, 0.2, STEPS))
    dts = np.diff(np.concatenate([[0.0], t]))
    x = np.array([0.0, 0.0, 1.0, 0.5])
    truth = np.empty((STEPS, 4))
    z = [np.full((STEPS, 2 if i % 2 == 0 else 1), np.nan) for i in range(5)]
    for k, dt in enumerate(dts):
        x = F(dt) @ x + np.linalg.cholesky(Q(dt)) @ rng.standard_normal(4)
        truth[k] = x
        for i, s in enumerate(SENSORS):
            if i == 3 and k % 2 == 1:
                continue  # node 3 at half the rate: NaN rows, it predicts and still fuses
            d = x[:2] - s
            b = np.arctan2(d[1], d[0]) + SIG_B * rng.standard_normal()
            if i % 2 == 0:
                z[i][k] = [np.hypot(*d) + SIG_R * rng.standard_normal(), b]
            else:
                z[i][k] = [b]
    x0 = np.array([0.0, 0.0, 1.0, 0.5]) + np.linalg.cholesky(P0) @ rng.standard_normal(4)
    return t, truth, z, x0


def average_nees(weights, algorithm="edc-cif"):
    cv, sensors = network_models()
    total = np.zeros((STEPS, 5))
    for seed in range(RUNS):
        t, truth, z, x0 = simulate(seed)
        net = edccif.ModelNetwork(cv, sensors, algorithm, x0=x0, P0=P0, weights=weights)
        r = net.run(z, t=t)
        e = r.estimates - truth[:, None, :]
        total += np.einsum("tki,tkij,tkj->tk", e, np.linalg.inv(r.covariances), e)
    return total / RUNS


COMPLETE = np.full((5, 5), 0.2)
RING = np.eye(5) / 3 + (np.eye(5, k=1) + np.eye(5, k=-1) + np.eye(5, k=4) + np.eye(5, k=-4)) / 3


@pytest.fixture(scope="module")
def nees_complete():
    return average_nees(COMPLETE)


def test_nees_in_the_95_band_on_the_complete_graph(nees_complete):
    lo, hi = BAND
    per_node = nees_complete[10:].mean(axis=0)  # after 10 steps of start-up
    inside = ((nees_complete >= lo) & (nees_complete <= hi)).mean()
    print(f"EDC-CIF complete graph: mean NEES per node {np.round(per_node, 3)}, "
          f"steps in the band {inside:.1%}, band [{lo:.3f}, {hi:.3f}]")
    assert ((per_node >= lo) & (per_node <= hi)).all(), per_node
    # about 95 % of the steps inside when consistent; at least 85 % required
    assert inside >= 0.85, inside


def test_ring_is_conservative_not_overconfident():
    nees = average_nees(RING)
    lo, hi = BAND
    per_node = nees[10:].mean(axis=0)
    inside = ((nees >= lo) & (nees <= hi)).mean()
    print(f"EDC-CIF ring: mean NEES per node {np.round(per_node, 3)}, steps in the band {inside:.1%}")
    # CI on a sparse graph: covariances too large (NEES below n = 4), never too small
    assert (per_node < N_STATE).all() and (nees <= hi).mean() >= 0.95, per_node
