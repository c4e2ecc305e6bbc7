"""`SingleFilter.batch_filter`: the same numbers as the `predict(); update(z)` loop
in Python, bit for bit, for every filter; missing rows, per-step time steps and
continuation; every bad input rejected by name, leaving the filter as it was."""

import numpy as np
import pytest

import edccif
from edccif import models


@pytest.fixture(scope="module")
def paper():
    sc = edccif.Scenario.paper(nodes=4)
    truth, z, x0 = sc.simulate(seed=3)
    node = 1
    zs = z[:, node].copy()
    zs[[5, 6, 40]] = np.nan  # three steps without a measurement
    mo, me = sc.motion, sc.measurement
    ct = models.CoordinatedTurn(mo["q1"], mo["q2"])
    rpa = models.RangePitchAzimuth(sc.sensors[node], me["sigma_r"], me["sigma_a"])
    return sc, x0, zs, ct, rpa


MAKERS = {
    "CKF": lambda ct, rpa, x0, p0, dt: edccif.CKF(ct, rpa, x0, p0, dt=dt),
    "EKF": lambda ct, rpa, x0, p0, dt: edccif.EKF(ct, rpa, x0, p0, dt=dt),
    "UKF": lambda ct, rpa, x0, p0, dt: edccif.UKF(ct, rpa, x0, p0, dt=dt, alpha=0.5),
    "CIF": lambda ct, rpa, x0, p0, dt: edccif.CIF(ct, rpa, x0, p0, dt=dt),
    "ETCIF": lambda ct, rpa, x0, p0, dt: edccif.ETCIF(ct, rpa, x0, p0, dt=dt),
}


def loop(f, zs, dts):
    """The reference: the Python loop over predict and update."""
    means, covs, sent = [], [], []
    for zk, dk in zip(zs, dts):
        f.predict(dt=dk)
        t = f.update(None if np.isnan(zk).all() else zk)
        means.append(f.x)
        covs.append(f.P)
        sent.append(-1 if t is None else int(t))
    return np.array(means), np.array(covs), np.array(sent, dtype=np.int8)


@pytest.mark.parametrize("kind", sorted(MAKERS))
def test_batch_equals_the_python_loop_bit_for_bit(paper, kind):
    sc, x0, zs, ct, rpa = paper
    make = MAKERS[kind]
    a = make(ct, rpa, x0, sc.p0, sc.dt)
    b = make(ct, rpa, x0, sc.p0, sc.dt)
    means, covs = a.batch_filter(zs)
    ref_means, ref_covs, ref_sent = loop(b, zs, [sc.dt] * len(zs))
    assert means.shape == (len(zs), 7) and covs.shape == (len(zs), 7, 7)
    np.testing.assert_array_equal(means, ref_means)
    np.testing.assert_array_equal(covs, ref_covs)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    if kind == "ETCIF":
        sent = a.batch_sent
        assert sent.dtype == np.int8 and sent.shape == (len(zs),)
        np.testing.assert_array_equal(sent, ref_sent)
        assert set(sent[[5, 6, 40]]) == {-1}
        # the default trigger sends some measurements and not others
        assert 0 < (sent == 1).sum() < (sent >= 0).sum()
        assert a.triggered == b.triggered


def test_per_step_dt_and_continuation(paper):
    sc, x0, zs, ct, rpa = paper
    rng = np.random.default_rng(7)
    dts = rng.uniform(0.05, 0.2, len(zs))
    a = edccif.ETCIF(ct, rpa, x0, sc.p0)  # no default dt: the batch gives them
    b = edccif.ETCIF(ct, rpa, x0, sc.p0)
    half = len(zs) // 2
    m1, c1 = a.batch_filter(zs[:half], dt=dts[:half])
    sent1 = a.batch_sent
    m2, c2 = a.batch_filter(zs[half:], dt=dts[half:])
    ref_m, ref_c, ref_sent = loop(b, zs, dts)
    np.testing.assert_array_equal(np.vstack([m1, m2]), ref_m)
    np.testing.assert_array_equal(np.concatenate([c1, c2]), ref_c)
    np.testing.assert_array_equal(np.concatenate([sent1, a.batch_sent]), ref_sent)
    # a scalar dt is every step's
    c = edccif.CKF(ct, rpa, x0, sc.p0)
    d = edccif.CKF(ct, rpa, x0, sc.p0, dt=0.1)
    np.testing.assert_array_equal(c.batch_filter(zs, dt=0.1)[0], d.batch_filter(zs)[0])


