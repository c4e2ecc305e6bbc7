"""Scenario files: every file in `scenarios/` is valid against the shipped JSON
Schema and round-trips through `from_toml`, `to_toml`, `to_dict`, `from_dict` and
`replace`; unknown keys and values a run would ignore are refused by name; the
per-node files of the model catalogue simulate and run."""

import json
import pathlib

import jsonschema
import numpy as np
import pytest

import edccif

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

ROOT = pathlib.Path(__file__).resolve().parents[2]
FILES = sorted((ROOT / "scenarios").glob("*.toml"))
SCHEMA = json.loads((pathlib.Path(edccif.__file__).parent / "scenario.schema.json").read_text())


def test_there_are_catalogue_files_beside_the_papers():
    names = {f.stem for f in FILES}
    assert {"paper-3", "paper-4", "paper-8", "bearing-only-2d", "mixed-3d"} <= names


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_every_file_is_valid_and_round_trips(path):
    raw = tomllib.loads(path.read_text())
    jsonschema.validate(raw, SCHEMA)
    a = edccif.Scenario.from_toml(str(path))
    b = edccif.Scenario.from_toml_str(a.to_toml())
    assert b.to_toml() == a.to_toml()
    # the parsed file as a dict, and to_dict, give the same scenario
    assert edccif.Scenario.from_dict(raw).to_toml() == a.to_toml()
    assert edccif.Scenario.from_dict(a.to_dict()).to_toml() == a.to_toml()
    jsonschema.validate(a.to_dict(), SCHEMA)
    assert a.replace().to_toml() == a.to_toml()


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_the_schema_rejects_an_unknown_key(path):
    raw = tomllib.loads(path.read_text())
    for bad in ({**raw, "stepz": 3}, {**raw, "motion": {**raw["motion"], "qq": 1.0}},
                {**raw, "topology": {"kind": "ring", "center": 2}}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, SCHEMA)
        with pytest.raises(edccif.ScenarioError):
            edccif.Scenario.from_dict(bad)


def test_topology_forms_are_the_same_everywhere():
    base = edccif.Scenario.paper(nodes=4)
    d = base.to_dict()
    for form in ["line", {"kind": "star", "center": 2}, [[0, 1, 1, 1], [1, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]]]:
        a = edccif.Scenario.from_dict({**d, "topology": form})
        b = base.replace(topology=form)
        assert a.to_toml() == b.to_toml()
        assert edccif.Scenario.from_toml_str(a.to_toml()).to_toml() == a.to_toml()
    with pytest.raises(edccif.ScenarioError, match="center"):
        edccif.Scenario.from_dict({**d, "topology": {"kind": "ring", "center": 2}})
    with pytest.raises(edccif.ScenarioError, match="wheel"):
        edccif.Scenario.from_dict({**d, "topology": "wheel"})


def test_catalogue_files_simulate_and_run():
    planar = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "bearing-only-2d.toml")).replace(steps=50)
    truth, z, x0 = planar.simulate(seed=1)
    assert truth.shape == (50, 5) and z.shape == (50, 6 * 1 + 1) and x0.shape == (5,)
    assert planar.meas_dim is None
    r = edccif.run("EDC-CIF", planar, z, x0=x0)
    assert r.estimates.shape == (50, 6, 5) and np.isfinite(r.estimates).all()
    mixed = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "mixed-3d.toml"))
    truth, z, x0 = mixed.simulate(seed=1)
    assert z.shape == (200, 3 + 3 + 3 + 1 + 3)
    assert np.isnan(z[0, 6:9]).all() and np.isfinite(z[4, 6:9]).all()  # node 2 measures every 5th step
    r = edccif.run("edc-cif", mixed, z, x0=x0)
    assert np.isfinite(r.estimates).all()


PER_NODE = [f for f in FILES if "nodes" in tomllib.loads(f.read_text())]


def test_per_node_sensors_are_each_nodes_position():
    nan = np.nan
    mixed = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "mixed-3d.toml"))
    np.testing.assert_array_equal(
        mixed.sensors,
        # the position sensors (nodes 2 and 4) have no position
        [[10.0, 0.0, 0.0], [-10.0, 0.0, 3.0], [nan, nan, nan], [0.0, 10.0, 2.0], [nan, nan, nan]],
    )
    planar = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "bearing-only-2d.toml"))
    expected = [node["sensor"]["position"] for node in planar.to_dict()["nodes"]]
    assert planar.sensors.shape == (6, 2) and planar.sensors.dtype == np.float64
    np.testing.assert_array_equal(planar.sensors, expected)
    # a planar range-only beacon in a 3-D scenario: NaN in the third column
    d = mixed.to_dict()
    d["nodes"][3]["sensor"]["position"] = [0.0, 10.0]
    np.testing.assert_array_equal(edccif.Scenario.from_dict(d).sensors[3], [0.0, 10.0, nan])
    # no node with a position: the target's position dimension, all NaN
    d["nodes"] = [{"sensor": {"kind": "position", "sigma": [0.1, 0.1, 0.1]}}] * 2
    d["delta"] = 0.01
    only_fixes = edccif.Scenario.from_dict(d).sensors
    assert only_fixes.shape == (2, 3) and np.isnan(only_fixes).all()


@pytest.mark.parametrize("path", PER_NODE, ids=[f.stem for f in PER_NODE])
def test_per_node_getters_answer_or_name_the_nodes_key(path):
    sc = edccif.Scenario.from_toml(str(path))
    names = [n for n, v in vars(edccif.Scenario).items() if not n.startswith("_") and not callable(v)]
    assert {"sensors", "measurement", "meas_dim", "position_dim", "motion"} <= set(names)
    refused = []
    for name in names:
        try:
            getattr(sc, name)
        except edccif.EdccifError as e:
            assert "`nodes`" in str(e), (name, str(e))
            refused.append(name)
    # only the uniform form's single measurement has no per-node answer
    assert refused == ["measurement"]
    assert sc.sensors.shape[0] == sc.nodes
    assert sc.position_dim == {"mixed-3d": 3, "bearing-only-2d": 2}.get(path.stem, sc.position_dim)
    assert sc.meas_dim is None  # both files mix sensors of different dimensions


@pytest.mark.parametrize("key", ["sigma_r", "sigma_a", "sigma", "sensors", "measurement"])
@pytest.mark.parametrize("path", PER_NODE, ids=[f.stem for f in PER_NODE])
def test_per_node_replace_of_a_uniform_key_says_to_use_nodes(path, key):
    sc = edccif.Scenario.from_toml(str(path))
    value = {
        "sigma_r": 0.3,
        "sigma_a": 0.02,
        "sigma": [0.1, 0.1, 0.1],
        "sensors": [[0.0, 0.0, 0.0]] * sc.nodes,
        "measurement": {"kind": "range-pitch-azimuth", "sigma_r": 0.1, "sigma_a": 0.01},
    }[key]
    with pytest.raises(edccif.ScenarioError, match=rf"`{key}`.*\[\[nodes\]\]"):
        sc.replace(**{key: value})
    # the way it names works: edit the nodes
    nodes = sc.to_dict()["nodes"]
    for n in nodes:
        if "sigma_r" in n["sensor"]:
            n["sensor"]["sigma_r"] = 0.3
    changed = sc.replace(nodes=nodes)
    assert changed.to_dict()["nodes"] == nodes and changed != sc
