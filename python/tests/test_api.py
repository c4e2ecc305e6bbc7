"""Shapes, dtypes, determinism, streaming ≡ batch, CI against numpy, TOML round trip."""

import numpy as np
import pytest

import edccif


def test_scenario_attributes(sc4):
    assert sc4.nodes == 4 and sc4.steps == 200 and sc4.dt == 0.1 and sc4.state_dim == 7
    assert sc4.sensors.shape == (4, 3) and sc4.sensors.dtype == np.float64
    np.testing.assert_allclose(sc4.sensors[1], [0.0, 10.0, 3.0], atol=1e-12)
    adj = sc4.adjacency
    assert adj.dtype == np.bool_ and adj.shape == (4, 4)
    assert adj.sum() == 8 and not adj.diagonal().any() and (adj == adj.T).all()
    np.testing.assert_allclose(sc4.weights.sum(axis=1), 1.0)
    assert (sc4.delta, sc4.sigma1, sc4.sigma2) == (0.04, 5e-4, 5e-4)
    assert sc4.consensus_iters == 5
    assert edccif.Scenario.paper(nodes=8).consensus_iters == 22
    np.testing.assert_allclose(np.diag(sc4.p0), [0.01] * 6 + [1e-4])


def test_replace_and_toml_roundtrip(sc4, tmp_path):
    s2 = sc4.replace(delta=0.02, steps=50, q1=0.3, topology="complete")
    assert (s2.delta, s2.steps, s2.motion["q1"]) == (0.02, 50, 0.3)
    assert s2.adjacency.sum() == 12
    assert sc4.delta == 0.04  # original untouched
    path = tmp_path / "s.toml"
    s2.save_toml(path)
    assert edccif.Scenario.from_toml(path) == s2
    assert edccif.Scenario.from_toml_str(s2.to_toml()) == s2
    assert edccif.Scenario.from_dict(s2.to_dict()) == s2


def test_simulate_shapes_and_seeding(sc4):
    truth, z, x0 = sc4.simulate(seed=0)
    assert truth.shape == (200, 7) and z.shape == (200, 4, 3) and x0.shape == (7,)
    assert truth.dtype == z.dtype == x0.dtype == np.float64
    t2, z2, x2 = sc4.simulate(seed=0)
    np.testing.assert_array_equal(z, z2)
    np.testing.assert_array_equal(x0, x2)
    assert not np.array_equal(z, sc4.simulate(seed=1)[1])
    # angles wrapped to [-pi, pi)
    assert (z[:, :, 1:] >= -np.pi).all() and (z[:, :, 1:] < np.pi).all()


@pytest.mark.parametrize("alg", edccif.ALGORITHMS)
def test_run_every_row(alg, sc4, sim4):
    truth, z, x0 = sim4
    res = edccif.run(alg, sc4, z, x0=x0)
    assert res.algorithm == alg
    assert res.estimates.shape == (200, 4, 7) and res.estimates.dtype == np.float64
    assert res.covariances.shape == (200, 4, 7, 7)
    assert res.triggered.shape == (200, 4) and res.triggered.dtype == np.bool_
    assert np.isfinite(res.estimates).all()
    assert 0.0 < res.trigger_rate <= 1.0
    err = np.linalg.norm(res.estimates[:, :, :3] - truth[:, None, :3], axis=2)
    assert err.mean() < 0.5, f"{alg}: mean position error {err.mean():.3f} m"
    # covariances symmetric positive definite
    P = res.covariances[-1]
    np.testing.assert_allclose(P, np.swapaxes(P, 1, 2), atol=1e-12)
    assert (np.linalg.eigvalsh(P) > 0).all()
    sent = res.values_sent
    assert sent["sensor_to_estimator"] == 3 * int(res.triggered.sum())


def test_run_is_deterministic(sc4, sim4):
    _, z, x0 = sim4
    a = edccif.run("edc-cif", sc4, z, x0=x0)
    b = edccif.run("edc-cif", sc4, z, x0=x0)
    np.testing.assert_array_equal(a.estimates, b.estimates)


def test_forced_trigger_equals_dc_cif(sc4, sim4):
    _, z, x0 = sim4
    a = edccif.run("edc-cif", sc4, z, x0=x0, force_trigger=True)
    b = edccif.run("dc-cif", sc4, z, x0=x0)
    np.testing.assert_allclose(a.estimates, b.estimates, rtol=0, atol=1e-12)