def test_custom_model_batch_matches_loop():
    # 1-D constant velocity written as Python functions (guide §1)
    def f(X, dt):
        return X @ np.array([[1.0, 0.0], [dt, 1.0]])

    def Q(dt):
        return 0.1 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])

    motion = models.CustomMotion(f, Q=Q, n=2)
    sensor = models.LinearMeasurement(np.array([[1.0, 0.0]]), np.array([[0.05**2]]))
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.05, 0.3, 50))
    z = (2.0 * t + 0.05 * rng.standard_normal(50))[:, None]
    a = edccif.CKF(motion, sensor, x0=[0.0, 0.0], P0=np.diag([1.0, 4.0]))
    b = edccif.CKF(motion, sensor, x0=[0.0, 0.0], P0=np.diag([1.0, 4.0]))
    dts = np.diff(t, prepend=0.0)
    means, covs = a.batch_filter(z, dt=dts)
    ref_m, ref_c, _ = loop(b, z, dts)
    np.testing.assert_array_equal(means, ref_m)
    np.testing.assert_array_equal(covs, ref_c)
    assert abs(means[-1, 1] - 2.0) < 0.3


def state(f):
    return f.x.copy(), f.P.copy()


def assert_unchanged(f, before):
    np.testing.assert_array_equal(f.x, before[0])
    np.testing.assert_array_equal(f.P, before[1])


def test_bad_inputs_are_named_and_leave_the_filter_unchanged(paper):
    sc, x0, zs, ct, rpa = paper
    f = edccif.ETCIF(ct, rpa, x0, sc.p0, dt=sc.dt)
    f.batch_filter(zs[:10])
    before = state(f)
    sent_before = f.batch_sent.copy()
    with pytest.raises(edccif.ShapeError, match="zs"):
        f.batch_filter(np.zeros((5, 4)))
    with pytest.raises(edccif.ShapeError, match="zs"):
        f.batch_filter(np.zeros(3))
    with pytest.raises(edccif.ShapeError, match="dt"):
        f.batch_filter(zs[:5], dt=np.full(4, 0.1))
    with pytest.raises(edccif.ParameterError, match=r"dt\[3\].*> 0"):
        f.batch_filter(zs[:5], dt=[0.1, 0.1, 0.1, 0.0, 0.1])
    with pytest.raises(edccif.ParameterError, match=r"dt\[1\]"):
        f.batch_filter(zs[:5], dt=[0.1, np.nan, 0.1, 0.1, 0.1])
    bad = zs[10:20].copy()
    bad[4, 1] = np.nan  # one NaN in a row: not "no measurement"
    with pytest.raises(edccif.NonFiniteError, match="^step 4: .*measurement z"):
        f.batch_filter(bad)
    bad[4] = [np.inf, 0.1, 0.2]
    with pytest.raises(edccif.NonFiniteError, match="^step 4:"):
        f.batch_filter(bad)
    assert_unchanged(f, before)
    np.testing.assert_array_equal(f.batch_sent, sent_before)
    # still usable, and the same as a filter that never saw the bad calls
    g = edccif.ETCIF(ct, rpa, x0, sc.p0, dt=sc.dt)
    g.batch_filter(zs[:10])
    np.testing.assert_array_equal(f.batch_filter(zs[10:20])[0], g.batch_filter(zs[10:20])[0])
    h = edccif.CKF(ct, rpa, x0, sc.p0)
    with pytest.raises(edccif.ParameterError, match="no time step"):
        h.batch_filter(zs[:3])


def test_a_model_callable_failing_mid_batch_keeps_its_cause():
    calls = {"n": 0}

    def f(X, dt):
        calls["n"] += 1
        if calls["n"] == 4:
            raise RuntimeError("sensor model exploded")
        return X @ np.array([[1.0, 0.0], [dt, 1.0]])

    motion = models.CustomMotion(f, Q=lambda dt: 0.01 * np.eye(2) * dt, n=2)
    sensor = models.LinearMeasurement(np.array([[1.0, 0.0]]), np.array([[0.01]]))
    k = edccif.CKF(motion, sensor, x0=[0.0, 1.0], P0=np.eye(2), dt=0.1)
    before = state(k)
    with pytest.raises(edccif.ModelError, match="^step 3:") as e:
        k.batch_filter(np.arange(6.0)[:, None] * 0.1)
    assert isinstance(e.value.__cause__, RuntimeError)
    assert "exploded" in str(e.value.__cause__)
    assert_unchanged(k, before)


