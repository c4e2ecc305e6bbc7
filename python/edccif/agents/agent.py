"""An estimator node as its own process (``edccif agent``): its step loop over the node phases."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Dict, Tuple

import numpy as np

from .. import _edccif
from .common import AgentError, key
from .inbox import _Inbox, _Sender
from .startup import _ready_wait, _wait_start
from .swarm_file import load_swarm, swarm_key
from .transport import _port, _zenoh, tcp_bytes, zenoh_config


def _info_to_gaussian(p: Any) -> Tuple[np.ndarray, np.ndarray]:
    if p.kind == "estimate":
        return np.asarray(p.vector), np.asarray(p.matrix)
    cov = np.linalg.inv(np.asarray(p.matrix))
    cov = 0.5 * (cov + cov.T)
    return cov @ np.asarray(p.vector), cov


def _fuse(phase: Any, got: Dict[int, Any], inbox: _Inbox) -> Any:
    """Runs a fusion phase with the packets that arrived (ascending sender); if the
    phase refuses them together (each passed :func:`unusable` alone), it runs
    again with none, which leaves the node's own estimate (a failed phase changes
    nothing), and the fallback is counted."""
    try:
        return phase([(j, p.vector, p.matrix) for j, p in sorted(got.items())])
    except _edccif.EdccifError:
        if not got:
            raise
        with inbox.cv:
            inbox.counts["fusion_fallbacks"] += 1
        return phase([])


def run_agent(path: os.PathLike[str] | str, node: int, *, rejoin: bool = False) -> Dict[str, Any]:
    """Runs estimator node ``node`` of the swarm file ``path`` to the last step;
    writes ``agent{node}.npz``/``.json`` (and ``.mcap`` when ``edccif.write_mcap``
    exists) into the run directory and returns the summary. ``rejoin``: start
    mid-run from the newest neighbour estimate (a restarted agent)."""
    spec, sc = load_swarm(path)
    k, swarm = sc.nodes, int(spec["swarm"])
    if not 0 <= node < k:
        raise AgentError(f"node: expected an index in 0..{k}, got {node}")
    nd = _edccif.Node(sc, spec["algorithm"], node=node, x0=spec["x0"], **spec["options"])
    neighbours = nd.neighbours
    steps, period = sc.steps, float(spec["period_s"])
    faults = spec["faults"]
    delays = {int(d[0]): float(d[2]) for d in faults.get("delay", []) if int(d[1]) == node}
    agents = spec["agents"]
    zenoh = _zenoh()
    key_bytes = swarm_key(spec)
    inbox = _Inbox(swarm, node, neighbours, delays, key=key_bytes, state_dim=nd.state_dim,
                   measurement_dim=nd.meas_dim, rounds=nd.rounds, window=int(spec["step_window"]))
    # the higher index connects to the lower one: one TCP connection per link
    connect = [agents[j]["listen"] for j in neighbours if j < node]
    session = zenoh.open(zenoh_config([agents[node]["listen"], agents[node]["sensor_listen"]], connect,
                                      agents[node].get("zenoh_config", spec["zenoh_config"])))
    tag = "-rejoin" if rejoin else ""
    run = Path(spec["run_dir"])
    try:
        subs = [session.declare_subscriber(key(swarm, node, "measurement"), inbox.on_sample)]
        for j in neighbours:
            subs.append(session.declare_subscriber(f"edccif/{swarm}/{j}/*", inbox.on_sample))
        alive_sub = session.liveliness().declare_subscriber(f"edccif/{swarm}/*/alive", inbox.on_alive, history=True)
        kinds = ["contribution", "information", "estimate"]
        seed = int(faults.get("loss_seed", 0)) * 100_003 + 2 * node + (7919 if rejoin else 0)
        tx = _Sender(session, swarm, node, kinds, float(faults.get("loss", 0.0)), seed, len(neighbours),
                     tag_key=key_bytes)
        token = None
        if not rejoin:
            # alive before ready: at step 0 every neighbour is waited for
            token = session.liveliness().declare_token(key(swarm, node, "alive"))
            _ready_wait(lambda: set(neighbours) <= inbox.alive_now() and tx.matched(),
                        float(spec["ready_timeout_s"]))
        start_ns = _wait_start(spec, "agent" + tag, node)
        inbox.start(start_ns, period)
        n = nd.state_dim
        est = np.full((steps, n), np.nan)
        cov = np.full((steps, n, n), np.nan)
        trig = np.zeros(steps, dtype=bool)
        first = 0
        if rejoin:
            got = inbox.first_estimate(time.monotonic() + max(5.0, 20 * period))
            if got is None:
                raise AgentError(f"agent {node}: no neighbour estimate to rejoin from")
            s, p = got
            x, P = _info_to_gaussian(p)
            nd.reset(x, P)
            now_step = int((time.time_ns() - start_ns) // int(period * 1e9))
            first = max(s + 1, now_step)
            inbox.forget_before(first)
            token = session.liveliness().declare_token(key(swarm, node, "alive"))
        fusion, rounds = nd.fusion, nd.rounds
        deadline = float(spec["deadline_s"])
        for t in range(first, steps):
            t_ns = start_ns + int(round(t * period * 1e9))
            if nd.measures(t):
                wait_until = time.monotonic() + max(0.0, (t_ns - time.time_ns()) / 1e9
                                                    + float(spec["sensor_wait_s"]))
                got = inbox.wait("measurement", t, 0, [node], wait_until)
                z = got[node].vector if node in got else None
                trig[t] = z is not None
            else:
                # the sensor's rate (`every`/`times`): no measurement at this step, none is waited for
                z = np.full(nd.meas_dim, np.nan)
            pkt = nd.local(z)
            if fusion.startswith("diffusion"):
                tx.send(pkt[0], pkt[1], pkt[2], t, 0, t_ns)
                got = inbox.wait("contribution", t, 0, neighbours, time.monotonic() + deadline)
                pkt = _fuse(nd.adapt, got, inbox)
                tx.send(pkt[0], pkt[1], pkt[2], t, 0, t_ns)
                got = inbox.wait(pkt[0], t, 0, neighbours, time.monotonic() + deadline)
                _fuse(nd.combine, got, inbox)
            elif fusion == "consensus":
                for r in range(rounds):
                    tx.send(pkt[0], pkt[1], pkt[2], t, r, t_ns)
                    got = inbox.wait("information", t, r, neighbours, time.monotonic() + deadline)
                    pkt = _fuse(nd.consensus_round, got, inbox)
            x, P = nd.estimate, nd.covariance
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P)) and np.all(np.linalg.eigvalsh(P) > 0)):
                raise AgentError(f"agent {node}: estimate at step {t} is not finite and positive definite")
            est[t], cov[t] = x, P
        # measured before anyone closes: every process lingers after its last step
        time.sleep(0.05)
        wire = tcp_bytes([_port(a["sensor_listen"]) for a in agents], [_port(a["listen"]) for a in agents])
        time.sleep(float(spec["linger_s"]))
        if token is not None:
            token.undeclare()
        alive_sub.undeclare()
        for s_ in subs:
            s_.undeclare()
    finally:
        session.close()
    summary = {
        "role": "agent",
        "node": node,
        "rejoin": rejoin,
        "first_step": first,
        "steps": steps,
        "algorithm": nd.algorithm,
        "sent": tx.counts,
        "inbox": inbox.counts,
        "wire": wire,
        "counters": dict(nd.counters),
        "triggered_steps": int(trig.sum()),
    }
    np.savez(run / f"agent{node}{tag}.npz", estimates=est, covariances=cov, triggered=trig, first=first)
    (run / f"agent{node}{tag}.json").write_text(json.dumps(summary, indent=1))
    writer = getattr(_edccif, "write_mcap", None)
    if writer is not None:
        writer(run / f"agent{node}{tag}.mcap", dt=sc.dt, fused=est[:, None, :], covariances=cov[:, None],
               t0_ns=start_ns, nodes=[node])
    return summary