def test_network_step_equals_run(sc4, sim4):
    _, z, x0 = sim4
    for alg in ("edc-cif", "ec-ckf"):
        res = edccif.run(alg, sc4, z, x0=x0)
        net = edccif.Network(sc4, algorithm=alg, x0=x0)
        for k in range(z.shape[0]):
            est = net.step(z[k])
            np.testing.assert_array_equal(est, res.estimates[k])
        assert net.counters["triggered"] == int(res.triggered.sum())


def test_missing_measurements(sc4, sim4):
    _, z, x0 = sim4
    z = z.copy()
    z[50:70, 1, :] = np.nan  # node 1's sensor is dark for 2 s
    res = edccif.run("edc-cif", sc4, z, x0=x0)
    assert not res.measured[50:70, 1].any() and res.measured[70:, 1].all()
    assert not res.triggered[50:70, 1].any()
    assert np.isfinite(res.estimates).all()


def test_options_change_behaviour(sc4, sim4):
    _, z, x0 = sim4
    lo = edccif.run("edc-cif", sc4, z, x0=x0, delta=0.01).trigger_rate
    hi = edccif.run("edc-cif", sc4, z, x0=x0, delta=0.1).trigger_rate
    assert lo > hi
    hold = edccif.run("edc-cif", sc4, z, x0=x0, et_policy="hold")
    opt = edccif.run("edc-cif", sc4, z, x0=x0)
    assert not np.array_equal(hold.estimates, opt.estimates)
    np.testing.assert_array_equal(hold.triggered, opt.triggered)
    c1 = edccif.run("ec-ckf", sc4, z, x0=x0, consensus_iters=1)
    c5 = edccif.run("ec-ckf", sc4, z, x0=x0)
    assert c1.values_sent["estimator_to_estimator"] * 5 == c5.values_sent["estimator_to_estimator"]


def _ci_numpy(xs, Ps, w):
    Y = sum(wi * np.linalg.inv(P) for wi, P in zip(w, Ps))
    y = sum(wi * np.linalg.inv(P) @ x for wi, x, P in zip(w, xs, Ps))
    P = np.linalg.inv(Y)
    return P @ y, P


def test_ci_fuse_against_numpy():
    rng = np.random.default_rng(0)
    K, n = 3, 4
    xs = rng.normal(size=(K, n))
    A = rng.normal(size=(K, n, n))
    Ps = A @ np.swapaxes(A, 1, 2) + n * np.eye(n)
    x, P, w = edccif.ci_fuse(xs, Ps)
    xr, Pr = _ci_numpy(xs, Ps, np.full(K, 1 / K))
    np.testing.assert_allclose(x, xr, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P, Pr, rtol=1e-10, atol=1e-12)
    w_in = np.array([0.2, 0.5, 0.3])
    x, P, w = edccif.ci_fuse(xs, Ps, weights=w_in)
    xr, Pr = _ci_numpy(xs, Ps, w_in)
    np.testing.assert_allclose(x, xr, rtol=1e-10, atol=1e-12)
    for crit, f in (("trace", np.trace), ("det", np.linalg.det)):
        x, P, w = edccif.ci_fuse(xs, Ps, weights=crit)
        assert w.shape == (K,) and abs(w.sum() - 1) < 1e-12 and (w >= 0).all()
        xr, Pr = _ci_numpy(xs, Ps, w)
        np.testing.assert_allclose(P, Pr, rtol=1e-9, atol=1e-12)
        assert f(P) <= f(_ci_numpy(xs, Ps, np.full(K, 1 / K))[1]) * (1 + 1e-12)


def test_monte_carlo_structure(sc4):
    sc = sc4.replace(steps=40)
    mc = edccif.monte_carlo(sc, ["edc-cif", {"label": "hold", "algorithm": "edc-cif", "et_policy": "hold"}],
                            runs=4, seed=1, progress=False)
    assert mc.labels == ["EDC-CIF", "hold"]
    assert mc.rmse["EDC-CIF"].shape == (7,)
    assert mc.pos_rmse_curve["hold"].shape == (40,)
    assert 0 < mc.trigger_rate["EDC-CIF"] < 1
    assert "| EDC-CIF |" in mc.to_markdown()
    d = mc.to_dict()
    assert d["runs"] == 4 and len(d["variants"]) == 2
    again = edccif.monte_carlo(sc, ["edc-cif"], runs=4, seed=1, progress=False)
    np.testing.assert_array_equal(again.rmse["EDC-CIF"], mc.rmse["EDC-CIF"])
