"""Networks of your own models (edccif.ModelNetwork / Network.from_models): custom
callables equal the built-in models bit for bit on every row, nodes of different
measurement dimensions fuse, timestamps, and bad input leaves the network as it was."""

import numpy as np
import pytest

import edccif
from edccif import models

ROWS = edccif.ALGORITHMS


def _builtins(sc):
    # the reference trigonometry: the catalogue's fast path transforms the points
    # with its own kernels, which a callable that sees one point at a time cannot
    ct = models.CoordinatedTurn(0.5, 1e-4, fast_trig=False)
    pos = models.Position([0.1, 0.1, 0.1])
    x_only = models.LinearMeasurement(np.eye(7)[:1], np.array([[0.01]]))
    xy = models.LinearMeasurement(np.eye(7)[:2], np.diag([0.02, 0.03]))
    return ct, [pos, x_only, xy, pos]


def _customs(ct, sensors):
    # each callable calls the built-in model's batch evaluator: same maths, via Python
    motion = models.CustomMotion(lambda X, dt: ct.f(X, dt), Q=ct.Q, n=7,
                                 jacobian=lambda x, dt: ct.jacobian(x, dt))

    def wrap(s):
        return models.CustomMeasurement(lambda X: s.h(X), s.R, m=s.m, n=7,
                                        jacobian=lambda x: s.jacobian(x))

    return motion, [wrap(s) for s in sensors]


def _data(sc, steps=25, seed=4):
    truth, _, x0 = sc.replace(steps=steps).simulate(seed=seed)
    rng = np.random.default_rng(seed)
    z0 = truth[:, :3] + 0.1 * rng.standard_normal((steps, 3))
    z1 = truth[:, :1] + 0.1 * rng.standard_normal((steps, 1))
    z2 = truth[:, :2] + 0.15 * rng.standard_normal((steps, 2))
    z3 = truth[:, :3] + 0.1 * rng.standard_normal((steps, 3))
    z1[::3] = np.nan  # node 1 at a third of the rate
    t = np.cumsum(rng.uniform(0.05, 0.15, steps))
    return truth, [z0, z1, z2, z3], x0, t


RING4 = np.array([[0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1], [1, 0, 1, 0]], dtype=bool)


@pytest.mark.parametrize("alg", ROWS)
def test_custom_callables_equal_builtin_models_bit_for_bit(alg, sc4):
    ct, sensors = _builtins(sc4)
    cm, cs = _customs(ct, sensors)
    truth, z, x0, t = _data(sc4)
    p0 = sc4.p0
    a = edccif.ModelNetwork(ct, sensors, alg, x0=x0, P0=p0, adjacency=RING4)
    b = edccif.Network.from_models(cm, cs, alg, x0=x0, P0=p0, adjacency=RING4)
    ra = a.run(z, t=t)
    rb = b.run(z, t=t)
    np.testing.assert_array_equal(ra.estimates, rb.estimates)
    np.testing.assert_array_equal(ra.covariances, rb.covariances)
    np.testing.assert_array_equal(ra.triggered, rb.triggered)
    assert a.counters == b.counters
    assert np.isfinite(ra.estimates).all()
    # and they track the target (tolerance 1 m on the position at the end)
    err = np.linalg.norm(ra.estimates[-1, :, :3] - truth[-1, :3], axis=1)
    assert err.max() < 1.0, err


def test_streaming_equals_run_and_meas_dims(sc4):
    ct, sensors = _builtins(sc4)
    _, z, x0, t = _data(sc4)
    net = edccif.ModelNetwork(ct, sensors, "edc-cif", x0=x0, P0=sc4.p0)
    assert net.meas_dims == [3, 1, 2, 3]
    assert (net.nodes, net.state_dim) == (4, 7)
    res = edccif.ModelNetwork(ct, sensors, "edc-cif", x0=x0, P0=sc4.p0).run(z, t=t)
    for k in range(len(t)):
        zk = [zi[k] for zi in z]
        if k % 5 == 0:
            zk[1] = None  # None means missing too
            assert np.isnan(z[1][k]).all() or k % 3 != 0 or True
        est = net.step(zk if k % 5 else [zi[k] for zi in z], t=t[k])
        np.testing.assert_array_equal(est, res.estimates[k])
    assert net.t == t[-1]
    assert res.measured[:, 1].sum() == len(t) - len(range(0, len(t), 3))


