"""Each error path: a ValueError subclass naming the argument, what was expected and
what was received; state unchanged after an error."""

import numpy as np
import pytest

import edccif


def test_hierarchy():
    for cls in (edccif.ShapeError, edccif.NonFiniteError, edccif.NotPositiveDefiniteError,
                edccif.GraphError, edccif.ScenarioError, edccif.ParameterError,
                edccif.UnknownAlgorithmError, edccif.UnknownOptionError):
        assert issubclass(cls, edccif.EdccifError) and issubclass(cls, ValueError)


def test_replay_bad_values(tmp_path):
    sc = edccif.Scenario.from_dict({
        "name": "pos", "dt": 0.1, "steps": 10, "delta": 3e-4, "sigma1": 5e-4, "sigma2": 5e-4,
        "x0": [5.0, 0.0, 1.0, 0.0, 1.5, 0.1], "p0_diag": [0.01] * 6, "sensors": [[0.0, 0.0, 0.0]] * 2,
        "motion": {"kind": "constant-velocity", "q": 0.5}, "measurement": {"kind": "position", "sigma": [0.05] * 3},
        "topology": {"kind": "line"},
    })
    edccif.record("edc-cif", sc, mcap=tmp_path / "r.mcap", ros2=True)
    topics = ["/node0/point", "/node1/point"]
    ok = edccif.replay(tmp_path / "r.mcap", measurements=topics)
    assert ok.report["input"]["frame"] == "world"
    for kw, cls, text in [
        ({"noise": "loud"}, edccif.ParameterError, "noise"),
        ({"noise": "0"}, edccif.ParameterError, "noise"),
        ({"same_frames": ["world"]}, edccif.ParameterError, "same_frames"),
        ({"rate_hz": 0.0}, edccif.ParameterError, "rate_hz"),
        ({"frame": "nowhere"}, edccif.ParameterError, "`nowhere`"),
        ({"motion": edccif.models.ConstantVelocity(3, 0.5)}, edccif.ParameterError, "motion and sensors"),
        ({"sensors": [edccif.models.Position([0.1] * 3)] * 3, "motion": edccif.models.ConstantVelocity(3, 0.5)},
         edccif.ShapeError, "one per source"),
        ({"sensors": [edccif.models.RangeOnly([0.0, 0.0, 0.0], 0.1)] * 2,
          "motion": edccif.models.ConstantVelocity(3, 0.5)}, edccif.ShapeError, "measures 1 values"),
        ({"motion": edccif.models.RandomWalk(6, 0.1), "sensors": [edccif.models.Position([0.1] * 3)] * 2},
         edccif.ParameterError, "x0, P0"),
        ({"threads": 2}, edccif.ParameterError, "threads"),
        ({"override": True}, edccif.ParameterError, "override"),
    ]:
        with pytest.raises(cls, match=text):
            edccif.replay(tmp_path / "r.mcap", measurements=topics, **kw)
    with pytest.raises(edccif.ParameterError, match="not both"):
        edccif.replay(tmp_path / "r.mcap", sc, measurements=topics, motion=edccif.models.ConstantVelocity(3, 0.5),
                      sensors=[edccif.models.Position([0.1] * 3)] * 2)
    with pytest.raises(edccif.ParameterError, match="only with measurements"):
        edccif.replay(tmp_path / "r.mcap", frame="map")


def test_unknown_algorithm(sc4, sim4):
    with pytest.raises(edccif.UnknownAlgorithmError, match=r'"edc".*edc-cif'):
        edccif.run("edc", sc4, sim4[1])


def test_unknown_option(sc4, sim4):
    with pytest.raises(edccif.UnknownOptionError, match="deltaa"):
        edccif.run("edc-cif", sc4, sim4[1], deltaa=0.1)
    with pytest.raises(edccif.UnknownOptionError, match="et_policy=greedy"):
        edccif.run("edc-cif", sc4, sim4[1], et_policy="greedy")


@pytest.mark.parametrize("z_shape", [(200, 3), (200, 4, 2), (200,), (4, 3)])
def test_bad_z_shape(sc4, z_shape):
    with pytest.raises(edccif.ShapeError, match=r"z: expected shape \(T, 4, 3\)"):
        edccif.run("edc-cif", sc4, np.zeros(z_shape))


def test_one_dimensional_z_is_not_broadcast(sc4):
    net = edccif.Network(sc4)
    with pytest.raises(edccif.ShapeError, match=r"z: expected shape \(4, 3\), got \(3,\)"):
        net.step(np.array([1.0, 0.1, 0.2]))


