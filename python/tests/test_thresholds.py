"""Thresholds a user can set: `delta` per node (list or array) in every entry
point, with named errors for bad lists, and `normalised=True` (δ on
(z − z_τ)ᵀR⁻¹(z − z_τ)); the untriggered step of a normalised threshold
against numpy (S = μ1 G P⁻ Gᵀ + μ2 R + μ3 δ R)."""

import numpy as np
import pytest

import edccif
from edccif import models


def test_per_node_delta_in_run_network_and_scenario(sc4, sim4):
    _, z, x0 = sim4
    per = [0.04, 0.16, 0.01, 0.04]
    r = edccif.run("edc-cif", sc4, z, x0=x0, delta=per)
    a = edccif.run("edc-cif", sc4, z, x0=x0, delta=np.array(per))
    assert np.array_equal(r.estimates, a.estimates)
    sent = r.triggered.mean(axis=0)
    assert sent[1] < sent[0] < sent[2], sent
    net = edccif.Network(sc4, "edc-cif", x0=x0, delta=per)
    for zk in z:
        fused = net.step(zk)
    assert np.array_equal(fused, r.estimates[-1])
    sc = sc4.replace(delta=per)
    assert sc.delta == per
    assert np.array_equal(edccif.run("edc-cif", sc, z, x0=x0).estimates, r.estimates)
    assert edccif.Scenario.from_toml_str(sc.to_toml()) == sc
    # equal values are the one threshold, bit for bit
    one = edccif.run("edc-cif", sc4, z, x0=x0)
    assert np.array_equal(edccif.run("edc-cif", sc4, z, x0=x0, delta=[0.04] * 4).estimates, one.estimates)


def test_per_node_delta_equals_each_node_alone_without_fusion(sc4, sim4):
    _, z, x0 = sim4
    per = [0.01, 0.04, 0.09, 0.3]
    r = edccif.run("edc-cif", sc4, z, x0=x0, delta=per, fusion="local")
    for i, d in enumerate(per):
        alone = edccif.run("edc-cif", sc4, z, x0=x0, delta=d, fusion="local")
        assert np.array_equal(r.estimates[:, i], alone.estimates[:, i]), i
        assert np.array_equal(r.triggered[:, i], alone.triggered[:, i]), i


def test_per_node_delta_in_node_and_sensor_trigger(sc4, sim4):
    _, z, x0 = sim4
    per = [0.04, 0.16, 0.01, 0.04]
    ref = edccif.run("edc-cif", sc4, z, x0=x0, delta=per)
    for i in range(4):
        trig = edccif.SensorTrigger(sc4, "edc-cif", node=i, delta=per)
        sent = [trig.decide(zk[i]) for zk in z]
        assert sent == ref.triggered[:, i].tolist(), i


@pytest.mark.parametrize(
    "bad, match",
    [
        ([0.04, 0.04, 0.04], r"delta: has 3 values for 4 nodes; expected one per node"),
        ([0.04, float("nan"), 0.04, 0.04], r"delta\[1\]: expected a finite number > 0.*got NaN"),
        ([0.04, 0.04, -1.0, 0.04], r"delta\[2\]: expected a finite number > 0.*got -1"),
        ([], r"delta: expected a finite number > 0.*an empty list"),
        (["a", 0.04, 0.04, 0.04], r"delta: expected a finite number > 0"),
        ("0.04", r"delta: expected a finite number > 0"),
        (True, r"delta: expected a finite number > 0"),
        (-0.5, r"delta: expected a finite number > 0.*got -0.5"),
    ],
)
def test_bad_delta_is_a_named_parameter_error(sc4, sim4, bad, match):
    _, z, x0 = sim4
    with pytest.raises(edccif.ParameterError, match=match):
        edccif.run("edc-cif", sc4, z[:3], x0=x0, delta=bad)
    with pytest.raises(edccif.ParameterError, match=match):
        edccif.Network(sc4, "edc-cif", x0=x0, delta=bad)


def test_bad_delta_in_a_scenario_names_the_field():
    with pytest.raises(edccif.ScenarioError, match="delta"):
        edccif.Scenario.paper(nodes=4).replace(delta=[0.04, 0.04])
    with pytest.raises(edccif.ScenarioError, match="delta"):
        edccif.Scenario.paper(nodes=4).replace(delta=[0.04, -1.0, 0.04, 0.04])
    with pytest.raises(edccif.ScenarioError, match="normalised"):
        edccif.Scenario.paper(nodes=4).replace(normalised=1)


