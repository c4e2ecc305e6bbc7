"""Timestamps (non-uniform steps, sensors at different rates) and networks with
their own adjacency and combination weights, on the scenario path."""

import numpy as np
import pytest

import edccif

RING5 = np.array(
    [[0, 1, 0, 0, 1], [1, 0, 1, 0, 0], [0, 1, 0, 1, 0], [0, 0, 1, 0, 1], [1, 0, 0, 1, 0]],
    dtype=bool,
)
# symmetric, rows sum to 1, > 0 exactly on the ring's edges
METRO5 = np.where(RING5, 1.0 / 3.0, 0.0) + np.eye(5) / 3.0


def _times(steps, seed=0):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(0.05, 0.2, size=steps))


@pytest.fixture(scope="module")
def sc5():
    return edccif.Scenario.paper(nodes=5).replace(steps=60)


@pytest.fixture(scope="module")
def sim5(sc5):
    return sc5.simulate(seed=2)


@pytest.mark.parametrize("alg", edccif.ALGORITHMS)
def test_streaming_with_timestamps_equals_run(alg, sc4, sim4):
    _, z, x0 = sim4
    z = z[:40]
    t = _times(40)
    res = edccif.run(alg, sc4, z, x0=x0, t=t)
    net = edccif.Network(sc4, alg, x0=x0)
    for k in range(40):
        est = net.step(z[k], t=t[k])
        # bit for bit: the same dt enters the same step
        np.testing.assert_array_equal(est, res.estimates[k])
    assert net.t == t[-1]
    # dt= gives the same as t= (dt from the same differences)
    net2 = edccif.Network(sc4, alg, x0=x0)
    dts = np.diff(np.concatenate([[0.0], t]))
    for k in range(40):
        net2.step(z[k], dt=dts[k])
    np.testing.assert_array_equal(net2.estimates, res.estimates[-1])


def test_uniform_dt_equals_nominal(sc4, sim4):
    _, z, x0 = sim4
    res = edccif.run("edc-cif", sc4, z[:30], x0=x0)
    net = edccif.Network(sc4, "edc-cif", x0=x0)
    for k in range(30):
        net.step(z[k], dt=sc4.dt)
    np.testing.assert_array_equal(net.estimates, res.estimates[29])
    assert net.t == pytest.approx(30 * sc4.dt, abs=1e-12)


def test_non_uniform_steps_change_the_estimate(sc4, sim4):
    _, z, x0 = sim4
    t = np.arange(1, 31) * sc4.dt
    t[10:] += 0.3  # one long gap
    a = edccif.run("edc-cif", sc4, z[:30], x0=x0)
    b = edccif.run("edc-cif", sc4, z[:30], x0=x0, t=t)
    # k*0.1 - (k-1)*0.1 is 0.1 only to rounding: equal to 1e-12 before the gap
    np.testing.assert_allclose(a.estimates[:10], b.estimates[:10], rtol=0, atol=1e-12)
    assert np.abs(a.estimates[10] - b.estimates[10]).max() > 1e-6


def test_process_noise_scales_with_dt(sc4, sim4):
    # without measurements the covariance grows by Q(dt): a longer step grows it more
    _, _, x0 = sim4
    z = np.full((1, 4, 3), np.nan)
    small = edccif.run("d-cif", sc4, z, x0=x0, t=[0.1])
    large = edccif.run("d-cif", sc4, z, x0=x0, t=[0.5])
    tr = lambda r: np.trace(r.covariances[0, 0])  # noqa: E731
    assert tr(large) > tr(small) > np.trace(sc4.p0)


def test_sensors_at_different_rates(sc4, sim4):
    # node 1 measures at a third of the rate, node 3 never: both predict and still fuse
    truth, z, x0 = sim4
    z = z.copy()
    z[np.arange(len(z)) % 3 != 0, 1] = np.nan
    z[:, 3] = np.nan
    res = edccif.run("edc-cif", sc4, z, x0=x0)
    assert not res.measured[:, 3].any()
    assert res.measured[:, 1].sum() == (len(z) + 2) // 3
    err = np.linalg.norm(res.estimates[:, 3, :3] - truth[:, :3], axis=1)
    assert np.isfinite(res.estimates).all()
    # node 3 has no sensor but follows the target through fusion (tolerance 1 m)
    assert err[20:].mean() < 1.0


def test_time_errors_name_the_index(sc4, sim4):
    _, z, x0 = sim4
    t = _times(10)
    bad = t.copy()
    bad[3] = bad[2]
    with pytest.raises(edccif.ParameterError, match=r"t\[3\]"):
        edccif.run("edc-cif", sc4, z[:10], x0=x0, t=bad)
    bad = t.copy()
    bad[2] = np.nan
    with pytest.raises(edccif.NonFiniteError, match=r"t\[2\]"):
        edccif.run("edc-cif", sc4, z[:10], x0=x0, t=bad)
    with pytest.raises(edccif.ShapeError, match=r"t: expected shape \(10,\)"):
        edccif.run("edc-cif", sc4, z[:10], x0=x0, t=t[:9])
    with pytest.raises(edccif.ParameterError, match=r"t\[0\]"):
        edccif.run("edc-cif", sc4, z[:10], x0=x0, t=t, t0=t[0])