def test_scenario_models_equal_the_scenario_network(sc4, sim4):
    # the paper's models as edccif.models objects give edccif.run's numbers
    truth, z, x0 = sim4
    sc = sc4
    ct = models.CoordinatedTurn(0.5, 1e-4)
    rpa = [models.RangePitchAzimuth(s, 0.1, 0.01) for s in sc.sensors]
    net = edccif.ModelNetwork(ct, rpa, "edc-cif", x0=x0, P0=sc.p0, weights=sc.weights, dt=sc.dt)
    res = net.run([z[:50, i] for i in range(4)])
    ref = edccif.run("edc-cif", sc, z[:50], x0=x0)
    np.testing.assert_array_equal(res.estimates, ref.estimates)
    np.testing.assert_array_equal(res.triggered, ref.triggered)


def test_bad_input_names_the_problem_and_leaves_state_unchanged(sc4):
    ct, sensors = _builtins(sc4)
    _, z, x0, t = _data(sc4)
    net = edccif.ModelNetwork(ct, sensors, "edc-cif", x0=x0, P0=sc4.p0, dt=0.1)
    net.step([zi[0] for zi in z], t=t[0])
    snap = (net.estimates, net.covariances, net.t, net.counters)
    good = [zi[1] for zi in z]
    mixed_nan = [zi[1].copy() for zi in z]
    mixed_nan[0][1] = np.nan
    cases = [
        (dict(z=good[:3]), edccif.ShapeError, "one measurement per node"),
        (dict(z=[good[0], np.zeros(2), good[2], good[3]]), edccif.ShapeError, r"z\[1\]"),
        (dict(z=mixed_nan), edccif.ParameterError, "node 0"),
        (dict(z=good, t=t[0]), edccif.ParameterError, "strictly increasing"),
        (dict(z=good, t=np.nan), edccif.NonFiniteError, "t"),
        (dict(z=good, dt=-1.0), edccif.ParameterError, "dt"),
        (dict(z=good, t=1.0, dt=0.1), edccif.ParameterError, "not both"),
        (dict(z=good, links=np.ones((3, 3))), edccif.ShapeError, "links"),
    ]
    for kw, err, msg in cases:
        zz = kw.pop("z")
        with pytest.raises(err, match=msg):
            net.step(zz, **kw)
        np.testing.assert_array_equal(net.estimates, snap[0])
        np.testing.assert_array_equal(net.covariances, snap[1])
        assert (net.t, net.counters) == snap[2:]
    run_cases = [
        (dict(z=z[:3], t=t), edccif.ShapeError, "one array per node"),
        (dict(z=[z[0], z[1][:5], z[2], z[3]], t=t), edccif.ShapeError, r"z\[1\]"),
        (dict(z=z, t=t), edccif.ParameterError, r"t\[0\]"),  # not after net.t
        (dict(z=z, t=t[::-1] + 10), edccif.ParameterError, r"t\[1\]"),
        (dict(z=z, dt=np.zeros(len(t))), edccif.ParameterError, r"dt\[0\]"),
        (dict(z=mixed_nan_run(z), dt=0.1), edccif.ParameterError, "step 2"),
    ]
    for kw, err, msg in run_cases:
        zz = kw.pop("z")
        with pytest.raises(err, match=msg):
            net.run(zz, **kw)
        np.testing.assert_array_equal(net.estimates, snap[0])
        assert (net.t, net.counters) == snap[2:]


def mixed_nan_run(z):
    out = [zi.copy() for zi in z]
    out[2][2, 0] = np.nan
    return out