def loop_with_r(f, zs, dts, rs):
    """The reference with a noise covariance per step: `update(z, R)`."""
    means, covs = [], []
    for zk, dk, rk in zip(zs, dts, rs):
        f.predict(dt=dk)
        f.update(None if np.isnan(zk).all() else zk, R=rk)
        means.append(f.x)
        covs.append(f.P)
    return np.array(means), np.array(covs)


@pytest.mark.parametrize("kind", sorted(MAKERS))
def test_per_step_noise_equals_update_with_r_bit_for_bit(paper, kind):
    sc, x0, zs, ct, rpa = paper
    make = MAKERS[kind]
    me = sc.measurement
    base = np.diag([me["sigma_r"] ** 2, me["sigma_a"] ** 2, me["sigma_a"] ** 2])
    # the range noise grows and shrinks along the run, with a correlated pair
    scale = 1.0 + 3.0 * np.sin(np.linspace(0.0, np.pi, len(zs))) ** 2
    rs = base[None] * scale[:, None, None]
    rs[:, 1, 2] = rs[:, 2, 1] = 0.3 * me["sigma_a"] ** 2
    a, b = make(ct, rpa, x0, sc.p0, sc.dt), make(ct, rpa, x0, sc.p0, sc.dt)
    means, covs = a.batch_filter(zs, Rs=rs)
    ref_m, ref_c = loop_with_r(b, zs, [sc.dt] * len(zs), rs)
    np.testing.assert_array_equal(means, ref_m)
    np.testing.assert_array_equal(covs, ref_c)
    # the per-step R is used: the run differs from one with the sensor's own R
    plain = make(ct, rpa, x0, sc.p0, sc.dt).batch_filter(zs)[0]
    assert np.abs(means - plain).max() > 1e-6
    # one (m, m) for every step is the same as that matrix repeated
    c, d = make(ct, rpa, x0, sc.p0, sc.dt), make(ct, rpa, x0, sc.p0, sc.dt)
    one = 2.0 * base
    np.testing.assert_array_equal(
        c.batch_filter(zs, Rs=one)[0], d.batch_filter(zs, Rs=np.repeat(one[None], len(zs), 0))[0]
    )
    # the override is for the batch only: the next update uses the sensor's R again
    e, g = make(ct, rpa, x0, sc.p0, sc.dt), make(ct, rpa, x0, sc.p0, sc.dt)
    e.batch_filter(zs[:20], Rs=rs[:20])
    g.batch_filter(zs[:20], Rs=rs[:20])
    e.predict()
    e.update(zs[20])
    g.predict()
    g.update(zs[20], R=base)
    np.testing.assert_array_equal(e.x, g.x)


@pytest.mark.parametrize("kind", ["CKF", "ETCIF"])
def test_bad_per_step_noise_is_named_and_leaves_the_filter_unchanged(paper, kind):
    sc, x0, zs, ct, rpa = paper
    f = MAKERS[kind](ct, rpa, x0, sc.p0, sc.dt)
    f.batch_filter(zs[:10])
    before = state(f)
    rs = np.repeat(np.eye(3)[None] * 0.01, 10, 0)
    with pytest.raises(edccif.ShapeError, match=r"Rs.*\(3, 3\) noise covariance for every step or \(10, 3, 3\)"):
        f.batch_filter(zs[10:20], Rs=rs[:9])
    with pytest.raises(edccif.ShapeError, match="Rs"):
        f.batch_filter(zs[10:20], Rs=np.eye(2))
    nan = rs.copy()
    nan[6, 0, 0] = np.nan
    with pytest.raises(edccif.NonFiniteError, match="Rs"):
        f.batch_filter(zs[10:20], Rs=nan)
    indefinite = rs.copy()
    indefinite[6, 0, 0] = -1.0
    with pytest.raises(edccif.NotPositiveDefiniteError, match=r"^step 6: .*R"):
        f.batch_filter(zs[10:20], Rs=indefinite)
    assert_unchanged(f, before)
    # the failed batch left no override behind
    g = MAKERS[kind](ct, rpa, x0, sc.p0, sc.dt)
    g.batch_filter(zs[:10])
    np.testing.assert_array_equal(f.batch_filter(zs[10:20])[0], g.batch_filter(zs[10:20])[0])
