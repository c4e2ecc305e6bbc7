"""Live agents (edccif.agents): the per-node binding without a network, the inbox's
accounting with forged packets, and whole swarms over Zenoh on loopback (each
process ends on its own; every run is bounded by run_swarm's timeout)."""

import doctest
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import edccif
from edccif import agents

DOCS = Path(__file__).resolve().parents[2] / "docs" / "agents.md"
ROWS = ["edc-cif", "ec-ckf", "ed-cif", "dec-ckf", "c-ckf", "dc-cif", "ec-ekf", "ec-ukf", "d-cif"]


def lockstep(sc, alg, z, x0, **options):
    """Every node and sensor as separate objects, every packet delivered."""
    k = sc.nodes
    nodes = [edccif.Node(sc, alg, node=i, x0=x0, **options) for i in range(k)]
    sensors = [edccif.SensorTrigger(sc, alg, node=i, **options) for i in range(k)]
    est = np.zeros((z.shape[0], k, sc.state_dim))
    for t in range(z.shape[0]):
        pk = [nd.local(z[t, i] if sensors[i].decide(z[t, i]) else None) for i, nd in enumerate(nodes)]
        if nodes[0].fusion.startswith("diffusion"):
            pk = [nd.adapt([(j, pk[j][1], pk[j][2]) for j in nd.neighbours]) for nd in nodes]
            for nd in nodes:
                nd.combine([(j, pk[j][1], pk[j][2]) for j in nd.neighbours])
        elif nodes[0].fusion == "consensus":
            for _ in range(nodes[0].rounds):
                pk = [nd.consensus_round([(j, pk[j][1], pk[j][2]) for j in nd.neighbours]) for nd in nodes]
        est[t] = [nd.estimate for nd in nodes]
    return est


@pytest.mark.parametrize("alg", ROWS)
def test_nodes_fed_every_packet_equal_run(sc4, sim4, alg):
    _, z, x0 = sim4
    z = z[:60]
    ref = edccif.run(alg, sc4, z, x0=x0)
    assert np.array_equal(lockstep(sc4, alg, z, x0), ref.estimates)


def test_nodes_through_the_wire_format_equal_run(sc4, sim4):
    """Packets encoded and decoded on the way (the upper triangle only) change nothing."""
    _, z, x0 = sim4
    z = z[:40]
    k = sc4.nodes
    nodes = [edccif.Node(sc4, "edc-cif", node=i, x0=x0) for i in range(k)]
    sensors = [edccif.SensorTrigger(sc4, "edc-cif", node=i) for i in range(k)]

    def wire(kind, v, m, i, t):
        p = edccif.decode_packet(edccif.encode_packet(kind, v, m, swarm=9, sender=i, step=t))
        assert (p.kind, p.sender, p.step) == (kind, i, t)
        return p.vector, p.matrix

    for t in range(z.shape[0]):
        pk = []
        for i, nd in enumerate(nodes):
            zi = wire("measurement", z[t, i], None, i, t)[0] if sensors[i].decide(z[t, i]) else None
            kind, v, m = nd.local(zi)
            pk.append((kind, *wire(kind, v, m, i, t)))
        pk = [nd.adapt([(j, pk[j][1], pk[j][2]) for j in nd.neighbours]) for nd in nodes]
        pk = [(kd, *wire(kd, v, m, i, t)) for i, (kd, v, m) in enumerate(pk)]
        for nd in nodes:
            nd.combine([(j, pk[j][1], pk[j][2]) for j in nd.neighbours])
    assert np.array_equal(np.array([nd.estimate for nd in nodes]), edccif.run("edc-cif", sc4, z, x0=x0).estimates[-1])


