"""Scenario files: every file in `scenarios/` is valid against the shipped JSON
Schema and round-trips through `from_toml`, `to_toml`, `to_dict`, `from_dict` and
`replace`; unknown keys and values a run would ignore are refused by name; the
per-node files of the model catalogue and of Python models by reference simulate
and run, with the same numbers through `edccif simulate`, `edccif sweep
--in-process` and the Python API."""

import json
import pathlib
import subprocess
import sys

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
    assert {"paper-3", "paper-4", "paper-8", "bearing-only-2d", "mixed-3d", "custom-turn-2d"} <= names


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_every_file_is_valid_and_round_trips(path):
    raw = tomllib.loads(path.read_text())
    jsonschema.validate(raw, SCHEMA)
    a = edccif.Scenario.from_toml(str(path))
    # `python_path` is relative to the file's directory: text and dicts say where that is
    here = path.parent
    b = edccif.Scenario.from_toml_str(a.to_toml(), base_dir=here)
    assert b.to_toml() == a.to_toml() and b == a
    # the parsed file as a dict, and to_dict, give the same scenario
    assert edccif.Scenario.from_dict(raw, base_dir=here).to_toml() == a.to_toml()
    assert edccif.Scenario.from_dict(a.to_dict(), base_dir=here).to_toml() == a.to_toml()
    jsonschema.validate(a.to_dict(), SCHEMA)
    assert a.replace().to_toml() == a.to_toml()


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_the_schema_rejects_an_unknown_key(path):
    raw = tomllib.loads(path.read_text())
    for bad in ({**raw, "stepz": 3}, {**raw, "motion": {**raw["motion"], "qq": 1.0}},
                {**raw, "nodes": [{**n, "sensor": {**n["sensor"], "sigma_x": 1.0}} for n in raw.get("nodes", [])]}
                if "nodes" in raw else {**raw, "measurement": {**raw["measurement"], "sigma_x": 1.0}},
                {**raw, "topology": {"kind": "ring", "center": 2}}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, SCHEMA)
        with pytest.raises(edccif.ScenarioError):
            edccif.Scenario.from_dict(bad, base_dir=path.parent)


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
    assert sc.position_dim == {"mixed-3d": 3, "bearing-only-2d": 2, "custom-turn-2d": None}[path.stem]
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


# --- Python models by reference (`kind = "python"`) and the three non-paper files on every path

NON_PAPER = ["bearing-only-2d", "mixed-3d", "custom-turn-2d"]
CUSTOM = ROOT / "scenarios" / "custom-turn-2d.toml"


def _module(tmp_path, name, text):
    (tmp_path / f"{name}.py").write_text(text)
    return tmp_path


def test_a_reference_round_trips_and_runs_on_the_model_network():
    sc = edccif.Scenario.from_toml(str(CUSTOM))
    d = sc.to_dict()
    assert d["motion"] == {"kind": "python", "model": "turn_models:turn_motion", "n": 5}
    assert d["python_path"] == ["../examples"]
    assert d["nodes"][4] == {"sensor": {"kind": "python", "model": "turn_models:position_tag", "m": 2}, "every": 10}
    assert sc.base_dir == str(CUSTOM.parent)
    again = edccif.Scenario.from_toml_str(sc.to_toml(), base_dir=CUSTOM.parent)
    assert again.to_toml() == sc.to_toml() and again.to_dict() == d
    short = sc.replace(steps=40)
    truth, z, x0 = short.simulate(seed=3)
    assert truth.shape == (40, 5) and z.shape == (40, 4 * 1 + 2 + 2)
    assert np.isnan(z[:9, 5:7]).all() and np.isfinite(z[9, 5:7]).all()  # the tag (node 4): every 10th step
    r = edccif.run("EDC-CIF", short, z, x0=x0)
    assert r.estimates.shape == (40, 6, 5) and np.isfinite(r.estimates).all()
    assert np.linalg.norm(r.estimates[-1, :, :2] - truth[-1, :2], axis=1).max() < 2.0
    # the same models in a ModelNetwork of the scenario's parameters: the same numbers, bit for bit
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        import turn_models
    finally:
        sys.path.remove(str(ROOT / "examples"))
    sensors = []
    for n in d["nodes"]:
        s = n["sensor"]
        sensors.append({
            "bearing-only": lambda s: edccif.models.BearingOnly(s["position"], s["sigma_b"]),
            "range-bearing": lambda s: edccif.models.RangeBearing(s["position"], s["sigma_r"], s["sigma_b"]),
            "python": lambda s: turn_models.position_tag(),
        }[s["kind"]](s))
    net = edccif.ModelNetwork(turn_models.turn_motion(), sensors, "edc-cif", x0=x0, P0=short.p0,
                              adjacency=short.adjacency, dt=short.dt, delta=4.0, normalised=True,
                              sigma1=short.sigma1, sigma2=short.sigma2)
    cols = list(zip([0, 1, 2, 4, 5, 7], [1, 1, 2, 1, 2, 1]))  # (offset, m) of each node in a row of z
    rows = [[None if np.isnan(z[t, o:o + m]).all() else z[t, o:o + m] for o, m in cols] for t in range(40)]
    est = np.stack([net.step(row) for row in rows])
    np.testing.assert_array_equal(est, r.estimates)