def _mixed():
    def f(X, dt):
        F = np.eye(4)
        F[0, 2] = F[1, 3] = dt
        return X @ F.T

    def Q(dt):
        q = np.zeros((4, 4))
        for a in (0, 1):
            q[a, a], q[a, a + 2] = dt**3 / 3, dt**2 / 2
            q[a + 2, a], q[a + 2, a + 2] = dt**2 / 2, dt
        return 0.05 * q

    sites = 30.0 * np.array([[np.cos(a), np.sin(a)] for a in 2 * np.pi * np.arange(4) / 4])

    def rb(p):
        def h(X):
            d = X[:, :2] - p
            return np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])], axis=1)

        return models.CustomMeasurement(h, R=np.diag([0.5**2, 0.01**2]), m=2, n=4, angles=(1,))

    def bo(p):
        return models.CustomMeasurement(
            lambda X: np.arctan2(X[:, 1] - p[1], X[:, 0] - p[0])[:, None], R=np.array([[0.01**2]]), m=1, n=4,
            angles=(0,))

    sensors = [rb(sites[0]), bo(sites[1]), rb(sites[2]), bo(sites[3])]
    rng = np.random.default_rng(7)
    x = np.array([0.0, 0.0, 1.0, 0.5])
    zs = [[], [], [], []]
    for _ in range(200):
        x = f(x[None, :], 0.1)[0] + np.linalg.cholesky(Q(0.1)) @ rng.standard_normal(4)
        for i, s in enumerate(sensors):
            sigma = np.sqrt(np.diag(s.R))
            zs[i].append(s.h(x[None, :])[0] + sigma * rng.standard_normal(sigma.size))
    return models.CustomMotion(f, Q=Q, n=4), sensors, [np.array(zi) for zi in zs]


def test_one_normalised_threshold_for_range_and_bearing_nodes():
    motion, sensors, z = _mixed()
    kw = dict(x0=[0.0, 0.0, 1.0, 0.5], P0=np.eye(4), dt=0.1)
    raw = edccif.ModelNetwork(motion, sensors, "edc-cif", **kw).run(z)
    rate_raw = raw.triggered.mean(axis=0)
    # δ = 0.04 in raw squared units: bearings (0.01 rad) hardly ever send
    assert rate_raw[1] < 0.1 and rate_raw[3] < 0.1, rate_raw
    net = edccif.ModelNetwork(motion, sensors, "edc-cif", normalised=True, delta=2.0, **kw)
    rate = net.run(z).triggered.mean(axis=0)
    assert ((rate > 0.2) & (rate < 0.8)).all(), rate
    # per node and normalised together
    per = edccif.ModelNetwork(motion, sensors, "edc-cif", normalised=True, delta=[2.0, 1.0, 2.0, 1.0], **kw)
    rate_per = per.run(z).triggered.mean(axis=0)
    assert rate_per[1] > rate[1] and rate_per[3] > rate[3] and rate_per[0] == rate[0], (rate_per, rate)
    with pytest.raises(edccif.ParameterError, match="normalised: expected True"):
        edccif.ModelNetwork(motion, sensors, "edc-cif", normalised="yes", **kw)
    with pytest.raises(edccif.ParameterError, match="delta: has 3 values for 4 nodes"):
        edccif.ModelNetwork(motion, sensors, "edc-cif", delta=[1.0, 1.0, 1.0], **kw)


def _untriggered_by_numpy(x, P, F, Q, H, R, z_tau, delta, s1, s2, normalised):
    """One predict + untriggered update of ALGORITHM.md §3 step 5, written out:
    S = μ1 G P⁻ Gᵀ + μ2 R + μ3 δ B with B = R (normalised) or I; the CIF's
    posterior is then (x⁻ + M Δz̄, P̄)."""
    xp = F @ x
    Pp = F @ P @ F.T + Q
    mu1, mu2, mu3 = 1 + s1, 1 + s2, 1 + 1 / s1 + 1 / s2
    B = R if normalised else np.eye(len(R))
    S = mu1 * H @ Pp @ H.T + mu2 * R + mu3 * delta * B
    M = mu1 * Pp @ H.T @ np.linalg.inv(S)
    Pbar = mu1 * (np.eye(len(x)) - M @ H) @ Pp
    return xp + M @ (z_tau - H @ xp), Pbar


@pytest.mark.parametrize("normalised", [True, False])
@pytest.mark.parametrize("s1, s2", [(5e-4, 5e-4), (0.1, 0.3)])
def test_the_untriggered_step_of_a_normalised_threshold_against_numpy(normalised, s1, s2):
    dt = 0.1
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    Q = 0.05 * np.kron(np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), np.eye(2))
    H = np.eye(4)[:2]
    R = np.diag([0.25, 0.01])  # 0.5 m and 0.1 m
    delta = 4.0 if normalised else 0.5
    x0, P0 = np.array([1.0, 2.0, 0.5, -0.3]), np.diag([0.5, 0.4, 0.2, 0.1])
    filt = edccif.ETCIF(models.LinearMotion(F, Q), models.LinearMeasurement(H, R), x0, P0, dt=dt,
                        delta=delta, sigma1=s1, sigma2=s2, normalised=normalised)
    z1 = np.array([1.1, 1.95])
    filt.predict()
    assert filt.update(z1) is True
    x1, P1 = filt.x.copy(), filt.P.copy()
    z2 = z1 + np.array([0.4, 0.05])  # (Δ/σ)² = 0.64 + 0.25 < 4; ‖Δ‖² = 0.1625 < 0.5
    filt.predict()
    assert filt.update(z2) is False
    x2, P2 = _untriggered_by_numpy(x1, P1, F, Q, H, R, z1, delta, s1, s2, normalised)
    np.testing.assert_allclose(filt.x, x2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(filt.P, P2, rtol=1e-9, atol=1e-12)
    # the other bound gives another posterior: the test can tell them apart
    x3, P3 = _untriggered_by_numpy(x1, P1, F, Q, H, R, z1, delta, s1, s2, not normalised)
    assert np.abs(P3 - P2).max() > 1e-6