def test_node_phase_errors_leave_it_usable(sc4, sim4):
    _, z, x0 = sim4
    nd = edccif.Node(sc4, "edc-cif", node=1, x0=x0)
    assert nd.neighbours == [0, 2] and nd.fusion == "diffusion-ci" and nd.rounds == 0
    with pytest.raises(edccif.ParameterError, match="phase 'idle'"):
        nd.adapt([])
    kind, v, m = nd.local(z[0, 1])
    assert kind == "contribution" and v.shape == (7,) and m.shape == (7, 7) and nd.triggered
    with pytest.raises(edccif.ParameterError, match="not a neighbour"):
        nd.adapt([(3, v, m)])
    with pytest.raises(edccif.ParameterError, match="appears twice"):
        nd.adapt([(0, v, m), (0, v, m)])
    with pytest.raises(edccif.NonFiniteError):
        nd.adapt([(0, v * np.nan, m)])
    with pytest.raises(edccif.ParameterError, match="phase 'local'"):
        nd.local(z[1, 1])
    assert nd.phase == "local"
    nd.adapt([])
    x, P = nd.combine([])
    assert np.all(np.isfinite(x)) and np.all(np.linalg.eigvalsh(P) > 0) and nd.phase == "idle"
    with pytest.raises(edccif.ParameterError, match="node"):
        edccif.Node(sc4, "edc-cif", node=4)
    ec = edccif.Node(sc4, "ec-ckf", node=0)
    assert ec.fusion == "consensus" and ec.rounds == 5
    assert ec.local(None) is not None and ec.triggered is None  # nothing ever came: no measurement


def test_sensor_trigger_sends_only_changes(sc4, sim4):
    _, z, _ = sim4
    s = edccif.SensorTrigger(sc4, "edc-cif", node=0)
    assert s.decide(z[0, 0]) and not s.decide(z[0, 0])
    assert not s.decide(np.full(3, np.nan)) and (s.measured, s.sent) == (2, 1)
    with pytest.raises(edccif.NonFiniteError):
        s.decide([1.0, np.nan, 2.0])
    always = edccif.SensorTrigger(sc4, "c-ckf", node=0)
    assert always.decide(z[0, 0]) and always.decide(z[0, 0])


class _Payload:
    def __init__(self, b):
        self.b = b

    def to_bytes(self):
        return self.b


class _Sample:
    def __init__(self, key, data):
        self.key_expr, self.payload = key, _Payload(data)


KEY = b"k" * 32


def test_inbox_rejects_and_counts(sc4):
    inbox = agents._Inbox(swarm=5, me=1, neighbours=[0, 2], delays={}, key=KEY, state_dim=7)
    inbox.alive = {0, 2}
    v, m = np.ones(7), np.eye(7)

    def put(key, **h):
        inbox.on_sample(_Sample(key, edccif.encode_packet("contribution", v, m, key=KEY, **h)))

    put(agents.key(5, 0, "contribution"), swarm=6, sender=0, step=0)  # another swarm
    put(agents.key(5, 0, "contribution"), swarm=5, sender=2, step=0)  # sender is not the key's
    put(agents.key(5, 3, "contribution"), swarm=5, sender=3, step=0)  # not a neighbour
    inbox.on_sample(_Sample(agents.key(5, 0, "contribution"), b"\xed\xcf\x01"))  # truncated
    put(agents.key(5, 0, "contribution"), swarm=5, sender=0, step=0)
    got = inbox.wait("contribution", 0, 0, [0, 2], until=0.0)
    assert list(got) == [0]
    put(agents.key(5, 2, "contribution"), swarm=5, sender=2, step=0)  # after its phase: late
    c = inbox.counts
    assert (c["foreign_swarm"], c["unknown_sender"], c["malformed"], c["late"], c["received"]) == (1, 2, 1, 1, 1)


def test_inbox_delayed_link_is_late(sc4):
    import time

    inbox = agents._Inbox(swarm=5, me=1, neighbours=[0, 2], delays={0: 10.0}, key=KEY, state_dim=7)
    inbox.alive = {0, 2}
    for j in (0, 2):
        inbox.on_sample(_Sample(agents.key(5, j, "information"),
                                edccif.encode_packet("information", np.ones(7), np.eye(7), swarm=5, sender=j, step=3,
                                                     key=KEY)))
    got = inbox.wait("information", 3, 0, [0, 2], until=time.monotonic() + 0.05)
    assert list(got) == [2] and inbox.counts["late"] == 1


def test_swarm_file_errors(tmp_path, sc4):
    spec = agents.write_swarm(tmp_path / "s.json", sc4, ports=list(range(9000, 9008)))
    assert spec["agents"][3] == {"node": 3, "listen": "tcp/127.0.0.1:9006", "sensor_listen": "tcp/127.0.0.1:9007"}
    assert agents.load_swarm(tmp_path / "s.json")[1] == sc4
    with pytest.raises(edccif.UnknownOptionError, match="period"):
        agents.write_swarm(tmp_path / "t.json", sc4, periodd_s=1.0)
    with pytest.raises(edccif.ParameterError, match="faults.loss"):
        agents.write_swarm(tmp_path / "t.json", sc4, faults={"loss": 1.5})
    with pytest.raises(agents.AgentError, match="ports"):
        agents.write_swarm(tmp_path / "t.json", sc4, ports=[1, 2])
    with pytest.raises(agents.AgentError, match="swarm file"):
        agents.load_swarm(tmp_path / "missing.json")