def test_a_reference_to_the_catalogue_model_gives_the_catalogue_bits(tmp_path):
    planar = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "bearing-only-2d.toml")).replace(steps=60)
    d = planar.to_dict()
    d["motion"] = {"kind": "python", "model": "turn_models:catalogue_turn", "n": 5}
    d["python_path"] = [str(ROOT / "examples")]
    ref = edccif.Scenario.from_dict(d)
    a, b = planar.simulate(seed=5), ref.simulate(seed=5)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    for alg in ("edc-cif", "ec-ekf", "dc-cif"):
        np.testing.assert_array_equal(edccif.run(alg, planar, a[1], x0=a[2]).estimates,
                                      edccif.run(alg, ref, b[1], x0=b[2]).estimates)
    # monte_carlo (3-D: its error metrics take a 3-D position and velocity)
    _module(tmp_path, "refs_cv",
            "from edccif import models\ndef cv():\n    return models.ConstantVelocity(dim=3, q=0.1)\n")
    mixed = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "mixed-3d.toml"))
    d = mixed.to_dict()
    d["motion"] = {"kind": "python", "model": "refs_cv:cv", "n": 6}
    d["python_path"] = [str(tmp_path)]
    ref = edccif.Scenario.from_dict(d)
    ma = edccif.monte_carlo(mixed, ["edc-cif", "ec-ckf"], runs=3, progress=False).to_dict()["variants"]
    mb = edccif.monte_carlo(ref, ["edc-cif", "ec-ckf"], runs=3, progress=False).to_dict()["variants"]
    assert [v["errors"] for v in ma] == [v["errors"] for v in mb]
    assert [v["trigger_rate"] for v in ma] == [v["trigger_rate"] for v in mb]


@pytest.mark.parametrize(
    "model, module, words",
    [
        ("no_such_module_xyz:f", None, ["no_such_module_xyz:f", "cannot import", "ModuleNotFoundError"]),
        ("refs_a:missing", "X = 1\n", ["refs_a:missing", "no attribute `missing`"]),
        ("refs_b:X", "X = 1\n", ["refs_b:X", "is a int", "MotionModel"]),
        ("refs_c:make", "def make():\n    return 'no model'\n", ["refs_c:make()", "returned a str", "MotionModel"]),
        ("refs_d:make", "def make():\n    raise RuntimeError('boom')\n", ["refs_d:make()", "RuntimeError: boom"]),
        ("refs_e:make", "from edccif import models\nimport numpy as np\n"
         "def make():\n    return models.Position([0.1, 0.1])\n", ["refs_e:make()", "returned a Position"]),
        ("refs_f:make", "from edccif import models\n"
         "def make():\n    return models.RandomWalk(n=3, q=0.1)\n", ["refs_f:make", "state dimension 3", "n = 5"]),
        ("not a reference", None, ["not a reference", "module:attribute"]),
    ],
)
def test_a_bad_reference_is_refused_naming_it(tmp_path, model, module, words):
    if module is not None:
        _module(tmp_path, model.split(":")[0], module)
    d = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "bearing-only-2d.toml")).to_dict()
    d["motion"] = {"kind": "python", "model": model, "n": 5}
    d["python_path"] = ["."]
    with pytest.raises(edccif.ScenarioError) as e:
        edccif.Scenario.from_dict(d, base_dir=tmp_path)
    assert "motion.model" in str(e.value)
    for w in words:
        assert w in str(e.value), str(e.value)


