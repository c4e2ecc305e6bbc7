"""One network class for every scenario: `edccif.Network(scenario, ...)` on a
per-node scenario (`[[nodes]]`: sensors of their own kinds and sizes, a Python
motion model) steps on the model network and gives `edccif.run`'s numbers bit for
bit, step by step and as a whole run; `ModelNetwork` is a `Network`."""

import pathlib

import numpy as np
import pytest

import edccif
from edccif import models

ROOT = pathlib.Path(__file__).resolve().parents[2]
PER_NODE = ["mixed-3d", "bearing-only-2d", "custom-turn-2d"]
ROWS = ["edc-cif", "ec-ckf", "dc-cif"]


def _scenario(stem, steps=40):
    sc = edccif.Scenario.from_toml(str(ROOT / "scenarios" / f"{stem}.toml"))
    # mixed-3d's node 4 measures at given times up to 19 s, which a shorter
    # run refuses
    return sc.replace(steps=200 if stem == "mixed-3d" else steps)


@pytest.mark.parametrize("alg", ROWS)
@pytest.mark.parametrize("stem", PER_NODE)
def test_a_per_node_scenario_steps_as_run_bit_for_bit(stem, alg):
    sc = _scenario(stem)
    truth, z, x0 = sc.simulate(seed=3)
    ref = edccif.run(alg, sc, z, x0=x0)
    net = edccif.Network(sc, alg, x0)
    assert net.meas_dims == list(sc.meas_dims) and net.nodes == sc.nodes and net.state_dim == sc.state_dim
    assert z.shape == (sc.steps, sum(sc.meas_dims))
    for t in range(sc.steps):
        est = net.step(z[t])
        np.testing.assert_array_equal(est, ref.estimates[t], err_msg=f"{stem} {alg} step {t}")
        np.testing.assert_array_equal(net.covariances, ref.covariances[t], err_msg=f"{stem} {alg} step {t}")
        np.testing.assert_array_equal(net.triggered, ref.triggered[t], err_msg=f"{stem} {alg} step {t}")
    assert net.t == pytest.approx(sc.steps * sc.dt)
    assert net.algorithm == alg
    # a whole run on a fresh network: the same numbers again
    r = edccif.Network(sc, alg, x0).run(z)
    np.testing.assert_array_equal(r.estimates, ref.estimates)
    np.testing.assert_array_equal(r.covariances, ref.covariances)
    np.testing.assert_array_equal(r.triggered, ref.triggered)
    assert r.values_sent == ref.values_sent


@pytest.mark.parametrize("stem", PER_NODE)
def test_per_node_entries_and_the_flat_row_are_the_same_step(stem):
    sc = _scenario(stem, steps=10)
    truth, z, x0 = sc.simulate(seed=1)
    flat, per_node = edccif.Network(sc, "edc-cif", x0), edccif.Network(sc, "edc-cif", x0)
    offsets = np.cumsum([0] + list(sc.meas_dims))
    for t in range(sc.steps):
        entries = [None if np.all(np.isnan(z[t, a:b])) else z[t, a:b] for a, b in zip(offsets, offsets[1:])]
        np.testing.assert_array_equal(flat.step(z[t]), per_node.step(entries))
    with pytest.raises(edccif.ShapeError, match=r"z: expected"):
        flat.step(np.zeros(int(offsets[-1]) + 1))
    with pytest.raises(edccif.ShapeError, match="one measurement per node"):
        flat.step([None])


def test_the_per_node_form_of_the_papers_scenario_gives_the_typed_numbers():
    sc = edccif.Scenario.paper(4).replace(steps=20)
    d = sc.to_dict()
    m = d.pop("measurement")
    positions = d.pop("sensors")
    d["nodes"] = [{"sensor": {"kind": m["kind"], "position": p, **{k: v for k, v in m.items() if k != "kind"}}}
                  for p in positions]
    per_node = edccif.Scenario.from_dict(d)
    truth, z, x0 = sc.simulate(seed=2)
    typed, models_net = edccif.Network(sc, "edc-cif", x0), edccif.Network(per_node, "edc-cif", x0)
    assert models_net.meas_dims == [3, 3, 3, 3]
    for t in range(sc.steps):
        np.testing.assert_array_equal(typed.step(z[t]), models_net.step(z[t].reshape(-1)))
    assert typed.counters == models_net.counters


