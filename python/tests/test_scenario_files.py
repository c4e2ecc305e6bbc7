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