def test_a_bad_sensor_reference_names_its_node(tmp_path):
    _module(tmp_path, "refs_s", "from edccif import models\nimport numpy as np\n"
            "def tag():\n    return models.CustomMeasurement(lambda X: X[:, :2], np.eye(2), m=2, n=5)\n")
    d = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "bearing-only-2d.toml")).to_dict()
    d["python_path"] = [str(tmp_path)]
    d["nodes"][2]["sensor"] = {"kind": "python", "model": "refs_s:tag", "m": 1}
    with pytest.raises(edccif.ScenarioError, match=r"nodes\[2\]\.sensor\.model.*refs_s:tag.*measurement dimension 2"):
        edccif.Scenario.from_dict(d)
    d["nodes"][2]["sensor"]["m"] = 2
    assert edccif.Scenario.from_dict(d).meas_dim is None
    # `python_path` without a Python model is a value nothing reads
    del d["nodes"][2]
    d["delta"] = 4.0
    with pytest.raises(edccif.ScenarioError, match="python_path"):
        edccif.Scenario.from_dict(d)


def test_a_failing_referenced_callable_raises_its_own_error(tmp_path):
    _module(tmp_path, "refs_fail", "from edccif import models\nimport numpy as np\n"
            "def boom(X, dt):\n    raise ValueError('the model failed')\n"
            "def motion():\n    return models.CustomMotion(boom, 0.01 * np.eye(5), n=5)\n")
    d = edccif.Scenario.from_toml(str(ROOT / "scenarios" / "bearing-only-2d.toml")).replace(steps=10).to_dict()
    d["motion"] = {"kind": "python", "model": "refs_fail:motion", "n": 5}
    d["python_path"] = [str(tmp_path)]
    sc = edccif.Scenario.from_dict(d)
    with pytest.raises(edccif.ModelError) as e:
        sc.simulate(seed=0)
    assert "the model failed" in str(e.value) or "the model failed" in str(e.value.__cause__)


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True,
                          check=False)


@pytest.mark.parametrize("stem", NON_PAPER)
def test_every_non_paper_file_gives_the_same_numbers_on_every_path(tmp_path, stem):
    """`edccif simulate --scenario F`, `edccif sweep --in-process --scenario F` (two
    cells) and the Python API: the same code, the same numbers bit for bit."""
    path = ROOT / "scenarios" / f"{stem}.toml"
    seed, runs = 2, 2
    # simulate: the CLI from another directory (python_path is relative to the file)
    sc = edccif.Scenario.from_toml(str(path))
    # mixed-3d's node 4 measures at given times up to 19 s: its full 200 steps
    steps = sc.steps if any("times" in n for n in sc.to_dict()["nodes"]) else 30
    p = _cli("simulate", "--scenario", str(path), "--seed", str(seed), "--out", str(tmp_path / "run.npz"),
             "--algorithm", "edc-cif", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    saved = np.load(tmp_path / "run.npz")
    truth, z, x0 = sc.simulate(seed=seed)
    r = edccif.run("edc-cif", sc, z, x0=x0)
    for key, value in (("truth", truth), ("z", z), ("x0", x0), ("estimates", r.estimates),
                       ("triggered", r.triggered)):
        np.testing.assert_array_equal(saved[key], value, err_msg=key)
    # sweep: two cells (two thresholds) in this process, vs monte_carlo on the cell's scenario
    topo = sc.topology["kind"]
    thresholds = [2.0, 8.0] if sc.normalised else [0.01, 0.04]
    out = tmp_path / "sweep.csv"
    p = _cli("sweep", "--in-process", "--quiet", "--no-figure", "--scenario", str(path), "--topology", topo,
             "--thresholds", *map(str, thresholds), "--runs", str(runs), "--steps", str(steps),
             "--seeds", str(seed), "--out", str(out), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    from edccif.sweep import read_table

    rows = read_table(out)
    assert [float(r["threshold"]) for r in rows] == thresholds
    base = sc.replace(steps=steps, topology={"kind": topo})
    for row, th in zip(rows, thresholds):
        mc = edccif.monte_carlo(base, [{"algorithm": "edc-cif", "delta": th}], runs=runs, seed=seed, progress=False)
        v = mc.to_dict()["variants"][0]
        assert row["scenario"] == stem and int(row["nodes"]) == sc.nodes
        assert float(row["pos_rmse"]) == v["errors"]["pos_rmse"]
        assert float(row["trigger_rate"]) == v["trigger_rate"]