def test_a_per_node_network_takes_masks_graphs_resets_and_refuses_threads():
    sc = _scenario("bearing-only-2d", steps=6)
    truth, z, x0 = sc.simulate(seed=0)
    k = sc.nodes
    ref = edccif.run("edc-cif", sc, z, x0=x0)
    net = edccif.Network(sc, "edc-cif", x0)
    np.testing.assert_array_equal(net.step(z[0], links=np.ones((k, k), bool), active=np.ones(k, bool)),
                                  ref.estimates[0])
    with pytest.raises(edccif.ShapeError, match="links"):
        net.step(z[1], links=np.ones((k, k + 1), bool))
    np.testing.assert_array_equal(net.estimates, ref.estimates[0]), "a refused step changes nothing"
    w = net.weights
    assert w.shape == (k, k) and np.allclose(w.sum(axis=1), 1.0)
    offsets, indices, weights = net.neighbours
    assert len(offsets) == k + 1 and len(indices) == len(weights) == np.count_nonzero(w)
    assert net.threads == 1
    with pytest.raises(edccif.ParameterError, match="threads"):
        net.threads = 2
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.Network(sc, "edc-cif", x0, threads=2)
    net.reset_node(1, x0 + 0.5, np.eye(sc.state_dim))
    np.testing.assert_array_equal(net.estimates[1], x0 + 0.5)
    with pytest.raises(edccif.ParameterError, match="node index"):
        net.reset_node(k, x0, np.eye(sc.state_dim))
    assert "meas_dims=[1, 1, 1, 2, 1, 1]" in repr(net) and repr(net).startswith("Network(")
    # another graph: the run's numbers on the replaced scenario
    ring = np.roll(np.eye(k, dtype=bool), 1, axis=1) | np.roll(np.eye(k, dtype=bool), -1, axis=1)
    adj = ring | np.roll(np.eye(k, dtype=bool), 2, axis=1) | np.roll(np.eye(k, dtype=bool), -2, axis=1)
    other = edccif.Network(sc, "edc-cif", x0, adjacency=adj)
    ref2 = edccif.run("edc-cif", sc.replace(topology={"kind": "custom", "adjacency": adj.tolist()}), z, x0=x0)
    np.testing.assert_array_equal(np.stack([other.step(zt) for zt in z]), ref2.estimates)


def test_a_network_of_the_papers_kinds_refuses_run_and_says_what_to_use():
    sc = edccif.Scenario.paper(4).replace(steps=3)
    truth, z, x0 = sc.simulate(seed=0)
    net = edccif.Network(sc, "edc-cif", x0)
    assert net.meas_dims == [3] * 4
    with pytest.raises(edccif.ParameterError, match="edccif.run"):
        net.run(z)


def test_model_network_is_a_network_and_from_models_builds_one():
    cv = models.ConstantVelocity(dim=2, q=0.1)
    sensors = [models.Position(sigma=[0.1, 0.1]), models.Position(sigma=[0.2, 0.2])]
    kw = dict(x0=np.zeros(4), P0=np.eye(4), dt=0.1)
    a = edccif.ModelNetwork(cv, sensors, "edc-cif", **kw)
    b = edccif.Network.from_models(cv, sensors, "edc-cif", **kw)
    assert isinstance(a, edccif.Network) and issubclass(edccif.ModelNetwork, edccif.Network)
    assert type(b) is edccif.ModelNetwork
    assert repr(a).startswith("ModelNetwork(")
    zs = [np.array([0.1, 0.2]), np.array([0.15, 0.25])]
    np.testing.assert_array_equal(a.step(zs), b.step(np.concatenate(zs)))
