"""A whole swarm on this machine (``edccif swarm``): its checks, processes, results and summary."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .. import _edccif
from .common import AgentError
from .inbox import COUNTERS
from .startup import _sleep_until_ns
from .swarm_file import write_swarm

MAX_PROCESSES_PER_CORE = 16
"""``edccif swarm`` starts 2 processes per node (agent and sensor), at most this
many per core of the machine."""


def _spawn(args: List[str], log: Path) -> subprocess.Popen:
    f = open(log, "w")
    try:
        return subprocess.Popen([sys.executable, "-m", "edccif", *args], stdout=f, stderr=subprocess.STDOUT)
    finally:
        f.close()


def run_swarm(
    nodes: int = 4,
    algorithm: str = "edc-cif",
    *,
    scenario: Optional[_edccif.Scenario] = None,
    seed: int = 0,
    steps: Optional[int] = None,
    out: os.PathLike[str] | str = "swarm",
    loss: float = 0.0,
    loss_seed: int = 0,
    delay: Sequence[Sequence[float]] = (),
    kill: Optional[Tuple[int, int, float]] = None,
    timeout_s: Optional[float] = None,
    force: bool = False,
    progress: bool = False,
    **settings: Any,
) -> Dict[str, Any]:
    """Runs a whole swarm on this machine: ``nodes`` agents and ``nodes`` sensors as
    processes on free loopback ports, then gathers their results.

    ``kill=(node, step, down_s)``: agent ``node`` is killed (SIGKILL) when step
    ``step`` starts and restarted ``down_s`` seconds later (it rejoins from its
    neighbours' estimate). ``loss``: fraction of packets dropped at every sender;
    ``delay``: ``[(from, to, seconds)]`` delays on agent links. ``settings``: swarm
    file settings (``period_s``, ``deadline_s``, ``options``, ``key``, ...).

    ``out`` receives ``swarm.json`` and the run directory ``run/``; when either
    exists already the call refuses (``AgentError``) unless ``force``, and even
    then it removes only the files a swarm run writes (it refuses a run directory
    holding anything else). Everything is checked before a file is touched or a
    process starts. ``progress``: a line on stderr at most every 5 s.

    Returns a dict with ``estimates`` (T, N, n; NaN where an agent had no
    estimate), ``covariances``, ``truth``, ``reference`` (the in-process ``run``
    estimates), ``summary`` (numbers printed by ``edccif swarm``), the per-process
    summaries and the run directory.
    """
    sc = scenario if scenario is not None else _edccif.Scenario.paper(nodes=nodes)
    if steps is not None:
        sc = sc.replace(steps=steps)
    k = sc.nodes
    check_swarm_request(sc, loss=loss, delay=delay, kill=kill)
    out = Path(out)
    run = out / "run"
    _clear_previous_run(out, force)
    out.mkdir(parents=True, exist_ok=True)
    run.mkdir(parents=True, exist_ok=True)
    truth, z, x0 = sc.simulate(seed=seed)
    faults = {"loss": loss, "loss_seed": loss_seed, "delay": [list(d) for d in delay]}
    spec = write_swarm(out / "swarm.json", sc, algorithm=algorithm, seed=seed, x0=x0, run_dir=run,
                       faults=faults, **settings)
    period = float(spec["period_s"])
    if timeout_s is None:
        # every phase of every step may wait out its deadline
        phases = _edccif.Node(sc, algorithm, node=0, **spec["options"]).rounds or 2
        timeout_s = 60.0 + sc.steps * (period + phases * float(spec["deadline_s"]))
    procs: Dict[str, subprocess.Popen] = {}
    swarm_file = str(out / "swarm.json")
    t_begin = time.monotonic()
    from .._args import Progress

    if progress:
        print(f"swarm: starting {2 * k} processes (logs in {run})", file=sys.stderr, flush=True)
    try:
        for i in range(k):
            procs[f"agent{i}"] = _spawn(["agent", "--swarm", swarm_file, "--node", str(i)], run / f"agent{i}.log")
            procs[f"sensor{i}"] = _spawn(["sensor", "--swarm", swarm_file, "--node", str(i)], run / f"sensor{i}.log")
        until = time.monotonic() + float(spec["ready_timeout_s"])
        while not (run / "ready").exists() or len(list((run / "ready").iterdir())) < 2 * k:
            dead = [n for n, p in procs.items() if p.poll() is not None]
            if dead or time.monotonic() > until:
                raise AgentError(f"swarm: {dead or 'some processes'} did not get ready; see the logs in {run}")
            time.sleep(0.01)
        start_ns = time.time_ns() + int(float(spec["start_margin_s"]) * 1e9)
        tmp = run / "start.json.tmp"
        tmp.write_text(json.dumps({"start_ns": start_ns}))
        tmp.rename(run / "start.json")
        bar = Progress("swarm", sc.steps, "steps", enabled=progress)
        if kill is not None:
            kn, ks, down = int(kill[0]), int(kill[1]), float(kill[2])
            _sleep_until_ns(start_ns + int(ks * period * 1e9))
            procs[f"agent{kn}"].send_signal(signal.SIGKILL)
            procs[f"agent{kn}"].wait()
            time.sleep(down)
            procs[f"agent{kn}-rejoin"] = _spawn(
                ["agent", "--swarm", swarm_file, "--node", str(kn), "--rejoin"], run / f"agent{kn}-rejoin.log")
        end = t_begin + timeout_s
        for name, p in procs.items():
            while True:
                bar.update(min(sc.steps, max(0, (time.time_ns() - start_ns) // max(1, int(period * 1e9)))))
                try:
                    p.wait(timeout=max(0.01, min(1.0, end - time.monotonic())))
                    break
                except subprocess.TimeoutExpired as e:
                    if time.monotonic() >= end:
                        raise AgentError(f"swarm: {name} did not finish within {timeout_s:.0f} s; see {run}") from e
        bar.update(sc.steps)
        bar.finish()
        failed = {n: p.returncode for n, p in procs.items()
                  if p.returncode != 0 and not (kill is not None and n == f"agent{kill[0]}")}
        if failed:
            logs = {n: (run / f"{n}.log").read_text()[-2000:] for n in failed}
            raise AgentError(f"swarm: processes failed {failed}: {logs}")
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    return gather(out, sc, truth, z, x0, algorithm, spec, kill)


def check_swarm_request(sc: _edccif.Scenario, *, loss: float = 0.0, delay: Sequence[Sequence[float]] = (),
                        kill: Optional[Tuple[int, int, float]] = None) -> None:
    """Checks a swarm's faults against its scenario (``ParameterError``) and its
    size against the machine (2 processes per node, at most
    :data:`MAX_PROCESSES_PER_CORE` per core), before anything starts."""
    k, steps = sc.nodes, sc.steps
    _check_swarm_size(k)
    if not (np.isfinite(loss) and 0.0 <= loss < 1.0):
        raise _edccif.ParameterError(f"loss: expected a probability in [0, 1), got {loss}")
    for d in delay:
        if len(d) != 3 or not (0 <= int(d[0]) < k and 0 <= int(d[1]) < k) or not float(d[2]) >= 0:
            raise _edccif.ParameterError(
                f"delay: expected FROM:TO:SECONDS with nodes in 0..{k - 1} and seconds >= 0, got {list(d)}")
    if kill is not None:
        kn, ks, down = int(kill[0]), int(kill[1]), float(kill[2])
        if not 0 <= kn < k:
            raise _edccif.ParameterError(f"kill: node {kn} is not in the swarm; expected 0..{k - 1}")
        if not 0 <= ks < steps:
            raise _edccif.ParameterError(f"kill: step {ks} is not in the run; expected 0..{steps - 1}")
        if not (np.isfinite(down) and down >= 0):
            raise _edccif.ParameterError(f"kill: expected a down time >= 0 s, got {down}")


def _check_swarm_size(k: int) -> None:
    cores = os.cpu_count() or 1
    if 2 * k > MAX_PROCESSES_PER_CORE * cores:
        raise _edccif.ParameterError(
            f"nodes: a swarm of {k} nodes starts {2 * k} processes; this machine takes at most "
            f"{MAX_PROCESSES_PER_CORE * cores} ({MAX_PROCESSES_PER_CORE} per core x {cores}), "
            f"so at most {MAX_PROCESSES_PER_CORE * cores // 2} nodes")


_RUN_FILE = re.compile(r"^(agent\d+(-rejoin)?\.(log|npz|json|mcap)|sensor\d+\.(log|json)|start\.json(\.tmp)?)$")


_READY_FILE = re.compile(r"^(agent\d+(-rejoin)?|sensor\d+)$")


def _clear_previous_run(out: Path, force: bool) -> None:
    """Refuses an ``out`` with an earlier run's ``swarm.json`` or ``run/`` unless
    ``force``; with ``force`` removes only what a swarm run writes there."""
    if out.exists() and not out.is_dir():
        raise AgentError(f"out: {out} is a file; expected a directory")
    run, swarm_file = out / "run", out / "swarm.json"
    if not (run.exists() or swarm_file.exists()):
        return
    if not force:
        raise AgentError(f"out: {out} holds an earlier swarm run (swarm.json or run/); "
                         "choose another directory or pass --force (force=True) to replace it")
    if run.exists():
        if not run.is_dir():
            raise AgentError(f"out: {run} is not a directory; not replacing it")
        ready = run / "ready"
        foreign = [f for f in run.iterdir() if not (_RUN_FILE.match(f.name) and f.is_file())
                   and f != ready]
        if ready.exists():
            foreign += [f for f in ready.iterdir() if not (_READY_FILE.match(f.name) and f.is_file())]
        if foreign:
            names = ", ".join(map(str, foreign[:3]))
            raise AgentError(f"out: {run} holds files a swarm run does not write ({names}); not replacing it")
        shutil.rmtree(run)
    if swarm_file.exists():
        swarm_file.unlink()


def gather(out: Path, sc: _edccif.Scenario, truth: np.ndarray, z: np.ndarray, x0: np.ndarray, algorithm: str,
           spec: Dict[str, Any], kill: Optional[Tuple[int, int, float]]) -> Dict[str, Any]:
    """Collects the agents' and sensors' outputs of a swarm run (see :func:`run_swarm`)."""
    run = Path(spec["run_dir"])
    k, steps, n = sc.nodes, sc.steps, sc.state_dim
    est = np.full((steps, k, n), np.nan)
    cov = np.full((steps, k, n, n), np.nan)
    agents, sensors = [], []
    for i in range(k):
        for tag in ("", "-rejoin"):
            f = run / f"agent{i}{tag}.npz"
            if f.exists():
                d = np.load(f)
                ok = np.all(np.isfinite(d["estimates"]), axis=1)
                est[ok, i] = d["estimates"][ok]
                cov[ok, i] = d["covariances"][ok]
                agents.append(json.loads((run / f"agent{i}{tag}.json").read_text()))
        sensors.append(json.loads((run / f"sensor{i}.json").read_text()))
    ref = _edccif.run(algorithm, sc, z, x0=x0, **spec["options"])
    d = sc.position_dim or n  # the position axes (all states for a motion that names none)
    err = np.linalg.norm(est[:, :, :d] - truth[:, None, :d], axis=2)
    ref_err = np.linalg.norm(ref.estimates[:, :, :d] - truth[:, None, :d], axis=2)
    measured = sum(s["measured"] for s in sensors)
    triggered = sum(s["triggered"] for s in sensors)
    wire = {lk: sum(p["wire"][lk]["sent"] for p in agents + sensors) for lk in ("sensor_link", "estimator_link")}
    s2e_wire = sum(s["wire"]["sensor_link"]["sent"] for s in sensors)
    e2s_wire = sum(s["wire"]["sensor_link"]["received"] for s in sensors)
    payload_s2e = sum(s["sent"]["measurement"]["bytes"] for s in sensors)
    payload_e2e = sum(a["sent"][kd]["link_bytes"] for a in agents for kd in a["sent"])
    packets_e2e = sum(a["sent"][kd]["packets"] for a in agents for kd in a["sent"])
    inbox = {c: sum(a["inbox"].get(c, 0) for a in agents) for c in COUNTERS}
    dropped = sum(p["sent"][kd]["dropped"] for p in agents + sensors for kd in p["sent"])
    vs = ref.values_sent
    summary = {
        "algorithm": algorithm,
        "nodes": k,
        "steps": steps,
        "position_rmse_m": float(np.sqrt(np.nanmean(err**2))),
        "position_rmse_in_process_m": float(np.sqrt(np.mean(ref_err**2))),
        "max_abs_diff_vs_in_process": float(np.nanmax(np.abs(est - ref.estimates))) if kill is None and
        spec["faults"].get("loss", 0) == 0 else None,
        "trigger_rate": triggered / measured if measured else 0.0,
        "trigger_rate_in_process": ref.trigger_rate,
        "bytes_per_step": {
            "sensor_to_estimator_wire": s2e_wire / steps,
            "estimator_to_sensor_wire": e2s_wire / steps,
            "estimator_to_estimator_wire": wire["estimator_link"] / steps,
            "sensor_to_estimator_payload": payload_s2e / steps,
            "estimator_to_estimator_payload": payload_e2e / steps,
            "sensor_to_estimator_in_process": 8 * vs["sensor_to_estimator"] / steps,
            "estimator_to_estimator_in_process": 8 * vs["estimator_to_estimator"] / steps,
        },
        "packets_estimator_to_estimator": packets_e2e,
        "dropped_at_sender": dropped,
        "inbox": inbox,
    }
    return {"estimates": est, "covariances": cov, "truth": truth, "reference": ref.estimates, "summary": summary,
            "agents": agents, "sensors": sensors, "run_dir": str(run)}


def format_summary(s: Dict[str, Any]) -> str:
    """The text ``edccif swarm`` prints."""
    b = s["bytes_per_step"]
    lines = [
        f"swarm: {s['algorithm']}, {s['nodes']} agents + {s['nodes']} sensors, {s['steps']} steps (Zenoh, loopback)",
        f"position RMSE            {s['position_rmse_m']:.4f} m   (in-process run: "
        f"{s['position_rmse_in_process_m']:.4f} m)",
        f"trigger rate             {s['trigger_rate']:.3f}      (in-process run: {s['trigger_rate_in_process']:.3f})",
    ]
    if s.get("max_abs_diff_vs_in_process") is not None:
        lines.append(f"max |swarm - in-process| {s['max_abs_diff_vs_in_process']:.3g}")
    lines += [
        "bytes per step           TCP (Zenoh)   wire-format payload   in-process (8 B x floats)",
        f"  sensor -> estimator    {b['sensor_to_estimator_wire']:>11.1f}   {b['sensor_to_estimator_payload']:>19.1f}"
        f"   {b['sensor_to_estimator_in_process']:>25.1f}",
        f"  estimator -> sensor    {b['estimator_to_sensor_wire']:>11.1f}   {0.0:>19.1f}   {0.0:>25.1f}",
        f"  estimator <-> estimator {b['estimator_to_estimator_wire']:>10.1f}   "
        f"{b['estimator_to_estimator_payload']:>19.1f}   {b['estimator_to_estimator_in_process']:>25.1f}",
        f"packets: dropped at sender {s['dropped_at_sender']}, late {s['inbox']['late']}, "
        f"foreign swarm {s['inbox']['foreign_swarm']}, unknown sender {s['inbox']['unknown_sender']}, "
        f"malformed {s['inbox']['malformed']}",
        f"rejected: unauthenticated {s['inbox']['unauthenticated']}, unusable {s['inbox']['unusable']}, "
        f"replayed {s['inbox']['replayed']}, out of window {s['inbox']['out_of_window']}, "
        f"duplicate {s['inbox']['duplicate']}, fusion fallbacks {s['inbox']['fusion_fallbacks']}",
    ]
    return "\n".join(lines)