def test_step_time_errors_leave_the_network_unchanged(sc4, sim4):
    _, z, x0 = sim4
    net = edccif.Network(sc4, "edc-cif", x0=x0)
    net.step(z[0], t=0.2)
    est, cov, t = net.estimates, net.covariances, net.t
    cases = [
        (dict(t=0.2), edccif.ParameterError, "strictly increasing"),
        (dict(t=0.1), edccif.ParameterError, "strictly increasing"),
        (dict(t=np.nan), edccif.NonFiniteError, "t:"),
        (dict(dt=0.0), edccif.ParameterError, "dt"),
        (dict(dt=-0.1), edccif.ParameterError, "dt"),
        (dict(dt=np.inf), edccif.ParameterError, "dt"),
        (dict(t=0.3, dt=0.1), edccif.ParameterError, "not both"),
    ]
    for kw, err, msg in cases:
        with pytest.raises(err, match=msg):
            net.step(z[1], **kw)
        np.testing.assert_array_equal(net.estimates, est)
        np.testing.assert_array_equal(net.covariances, cov)
        assert net.t == t
    # and it still steps as if nothing happened
    ref = edccif.Network(sc4, "edc-cif", x0=x0)
    ref.step(z[0], t=0.2)
    np.testing.assert_array_equal(net.step(z[1], t=0.35), ref.step(z[1], t=0.35))


@pytest.mark.parametrize("alg", ["edc-cif", "ec-ckf"])
def test_network_with_own_adjacency_equals_scenario_topology(alg, sc5, sim5):
    _, z, x0 = sim5
    line = np.zeros((5, 5), dtype=bool)
    for i in range(4):
        line[i, i + 1] = line[i + 1, i] = True
    res = edccif.run(alg, sc5.replace(topology=line), z, x0=x0)
    net = edccif.Network(sc5, alg, x0=x0, adjacency=line)
    for k in range(len(z)):
        net.step(z[k])
    np.testing.assert_array_equal(net.estimates, res.estimates[-1])
    np.testing.assert_array_equal(net.weights, sc5.replace(topology=line).weights)
    # a different graph gives different estimates
    ring = edccif.run(alg, sc5, z, x0=x0)
    assert np.abs(ring.estimates[-1] - res.estimates[-1]).max() > 1e-9


@pytest.mark.parametrize("alg", ["edc-cif", "ec-ckf", "d-cif"])
def test_network_with_own_weights(alg, sc5, sim5):
    _, z, x0 = sim5
    custom = sc5.replace(weights=METRO5)
    np.testing.assert_array_equal(custom.weights, METRO5)
    np.testing.assert_array_equal(custom.adjacency, RING5)
    # max-degree weights of a ring are 1/3 too: the same numbers through both paths
    np.testing.assert_allclose(sc5.weights, METRO5, atol=1e-15)
    res = edccif.run(alg, custom, z, x0=x0)
    net = edccif.Network(sc5, alg, x0=x0, weights=METRO5)
    net_a = edccif.Network(sc5, alg, x0=x0, adjacency=RING5, weights=METRO5)
    for k in range(len(z)):
        net.step(z[k])
        net_a.step(z[k])
    np.testing.assert_array_equal(net.estimates, res.estimates[-1])
    np.testing.assert_array_equal(net_a.estimates, res.estimates[-1])
    # other weights on the same graph change the result
    lazy = np.where(RING5, 0.1, 0.0) + np.eye(5) * 0.8
    other = edccif.run(alg, sc5.replace(weights=lazy), z, x0=x0)
    assert np.abs(other.estimates[-1] - res.estimates[-1]).max() > 1e-9
    # the adequate consensus iterations follow the weights
    assert sc5.replace(weights=lazy).consensus_iters > sc5.consensus_iters


def test_custom_weights_roundtrip_through_toml_and_dict(sc5):
    custom = sc5.replace(weights=METRO5)
    assert edccif.Scenario.from_toml_str(custom.to_toml()) == custom
    assert edccif.Scenario.from_dict(custom.to_dict()) == custom
    assert custom.topology["kind"] == "custom"


def test_bad_graph_inputs(sc5, sim5):
    _, z, x0 = sim5
    disconnected = np.eye(5)
    asym = METRO5.copy()
    asym[0, 1], asym[0, 0] = 0.5, 1.0 / 6.0
    not_stochastic = METRO5 * 1.1
    negative = METRO5.copy()
    negative[0, 0] = -0.1
    negative[0, 1] = negative[1, 0] = 1.1 / 3.0 + 0.1
    off_edge = METRO5.copy()
    off_edge[0, 2] = off_edge[2, 0] = 0.1
    off_edge[0, 0] -= 0.1
    off_edge[2, 2] -= 0.1
    cases = [
        (dict(weights=disconnected), edccif.GraphError, "disconnected"),
        (dict(weights=asym), edccif.GraphError, "symmetric"),
        (dict(weights=not_stochastic), edccif.GraphError, "sum to 1"),
        (dict(weights=negative), edccif.GraphError, ">= 0"),
        (dict(adjacency=RING5, weights=off_edge), edccif.GraphError, "not neighbours"),
        (dict(adjacency=RING5 & False), edccif.GraphError, "disconnected"),
        (dict(adjacency=~np.eye(5, dtype=bool) & ~np.eye(5, k=1, dtype=bool)), edccif.GraphError, "asymmetric"),
        (dict(weights=np.full((5, 5), np.nan)), edccif.NonFiniteError, "weights"),
        (dict(weights=np.eye(4)), edccif.ShapeError, r"weights: expected shape \(5, 5\)"),
        (dict(adjacency=np.ones((5, 4))), edccif.ShapeError, "adjacency"),
    ]
    for kw, err, msg in cases:
        with pytest.raises(err, match=msg):
            edccif.Network(sc5, "edc-cif", x0=x0, **kw)
        if "adjacency" not in kw:
            with pytest.raises(err, match=msg):
                sc5.replace(**kw)
    # the scenario is unchanged by the failed replacements
    assert sc5 == edccif.Scenario.paper(nodes=5).replace(steps=60)
