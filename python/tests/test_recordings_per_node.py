"""Recordings of per-node scenarios (each node its own sensor kind, size,
noise and rate; other motions; Python models by reference): `edccif.record`
and `edccif simulate --mcap` store each node's measurements at its own size
(docs/formats.md, "MCAP"), and `edccif.replay` / `edccif replay` run them to
the in-process numbers bit for bit (the same code runs: tolerance 0). What
cannot work is refused naming what was wrong and what to do."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import edccif

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"


def scenario(name, steps):
    return edccif.Scenario.from_toml(SCENARIOS / name).replace(steps=steps)


def cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "edccif", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def same(a, b):
    """Equal bit for bit, NaN where NaN."""
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


# mixed-3d: node 2 every 5th step, node 4 at given times (up to 19 s), sizes 3, 3, 3, 1, 3;
# bearing-only-2d: sizes 1 and 2 on a planar coordinated turn
@pytest.mark.parametrize("name,steps", [("mixed-3d.toml", 200), ("bearing-only-2d.toml", 60)])
@pytest.mark.parametrize("alg", ["edc-cif", "dc-cif"])
def test_record_and_replay_equal_the_in_process_run(tmp_path, name, steps, alg):
    sc = scenario(name, steps)
    truth, z, x0 = sc.simulate(seed=3)
    ref = edccif.run(alg, sc, z, x0=x0)
    path = tmp_path / "run.mcap"
    rec = edccif.record(alg, sc, seed=3, mcap=path)
    assert np.array_equal(rec.estimates, ref.estimates)
    # every node's measurements at its own size, as simulate gives them
    t_ns, zr, trig = edccif.read_mcap_measurements(path)
    assert same(zr, z) and zr.shape == (steps, sum(sc.meas_dims))
    assert np.array_equal(trig, ref.triggered)
    assert np.array_equal(t_ns, np.round(np.arange(steps) * sc.dt * 1e9))
    # the replay runs the stored scenario, algorithm and x̂0
    rep = edccif.replay(path)
    assert np.array_equal(rep.estimates, ref.estimates)
    assert np.array_equal(rep.covariances, ref.covariances)
    assert np.array_equal(rep.triggered, ref.triggered)
    assert rep.report["stored"]["scenario"] == "stored" and rep.algorithm == alg
    assert [n["source"] for n in rep.report["per_node"]] == [f"/node{i}/measurement" for i in range(sc.nodes)]
    # the same file given again is accepted; another one refused unless override
    again = edccif.replay(path, scenario=sc)
    assert np.array_equal(again.estimates, ref.estimates)
    other = sc.replace(sigma1=1e-3)
    with pytest.raises(edccif.ScenarioError, match=r"differs from it in: sigma1.*override"):
        edccif.replay(path, scenario=other)
    over = edccif.replay(path, scenario=other, override=True)
    assert np.array_equal(over.estimates, edccif.run(alg, other, z).estimates)


def test_model_network_on_the_recorded_measurements(tmp_path):
    """A ModelNetwork of the scenario's own models on the replayed
    measurements: the in-process numbers."""
    sc = scenario("bearing-only-2d.toml", 40)
    path = tmp_path / "b.mcap"
    rec = edccif.record("edc-cif", sc, seed=1, mcap=path)
    _, zr, _ = edccif.read_mcap_measurements(path)
    _, z, x0 = sc.simulate(seed=1)
    assert same(zr, z)
    assert np.array_equal(edccif.run("edc-cif", sc, zr, x0=x0).estimates, rec.estimates)


def test_a_scenario_of_other_sizes_is_refused_naming_the_node(tmp_path):
    path = tmp_path / "m.mcap"
    edccif.record("edc-cif", scenario("mixed-3d.toml", 200), mcap=path)
    # five nodes too, node 3 measures 3 values instead of a range
    d = edccif.Scenario.from_toml(SCENARIOS / "mixed-3d.toml").to_dict()
    d["nodes"][3]["sensor"] = {"kind": "position", "sigma": [0.1, 0.1, 0.1]}
    other = edccif.Scenario.from_dict(d).replace(steps=200)
    with pytest.raises(edccif.ShapeError, match=r"node 3 measures 1 values in the file.*position.*measures 3"):
        edccif.replay(path, scenario=other, override=True)
    with pytest.raises(edccif.ShapeError, match=r"the file has 5 nodes, the scenario 6"):
        edccif.replay(path, scenario=scenario("bearing-only-2d.toml", 20), override=True)
    # models of the wrong sizes: named per sensor; without x0/P0 the start cannot come from the rows
    from edccif import models

    cv = models.ConstantVelocity(3, 0.1)
    with pytest.raises(edccif.ParameterError, match=r"x0, P0: needed here.*\[3, 3, 3, 1, 3\]"):
        edccif.replay(path, motion=cv, sensors=[models.Position([0.1] * 3)] * 5, override=True)


def test_cli_simulate_mcap_and_replay_of_a_per_node_file(tmp_path):
    f = SCENARIOS / "mixed-3d.toml"
    made = cli("simulate", "--scenario", f, "--seed", 4, "--mcap", tmp_path / "r.mcap", "--tum", tmp_path / "tum",
               "--out", tmp_path / "r.npz", cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    run = np.load(tmp_path / "r.npz")
    sc = edccif.Scenario.from_toml(f)
    ref = edccif.run("edc-cif", sc, run["z"], x0=run["x0"])
    assert np.array_equal(run["estimates"], ref.estimates)
    rep = cli("replay", tmp_path / "r.mcap", "--json", "--out", tmp_path / "o.npz", cwd=tmp_path)
    assert rep.returncode == 0, rep.stderr
    summary = json.loads(rep.stdout)
    assert summary["stored"]["scenario"] == "stored" and summary["nodes"] == 5
    out = np.load(tmp_path / "o.npz")
    assert np.array_equal(out["estimates"], ref.estimates)
    assert same(out["z"], run["z"])
    # the TUM files hold the positions
    t, p, _ = edccif.read_tum(tmp_path / "tum" / "node0.txt")
    np.testing.assert_allclose(p, ref.estimates[:, 0, :3], rtol=1e-9)
    # --scenario: the same file is accepted, --motion (3-D position sensors) refused saying what instead
    same_file = cli("replay", tmp_path / "r.mcap", "--scenario", f, "--json", cwd=tmp_path)
    assert same_file.returncode == 0, same_file.stderr
    moved = cli("replay", tmp_path / "r.mcap", "--motion", "cv3", cwd=tmp_path)
    assert moved.returncode == 2
    assert "measure different sizes" in moved.stderr and "without --motion" in moved.stderr


def test_a_planar_recording_writes_positions_at_z_0(tmp_path):
    sc = scenario("bearing-only-2d.toml", 10)
    res = edccif.record("edc-cif", sc, mcap=tmp_path / "b.mcap", tum_dir=tmp_path / "tum")
    _, p, _ = edccif.read_tum(tmp_path / "tum" / "node2.txt")
    np.testing.assert_allclose(p[:, :2], res.estimates[:, 2, :2], rtol=1e-9)
    assert np.all(p[:, 2] == 0.0)


def test_a_ros2_replay_with_a_per_node_scenario_is_refused_saying_what_instead(tmp_path):
    path = tmp_path / "p.mcap"
    edccif.record("edc-cif", edccif.Scenario.paper(3).replace(steps=5), mcap=path, ros2=True)
    with pytest.raises(edccif.ScenarioError, match=r"a sensor of its own per node.*motion=, sensors="):
        edccif.replay(path, measurements=["/node0/point", "/node1/point", "/node2/point"],
                      scenario=scenario("mixed-3d.toml", 200))


def _turn_file(tmp_path, module_dir):
    text = (SCENARIOS / "custom-turn-2d.toml").read_text().replace("steps = 200", "steps = 30")
    text = text.replace('python_path = ["../examples"]', f'python_path = ["{module_dir}"]')
    f = tmp_path / "turn.toml"
    f.write_text(text)
    return f


def test_a_referenced_python_model_is_recorded_and_replayed(tmp_path):
    """The stored scenario names its Python models with python_path made
    absolute: a replay from another directory, in a fresh process, builds
    them and gives the in-process numbers."""
    sc = edccif.Scenario.from_toml(SCENARIOS / "custom-turn-2d.toml").replace(steps=30)
    path = tmp_path / "turn.mcap"
    rec = edccif.record("edc-cif", sc, seed=2, mcap=path)
    _, z, x0 = sc.simulate(seed=2)
    assert np.array_equal(rec.estimates, edccif.run("edc-cif", sc, z, x0=x0).estimates)
    assert np.array_equal(edccif.replay(path).estimates, rec.estimates)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    rep = cli("replay", path, "--out", tmp_path / "o.npz", cwd=elsewhere)
    assert rep.returncode == 0, rep.stderr
    assert np.array_equal(np.load(tmp_path / "o.npz")["estimates"], rec.estimates)
    # a scenario file naming the same directory relative to itself equals the stored one
    # (python_path resolved on both sides)
    text = (SCENARIOS / "custom-turn-2d.toml").read_text().replace("steps = 200", "steps = 30")
    rel = os.path.relpath(ROOT / "examples", tmp_path)
    (tmp_path / "turn.toml").write_text(text.replace('python_path = ["../examples"]', f'python_path = ["{rel}"]'))
    given = cli("replay", path, "--scenario", tmp_path / "turn.toml", "--json", cwd=elsewhere)
    assert given.returncode == 0, given.stderr
    assert json.loads(given.stdout)["stored"]["scenario"] == "stored (the given one equals it)"


def test_a_python_model_that_cannot_be_imported_at_replay_is_refused_saying_what_to_do(tmp_path):
    mods = tmp_path / "mods"
    mods.mkdir()
    shutil.copy(ROOT / "examples" / "turn_models.py", mods / "turn_models.py")
    f = _turn_file(tmp_path, mods)
    path = tmp_path / "turn.mcap"
    made = cli("simulate", "--scenario", f, "--mcap", path, "--out", tmp_path / "r.npz", cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    shutil.rmtree(mods)
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    rep = subprocess.run([sys.executable, "-m", "edccif", "replay", str(path)], capture_output=True, text=True,
                         timeout=300, cwd=tmp_path, env=env)
    assert rep.returncode == 2, rep.stderr
    err = rep.stderr
    assert "names Python models" in err and "turn_models" in err and "cannot be built" in err
    assert os.path.realpath(mods) in err and "PYTHONPATH" in err and "--override" in err
    # the models from elsewhere: the module put back on PYTHONPATH
    env["PYTHONPATH"] = str(ROOT / "examples")
    again = subprocess.run([sys.executable, "-m", "edccif", "replay", str(path), "--out", tmp_path / "o.npz"],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env)
    assert again.returncode == 0, again.stderr
    assert np.array_equal(np.load(tmp_path / "o.npz")["estimates"], np.load(tmp_path / "r.npz")["estimates"])


def test_a_sensor_agent_replays_its_own_columns_of_a_per_node_recording(tmp_path):
    from edccif import agents

    sc = scenario("mixed-3d.toml", 200)
    path = tmp_path / "m.mcap"
    edccif.record("edc-cif", sc, seed=5, mcap=path)
    _, z, _ = sc.simulate(seed=5)
    spec = {"source": {"kind": "mcap", "path": str(path)}}
    for i in range(sc.nodes):
        got = agents.sensor_measurements(spec, sc, i)
        assert same(got, agents.node_columns(sc, z, i)) and got.shape[1] == sc.meas_dims[i]
    with pytest.raises(agents.AgentError, match=r"holds 13 values per step.*\[1, 1, 1, 2, 1, 1\]"):
        agents.sensor_measurements(spec, scenario("bearing-only-2d.toml", 30), 0)
