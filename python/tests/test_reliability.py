"""Fault injection and the innovation gate from Python, and bad-input cases not
covered by test_errors.py."""

import numpy as np
import pytest

import edccif


def test_run_with_faults(sc4, sim4):
    truth, z, x0 = sim4
    plain = edccif.run("edc-cif", sc4, z, x0=x0)
    same = edccif.run("edc-cif", sc4, z, x0=x0, faults={})
    np.testing.assert_array_equal(plain.estimates, same.estimates)
    f = dict(seed=1, message_loss=0.3, outlier_prob=0.05,
             dropout=[(1, 66, 133)], outage=[(0, 100, 120)])
    a = edccif.run("edc-cif", sc4, z, x0=x0, faults=f, gate=16.27)
    b = edccif.run("edc-cif", sc4, z, x0=x0, faults=f, gate=16.27)
    np.testing.assert_array_equal(a.estimates, b.estimates)
    assert np.isfinite(a.estimates).all() and np.isfinite(a.covariances).all()
    assert np.all(np.linalg.eigvalsh(a.covariances) > 0)
    assert a.gated > 0 and plain.gated == 0
    assert not a.measured[100:120, 0].any() and not a.measured[66:133, 1].any()
    # node 1 is frozen while down
    np.testing.assert_array_equal(a.estimates[66:133, 1], np.broadcast_to(a.estimates[65, 1], (67, 7)))
    assert a.values_sent["estimator_to_estimator"] < plain.values_sent["estimator_to_estimator"]


def test_gate_rejects_outliers(sc4, sim4):
    truth, z, x0 = sim4
    f = dict(seed=2, outlier_prob=0.05)
    bad = edccif.run("ec-ckf", sc4, z, x0=x0, faults=f)
    good = edccif.run("ec-ckf", sc4, z, x0=x0, faults=f, gate=16.27)
    def err(r):
        return np.linalg.norm(r.estimates[:, :, :3] - truth[:, None, :3], axis=2).mean()
    assert good.gated > 0 and err(good) < err(bad)


def test_bad_faults(sc4, sim4):
    _, z, _ = sim4
    with pytest.raises(edccif.UnknownOptionError, match="message_los"):
        edccif.run("edc-cif", sc4, z, faults={"message_los": 0.1})
    with pytest.raises(edccif.ParameterError, match="message_loss"):
        edccif.run("edc-cif", sc4, z, faults={"message_loss": 2.0})
    with pytest.raises(edccif.ParameterError, match=r"dropout\[0\].node"):
        edccif.run("edc-cif", sc4, z, faults={"dropout": [(7, 0, 10)]})
    with pytest.raises(edccif.ParameterError, match="faults"):
        edccif.run("edc-cif", sc4, z, faults={"outage": "soon"})
    with pytest.raises(edccif.ParameterError, match="gate"):
        edccif.run("edc-cif", sc4, z, gate=-1.0)


@pytest.mark.parametrize("key", ["dt", "delta", "sigma1", "sigma2"])
@pytest.mark.parametrize("value", [0.0, -1.0, np.inf])
def test_zero_negative_and_infinite_parameters(sc4, key, value):
    with pytest.raises(edccif.ScenarioError, match=key):
        sc4.replace(**{key: value})


def test_bad_initial_covariance_and_state(sc4):
    with pytest.raises(edccif.ScenarioError, match="p0_diag"):
        sc4.replace(p0_diag=[0.01, 0.01, np.nan, 0.01, 0.01, 0.01, 1e-4])
    with pytest.raises(edccif.ScenarioError, match=r"p0_diag\[0\]"):
        sc4.replace(p0_diag=[-0.01] + [0.01] * 6)
    with pytest.raises(edccif.ScenarioError, match="x0"):
        sc4.replace(x0=[5.0, np.inf, 1.0, 0.0, 1.5, 0.1, 0.3])


def test_reset_node_rejects_bad_covariances_and_keeps_state(sc4, sim4):
    _, z, x0 = sim4
    net = edccif.Network(sc4, "edc-cif", x0=x0)
    net.step(z[0])
    before = net.estimates.copy(), net.covariances.copy()
    asym = np.eye(7)
    asym[0, 1] = 0.5
    with pytest.raises(edccif.NotPositiveDefiniteError, match="symmetric"):
        net.reset_node(1, np.zeros(7), asym)
    with pytest.raises(edccif.NotPositiveDefiniteError):
        net.reset_node(1, np.zeros(7), -np.eye(7))
    with pytest.raises(edccif.NonFiniteError):
        net.reset_node(1, np.full(7, np.nan), np.eye(7))
    with pytest.raises(edccif.ShapeError):
        net.reset_node(1, np.zeros(7), np.eye(6))
    with pytest.raises(edccif.ParameterError, match="out of range"):
        net.reset_node(9, np.zeros(7), np.eye(7))
    np.testing.assert_array_equal(net.estimates, before[0])
    np.testing.assert_array_equal(net.covariances, before[1])


def test_bad_masks(sc4, sim4):
    _, z, x0 = sim4
    net = edccif.Network(sc4, "edc-cif", x0=x0)
    with pytest.raises(edccif.ShapeError, match="links"):
        net.step(z[0], links=np.ones(4, dtype=bool))
    with pytest.raises(edccif.ShapeError, match="active"):
        net.step(z[0], active=np.ones((4, 4), dtype=bool))
    with pytest.raises(edccif.ShapeError, match="z"):
        net.step(z[0].ravel())
    assert net.counters["steps"] == 0


def test_scenario_file_wrong_type_names_key_and_line(sc4):
    text = sc4.to_toml().replace("delta = 0.04", 'delta = "small"')
    with pytest.raises(edccif.ScenarioError, match=r"(?s)line \d+.*delta|delta.*line \d+"):
        edccif.Scenario.from_toml_str(text)