def test_failing_callable_raises_its_error_and_leaves_state_unchanged(sc4):
    ct, sensors = _builtins(sc4)
    _, z, x0, t = _data(sc4)
    calls = {"n": 0}

    def h(X):
        calls["n"] += 1
        if calls["n"] > 3:
            raise RuntimeError("sensor driver lost")
        return X[:, :1]

    bad = models.CustomMeasurement(h, np.array([[0.01]]), m=1, n=7)
    net = edccif.ModelNetwork(ct, [sensors[0], bad], "edc-cif", x0=x0, P0=sc4.p0, dt=0.1)
    net.step([z[0][0], z[1][0]])
    snap = (net.estimates, net.covariances, net.t, net.counters)
    with pytest.raises(edccif.ModelError, match="sensor driver lost") as info:
        for k in range(1, 5):
            net.step([z[0][k], z[1][k] if not np.isnan(z[1][k]).all() else np.array([x0[0]])])
            snap = (net.estimates, net.covariances, net.t, net.counters)
    assert isinstance(info.value.__cause__, RuntimeError)
    np.testing.assert_array_equal(net.estimates, snap[0])
    assert (net.t, net.counters) == snap[2:]


def test_failing_run_restores_the_last_steps_local_estimates_and_triggers(sc4):
    # A run that fails part-way (the motion callable raises in its third step,
    # the one with dt = 0.25) leaves every view of the network as the last
    # successful step left it: the fused estimates, and also that step's local
    # (pre-combination) estimates and trigger flags.
    ct, sensors = _builtins(sc4)
    _, z, x0, _ = _data(sc4)

    def f(X, dt):
        if dt == 0.25:
            raise RuntimeError("motion model lost")
        return ct.f(X, dt)

    motion = models.CustomMotion(f, Q=ct.Q, n=7, jacobian=lambda x, dt: ct.jacobian(x, dt))
    net = edccif.ModelNetwork(motion, sensors[:2], "edc-cif", x0=x0, P0=sc4.p0, dt=0.1)
    net.step([z[0][0], z[1][1]])
    net.step([z[0][1], None])  # node 1 has no measurement: its flag is False
    snap = (net.estimates, net.local_estimates, net.triggered, net.t, net.counters)
    assert snap[2].tolist() == [True, False]
    zs = [z[0][2:6], z[1][2:6].copy()]
    zs[1][1] = z[1][2] + 5.0  # a jump: node 1 triggers in the run's second step
    with pytest.raises(edccif.ModelError, match="motion model lost"):
        net.run(zs, dt=np.array([0.1, 0.1, 0.25, 0.1]))
    np.testing.assert_array_equal(net.estimates, snap[0])
    np.testing.assert_array_equal(net.local_estimates, snap[1])
    np.testing.assert_array_equal(net.triggered, snap[2])
    assert (net.t, net.counters) == snap[3:]
    # the two good steps of that run would have changed both views
    ok = edccif.ModelNetwork(motion, sensors[:2], "edc-cif", x0=x0, P0=sc4.p0, dt=0.1)
    ok.step([z[0][0], z[1][1]])
    ok.step([z[0][1], None])
    ok.run([zi[:2] for zi in zs], dt=0.1)
    assert not np.array_equal(ok.local_estimates, snap[1])
    assert ok.triggered[1]


def test_failing_step_keeps_the_last_steps_local_estimates_and_triggers(sc4):
    # A step that fails at node 1's local step, after node 0's has run, leaves
    # the previous step's local estimates and trigger flags too.
    ct, sensors = _builtins(sc4)
    _, z, x0, _ = _data(sc4)
    lost = {"now": False}

    def h(X):
        if lost["now"]:
            raise RuntimeError("sensor driver lost")
        return X[:, :1]

    bad = models.CustomMeasurement(h, np.array([[0.01]]), m=1, n=7)
    net = edccif.ModelNetwork(ct, [sensors[0], bad], "edc-cif", x0=x0, P0=sc4.p0, dt=0.1)
    net.step([z[0][0], np.array([x0[0]])])
    net.step([None, np.array([x0[0]])])  # node 0 has no measurement: its flag is False
    snap = (net.estimates, net.local_estimates, net.triggered, net.t, net.counters)
    assert not snap[2][0]
    lost["now"] = True  # node 0 would trigger on its jump, then node 1 fails
    with pytest.raises(edccif.ModelError, match="sensor driver lost"):
        net.step([z[0][2] + 5.0, np.array([x0[0]])])
    np.testing.assert_array_equal(net.estimates, snap[0])
    np.testing.assert_array_equal(net.local_estimates, snap[1])
    np.testing.assert_array_equal(net.triggered, snap[2])
    assert (net.t, net.counters) == snap[3:]