def test_module_doctests():
    assert doctest.testmod(agents).failed == 0


# ----------------------------------------------------------------- over Zenoh

# Generous sensor wait: a measurement that misses it would change the numbers.
EXACT = {"period_s": 0.06, "sensor_wait_s": 0.045, "deadline_s": 2.0}


@pytest.mark.parametrize("alg", ["edc-cif", "ec-ckf"])
def test_swarm_without_loss_equals_run(tmp_path, alg):
    res = agents.run_swarm(4, alg, seed=0, steps=100, out=tmp_path / alg, **EXACT)
    s = res["summary"]
    assert not np.isnan(res["estimates"]).any()
    assert np.max(np.abs(res["estimates"] - res["reference"])) <= 1e-9
    assert s["inbox"]["late"] == 0 and s["dropped_at_sender"] == 0
    assert s["trigger_rate"] == pytest.approx(s["trigger_rate_in_process"])
    b = s["bytes_per_step"]
    # the payload on estimator links is the in-process float count plus a 28-byte header per packet
    packets_per_step = s["packets_estimator_to_estimator"] / s["steps"]
    assert b["estimator_to_estimator_wire"] >= b["estimator_to_estimator_payload"] > 0
    assert b["sensor_to_estimator_wire"] >= b["sensor_to_estimator_payload"] > 0
    assert packets_per_step == (2 if alg == "edc-cif" else 5) * 4


def test_swarm_kill_restart_and_loss(tmp_path):
    """One agent killed and restarted, 20 % of packets dropped at every sender, one
    link delayed: every agent finishes, every estimate is finite and PD, and the
    restarted agent converges back."""
    steps = 150
    res = agents.run_swarm(4, "edc-cif", seed=1, steps=steps, out=tmp_path, loss=0.2, loss_seed=3,
                           delay=[(0, 3, 0.01)], kill=(1, 30, 0.5), period_s=0.04, deadline_s=0.03)
    est, cov, truth = res["estimates"], res["covariances"], res["truth"]
    rejoined = [a for a in res["agents"] if a["rejoin"]]
    assert len(rejoined) == 1 and len(res["agents"]) == 4
    first = rejoined[0]["first_step"]
    assert 30 < first <= steps - 60
    valid = ~np.isnan(est).any(axis=2)
    assert valid[:, [0, 2, 3]].all() and valid[first:, 1].all() and not valid[30:first, 1].any()
    P = cov[valid]
    assert np.isfinite(est[valid]).all() and (np.linalg.eigvalsh(P) > 0).all()
    err = np.linalg.norm(est[:, :, :3] - truth[:, None, :3], axis=2)
    t = first + 50
    neighbours = edccif.Node(edccif.Scenario.paper(4), node=1).neighbours
    assert err[t:, 1].mean() <= 2 * err[t:, neighbours].mean()
    s = res["summary"]
    assert s["dropped_at_sender"] > 0 and s["inbox"]["late"] > 0


def test_swarm_command(tmp_path):
    out = subprocess.run(
        [sys.executable, "-m", "edccif", "swarm", "--nodes", "3", "--steps", "20", "--period", "0.06",
         "--sensor-wait", "0.045", "--out", str(tmp_path),
         "--json", str(tmp_path / "s.json")],
        capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert re.search(r"position RMSE +\d", out.stdout) and "estimator <-> estimator" in out.stdout
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["nodes"] == 3 and s["max_abs_diff_vs_in_process"] <= 1e-9


def test_docs_example_runs():
    text = DOCS.read_text()
    block = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    exec(compile(block, "docs/agents.md", "exec"), {"__name__": "__docs__"})


def test_docs_zenoh_deployment_config_loads():
    """The TLS/mTLS/access-control example holds only keys the pinned Zenoh reads."""
    zenoh = pytest.importorskip("zenoh")
    block = re.search(r"```json5\n(.*?)```", DOCS.read_text(), re.S).group(1)
    zenoh.Config.from_json5(block)
    with pytest.raises(Exception, match="enable_mtlz"):
        zenoh.Config.from_json5(block.replace("enable_mtls", "enable_mtlz"))
