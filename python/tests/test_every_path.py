"""Scenario files with per-node catalogue models, mixed sensors and rates, and
Python models named by reference, on every path: `edccif reproduce --scenario`,
`Node`/`SensorTrigger` driven step by step, and `swarm` files; each compared
with the in-process run of the same file."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import edccif
from edccif import agents
from edccif.reproduce import reproduce_scenario

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios"
FILES = ["mixed-3d.toml", "bearing-only-2d.toml", "custom-turn-2d.toml"]
# the sensor-side rows: one diffusion, one consensus, one without fusion, the dynamic trigger
ROWS = ["edc-cif", "dc-cif", "ec-ckf", "dec-ckf", "ed-cif"]


def scenario(name, steps=None):
    """A shipped file (`mixed-3d` keeps its 200 steps: a node measures at 19 s)."""
    sc = edccif.Scenario.from_toml(SCENARIOS / name)
    return sc if steps is None else sc.replace(steps=steps)


def lockstep(sc, alg, z, x0):
    """Every node and sensor of `sc` as separate objects, every packet
    delivered; a sensor that does not measure at a step (its rate) gives the
    node a row of NaN, as the agents do."""
    k = sc.nodes
    nodes = [edccif.Node(sc, alg, node=i, x0=x0) for i in range(k)]
    sensors = [edccif.SensorTrigger(sc, alg, node=i) for i in range(k)]
    cols = [agents.node_columns(sc, z, i) for i in range(k)]
    est = np.zeros((z.shape[0], k, sc.state_dim))
    for t in range(z.shape[0]):
        pk = []
        for i, nd in enumerate(nodes):
            zi = cols[i][t]
            assert nd.measures(t) == (not np.isnan(zi).all())
            if not nd.measures(t):
                pk.append(nd.local(zi))
            else:
                pk.append(nd.local(zi if sensors[i].decide(zi) else None))
        if nodes[0].fusion.startswith("diffusion"):
            pk = [nd.adapt([(j, pk[j][1], pk[j][2]) for j in nd.neighbours]) for nd in nodes]
            for nd in nodes:
                nd.combine([(j, pk[j][1], pk[j][2]) for j in nd.neighbours])
        elif nodes[0].fusion == "consensus":
            for _ in range(nodes[0].rounds):
                pk = [nd.consensus_round([(j, pk[j][1], pk[j][2]) for j in nd.neighbours]) for nd in nodes]
        est[t] = [nd.estimate for nd in nodes]
    return est


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("alg", ROWS)
def test_nodes_of_any_model_equal_run_bit_for_bit(name, alg):
    """The same core phases run in both: tolerance 0."""
    sc = scenario(name)
    _, z, x0 = sc.simulate(seed=2)
    ref = edccif.run(alg, sc, z, x0=x0)
    assert np.array_equal(lockstep(sc, alg, z, x0), ref.estimates)


def test_node_and_trigger_take_the_nodes_own_sensor():
    sc = scenario("mixed-3d.toml")
    assert [edccif.Node(sc, node=i).meas_dim for i in range(sc.nodes)] == sc.meas_dims
    assert [edccif.SensorTrigger(sc, node=i).meas_dim for i in range(sc.nodes)] == sc.meas_dims
    nd = edccif.Node(sc, node=3)  # range-only: m = 1
    with pytest.raises(edccif.EdccifError, match=r"z"):
        nd.local(np.zeros(3))
    assert nd.phase == "idle"
    # node 2 measures every 5th step only, node 4 at its times (s)
    n2, n4 = edccif.Node(sc, node=2), edccif.Node(sc, node=4)
    assert [t for t in range(12) if n2.measures(t)] == [4, 9]
    assert [t for t in range(60) if n4.measures(t)] == [9, 19, 49]
    with pytest.raises(edccif.EdccifError, match="t"):
        n2.measures(-1)


def test_reproduce_scenario_equals_the_in_process_runs():
    """Each row of `reproduce --scenario` is its Monte Carlo study, run r
    simulated with seed + r: the RMSE curve from `edccif.run` on those runs."""
    sc = scenario("mixed-3d.toml")
    data = reproduce_scenario(sc, runs=2, seed=5, out=None, progress=False, deltas=(1.0,), sigmas=(5e-4,))
    rows = {v["label"]: v for v in data["table2"]["variants"]}
    assert set(rows) == {"C-CKF", "EC-EKF", "EC-UKF", "EC-CKF", "DEC-CKF", "D-CIF", "DC-CIF", "ED-CIF", "EDC-CIF"}
    assert not data["refused"]["table2"]
    d = sc.position_dim
    for label, alg in (("EDC-CIF", "edc-cif"), ("EC-EKF", "ec-ekf")):
        sq = []
        for r in range(2):
            truth, z, x0 = sc.simulate(seed=5 + r)
            est = edccif.run(alg, sc, z, x0=x0).estimates
            sq.append(np.sum((est[:, :, :d] - truth[:, None, :d]) ** 2, axis=2))
        curve = np.sqrt(np.mean(np.stack(sq), axis=(0, 2)))
        np.testing.assert_allclose(rows[label]["errors"]["pos_rmse_curve"], curve, rtol=1e-12, atol=0)
    assert [v["label"] for v in data["table1"]["variants"]] == [
        "EDC-CIF", "w/o optimal ET filter (hold)", "w/o diffusion with CI (consensus)", "DEC-CKF"]
    assert data["table1"]["variants"][0]["errors"] == rows["EDC-CIF"]["errors"]
    assert set(data["not_run"]) == {"realworld", "flights", "paper"}
    assert "## Not run on a scenario file" in data["markdown"]


def test_reproduce_scenario_refuses_a_row_alone(monkeypatch):
    """A row the scenario cannot run is named with its error; the others run."""
    real = edccif._edccif.monte_carlo

    def picky(sc, variants, **kw):
        if variants == ["ec-ukf"]:
            raise edccif.ParameterError("this row is refused here")
        return real(sc, variants, **kw)

    monkeypatch.setattr(edccif._edccif, "monte_carlo", picky)
    sc = scenario("bearing-only-2d.toml", steps=10)
    data = reproduce_scenario(sc, runs=1, out=None, progress=False, deltas=(1.0,), sigmas=())
    assert "EC-UKF" not in [v["label"] for v in data["table2"]["variants"]]
    assert "this row is refused here" in data["refused"]["table2"]["ec-ukf"]
    assert "ec-ukf: refused — ParameterError: this row is refused here" in data["markdown"]


def test_reproduce_command_on_a_referenced_model(tmp_path):
    sc_file = tmp_path / "turn.toml"
    text = (SCENARIOS / "custom-turn-2d.toml").read_text().replace("steps = 200", "steps = 20")
    text = text.replace('python_path = ["../examples"]', f'python_path = ["{ROOT / "examples"}"]')
    sc_file.write_text(text)
    out = subprocess.run([sys.executable, "-m", "edccif", "reproduce", "--scenario", str(sc_file), "--runs", "2",
                          "--out", str(tmp_path / "r"), "--quiet"], capture_output=True, text=True, timeout=600,
                         cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    data = json.loads((tmp_path / "r" / "results.json").read_text())
    assert data["settings"]["scenario"] == "custom-turn-2d" and data["settings"]["nodes"] == 6
    assert (tmp_path / "r" / "rmse_over_time.png").stat().st_size > 0
    assert (tmp_path / "r" / "delta_sweep.png").stat().st_size > 0
    sc = edccif.Scenario.from_toml(sc_file)
    mc = edccif.monte_carlo(sc, "edc-cif", runs=2, seed=0, progress=False)
    row = next(v for v in data["table2"]["variants"] if v["label"] == "EDC-CIF")
    assert row["errors"]["pos_rmse"] == mc.pos_rmse["EDC-CIF"]
    bad = subprocess.run([sys.executable, "-m", "edccif", "reproduce", "--scenario", str(sc_file), "--nodes", "3",
                          "--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert bad.returncode != 0 and "--nodes" in bad.stderr and "not with --scenario" in bad.stderr


def _load_in_fresh_process(path, cwd):
    """`load_swarm(path)` in a new interpreter (nothing imported yet) at `cwd`."""
    code = ("import sys; from edccif import agents\n"
            "try:\n    print(agents.load_swarm(sys.argv[1])[1].nodes)\n"
            "except Exception as e:\n    print(type(e).__name__, e)")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120,
                         cwd=cwd)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_swarm_file_with_a_referenced_model_loads_anywhere(tmp_path):
    """The swarm file stores the Python models' directories absolute; a
    relative one in a hand-written file is relative to the swarm file; a
    module that is not there is refused naming it."""
    sc = edccif.Scenario.from_toml(SCENARIOS / "custom-turn-2d.toml")
    spec = agents.write_swarm(tmp_path / "a" / "swarm.json", sc)
    assert spec["scenario"]["python_path"] == [str(ROOT / "examples")]
    assert _load_in_fresh_process(tmp_path / "a" / "swarm.json", tmp_path) == "6"
    other = tmp_path / "b" / "c"
    other.mkdir(parents=True)
    spec["scenario"]["python_path"] = [os.path.relpath(ROOT / "examples", other)]
    (other / "swarm.json").write_text(json.dumps(spec))
    assert _load_in_fresh_process(other / "swarm.json", tmp_path) == "6"
    spec["scenario"]["python_path"] = ["nowhere"]
    (other / "swarm.json").write_text(json.dumps(spec))
    got = _load_in_fresh_process(other / "swarm.json", tmp_path)
    assert got.startswith("ScenarioError") and "turn_models" in got and "nowhere" in got


@pytest.mark.parametrize("name", ["mixed-3d.toml", "custom-turn-2d.toml", "bearing-only-2d.toml"])
def test_swarm_of_a_per_node_scenario_equals_run(tmp_path, name):
    """Agents and sensors as processes over Zenoh on loopback, with mixed
    sensors and rates (and Python models by reference): the in-process
    numbers, to the tolerance of the existing swarm test."""
    pytest.importorskip("zenoh")
    sc = edccif.Scenario.from_toml(SCENARIOS / name)
    # mixed-3d keeps its 200 steps (a node measures at 19 s); the other runs 40
    steps = None if name == "mixed-3d.toml" else 40
    res = agents.run_swarm(sc.nodes, "edc-cif", scenario=sc, seed=0, steps=steps, out=tmp_path,
                           period_s=0.06, sensor_wait_s=0.045, deadline_s=2.0)
    assert not np.isnan(res["estimates"]).any()
    assert np.max(np.abs(res["estimates"] - res["reference"])) <= 1e-9
    s = res["summary"]
    assert s["inbox"]["late"] == 0 and s["trigger_rate"] == pytest.approx(s["trigger_rate_in_process"])


FAILING = '''
import turn_models
from edccif import models


def motion():
    calls = {"n": 0}

    def f(X, dt):
        calls["n"] += 1
        if calls["n"] > 3:
            raise RuntimeError("boom from the model")
        return turn_models._turn(X, dt)

    return models.CustomMotion(f, turn_models._noise, n=5)
'''


def test_node_raises_its_python_models_error_and_leaves_nothing_behind(tmp_path):
    """A referenced model that raises inside a Node: the step raises ModelError
    with the model's exception as its cause, the node keeps its state, and
    nothing of it reaches a later run (the node still holds the model)."""
    (tmp_path / "failing_turn_models.py").write_text(FAILING)
    import tomllib

    with open(SCENARIOS / "custom-turn-2d.toml", "rb") as f:
        d = tomllib.load(f)
    d["python_path"] = [str(ROOT / "examples"), str(tmp_path)]
    d["motion"]["model"] = "failing_turn_models:motion"
    sc = edccif.Scenario.from_dict(d)
    good = scenario("custom-turn-2d.toml", steps=20)
    _, z, x0 = good.simulate(seed=0)
    nd = edccif.Node(sc, "edc-cif", node=0, x0=x0)
    with pytest.raises(edccif.ModelError, match="boom from the model") as e:
        for t in range(10):
            nd.local(z[t, :1])
            nd.abort_step()
    assert isinstance(e.value.__cause__, RuntimeError)
    assert nd.phase == "idle" and np.array_equal(nd.estimate, x0)
    ref = edccif.run("edc-cif", good, z, x0=x0)
    assert np.isfinite(ref.estimates).all()
    del nd
    assert np.array_equal(edccif.run("edc-cif", good, z, x0=x0).estimates, ref.estimates)