def test_bad_construction(sc4):
    ct, sensors = _builtins(sc4)
    x0, p0 = sc4.x0, sc4.p0
    cases = [
        (dict(motion=sensors[0]), edccif.ParameterError, "motion"),
        (dict(sensors=[sensors[0], ct]), edccif.ParameterError, r"sensors\[1\]"),
        (dict(sensors=[]), edccif.ParameterError, "at least one"),
        (dict(x0=np.zeros(6)), edccif.ShapeError, "x0"),
        (dict(P0=-np.eye(7)), edccif.NotPositiveDefiniteError, "positive definite"),
        (dict(algorithm="edc"), edccif.UnknownAlgorithmError, "edc-cif"),
        (dict(weights=np.eye(4)), edccif.GraphError, "disconnected"),
        (dict(weights=np.full((4, 4), 0.3)), edccif.GraphError, "sum to 1"),
        (dict(adjacency=RING4 & ~np.eye(4, k=1, dtype=bool)), edccif.GraphError, "asymmetric"),
        (dict(dt=0.0), edccif.ParameterError, "dt"),
        (dict(bogus=1), edccif.UnknownOptionError, "bogus"),
        (dict(sensors=[models.LinearMeasurement(np.eye(3), np.eye(3))] * 2), edccif.ShapeError, "sensors"),
    ]
    for kw, err, msg in cases:
        args = dict(motion=ct, sensors=sensors, algorithm="edc-cif", x0=x0, P0=p0)
        args.update(kw)
        with pytest.raises(err, match=msg):
            edccif.ModelNetwork(args.pop("motion"), args.pop("sensors"), args.pop("algorithm"), **args)
    net = edccif.ModelNetwork(ct, sensors, x0=x0, P0=p0)
    with pytest.raises(edccif.ParameterError, match="no time step"):
        net.step([None] * 4)


def test_reset_node_and_t0_errors(sc4):
    ct, sensors = _builtins(sc4)
    net = edccif.ModelNetwork(ct, sensors, x0=sc4.x0, P0=sc4.p0, dt=0.1)
    est = net.estimates
    for args, err, msg in [
        ((9, sc4.x0, sc4.p0), edccif.ParameterError, "node index"),
        ((0, sc4.x0[:6], sc4.p0), edccif.ShapeError, "x"),
        ((0, sc4.x0, -sc4.p0), edccif.NotPositiveDefiniteError, "positive definite"),
        ((0, np.full(7, np.nan), sc4.p0), edccif.NonFiniteError, "x"),
    ]:
        with pytest.raises(err, match=msg):
            net.reset_node(*args)
        np.testing.assert_array_equal(net.estimates, est)
    net.reset_node(2, sc4.x0 + 1.0, sc4.p0)
    np.testing.assert_array_equal(net.estimates[2], sc4.x0 + 1.0)
    with pytest.raises(edccif.NonFiniteError, match="t0"):
        edccif.ModelNetwork(ct, sensors, x0=sc4.x0, P0=sc4.p0, t0=np.nan)
    with pytest.raises(edccif.NonFiniteError, match="t0"):
        edccif.Network(sc4, t0=np.inf)
    with pytest.raises(edccif.NonFiniteError, match="t0"):
        edccif.run("edc-cif", sc4, np.zeros((2, 4, 3)), t=[0.1, 0.2], t0=np.nan)