def test_bad_dtype(sc4):
    with pytest.raises(edccif.ShapeError, match="z"):
        edccif.run("edc-cif", sc4, np.array([["a", "b", "c"]] * 4))


def test_bad_x0(sc4, sim4):
    with pytest.raises(edccif.ShapeError, match=r"x0: expected shape \(7,\), got \(6,\)"):
        edccif.run("edc-cif", sc4, sim4[1], x0=np.zeros(6))
    with pytest.raises(edccif.NonFiniteError, match="x0"):
        edccif.run("edc-cif", sc4, sim4[1], x0=np.full(7, np.nan))


def test_partial_nan_and_inf_measurement(sc4, sim4):
    z = sim4[1].copy()
    z[10, 2, 0] = np.nan
    with pytest.raises(edccif.ParameterError, match="node 2"):
        edccif.run("edc-cif", sc4, z)
    z = sim4[1].copy()
    z[10, 2, :] = np.inf
    with pytest.raises(edccif.ParameterError, match="node 2"):
        edccif.run("edc-cif", sc4, z)


@pytest.mark.parametrize("key,value", [("delta", 0.0), ("sigma1", -1.0), ("sigma2", np.nan)])
def test_bad_parameters(sc4, sim4, key, value):
    with pytest.raises(edccif.ParameterError, match=key):
        edccif.run("edc-cif", sc4, sim4[1], **{key: value})
    with pytest.raises(edccif.ScenarioError, match=key):
        sc4.replace(**{key: value})


def test_bad_scenario_values(sc4):
    with pytest.raises(edccif.ScenarioError, match="dt"):
        sc4.replace(dt=-0.1)
    with pytest.raises(edccif.UnknownOptionError, match="nodez"):
        sc4.replace(nodez=3)
    with pytest.raises(edccif.ScenarioError, match="x0"):
        sc4.replace(x0=[0.0] * 6)


def test_bad_graphs(sc4):
    disconnected = np.zeros((4, 4), dtype=bool)
    disconnected[0, 1] = disconnected[1, 0] = True
    with pytest.raises(edccif.GraphError, match="disconnected"):
        sc4.replace(topology=disconnected)
    asym = ~np.eye(4, dtype=bool)
    asym[0, 1] = False
    with pytest.raises(edccif.GraphError, match="asymmetric"):
        sc4.replace(topology=asym)
    loop = ~np.eye(4, dtype=bool)
    loop[2, 2] = True
    with pytest.raises(edccif.GraphError, match="self-loop"):
        sc4.replace(topology=loop)


def test_scenario_file_errors(sc4, tmp_path):
    text = sc4.to_toml().replace("steps = 200", "stepz = 200")
    with pytest.raises(edccif.ScenarioError, match=r"(?s)stepz.*line|line.*stepz"):
        edccif.Scenario.from_toml_str(text)
    text = sc4.to_toml().replace("steps = 200", 'steps = "many"')
    with pytest.raises(edccif.ScenarioError, match="steps"):
        edccif.Scenario.from_toml_str(text)
    with pytest.raises(edccif.ScenarioError, match="cannot read"):
        edccif.Scenario.from_toml(tmp_path / "missing.toml")


def test_ci_fuse_errors():
    xs = np.zeros((2, 3))
    Ps = np.stack([np.eye(3), np.eye(3)])
    with pytest.raises(edccif.ShapeError, match=r"Ps: expected shape \(2, 3, 3\)"):
        edccif.ci_fuse(xs, Ps[:, :2, :2])
    bad = Ps.copy()
    bad[1] = -np.eye(3)
    with pytest.raises(edccif.NotPositiveDefiniteError, match=r"Ps\[1\]"):
        edccif.ci_fuse(xs, bad)
    with pytest.raises(edccif.ParameterError, match="weights"):
        edccif.ci_fuse(xs, Ps, weights="best")


def test_network_state_unchanged_after_error(sc4, sim4):
    _, z, x0 = sim4
    net = edccif.Network(sc4, "edc-cif", x0=x0)
    net.step(z[0])
    before = net.estimates.copy(), net.covariances.copy(), dict(net.counters)
    bad = z[1].copy()
    bad[0, 0] = np.inf
    with pytest.raises(edccif.EdccifError):
        net.step(bad)
    with pytest.raises(edccif.ShapeError):
        net.step(z[1][:3])
    np.testing.assert_array_equal(net.estimates, before[0])
    np.testing.assert_array_equal(net.covariances, before[1])
    assert net.counters == before[2]
    # and it continues exactly as a network that never saw the errors
    ref = edccif.Network(sc4, "edc-cif", x0=x0)
    ref.step(z[0])
    np.testing.assert_array_equal(net.step(z[1]), ref.step(z[1]))
