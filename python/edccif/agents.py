"""Live agents: every estimator node and every sensor its own process, talking over Zenoh.

A *swarm file* (JSON, written by :func:`write_swarm` or ``edccif swarm``) says
everything the processes share: the scenario, the algorithm row and its options,
the swarm id, the step period, the deadlines, the loopback (or real) endpoints and
the faults to inject. Then

- ``edccif agent --swarm FILE --node I`` runs estimator node ``I``
  (:func:`run_agent`): at each step it waits for its sensor's measurement (up to
  ``sensor_wait_s`` after the step's start), runs its local phase, publishes its
  packet and waits for its neighbours' packets of each fusion phase (up to
  ``deadline_s`` per phase), then fuses what arrived (weights renormalised over
  it). Packets that arrive after their phase are dropped and counted as late;
  packets without a valid authentication tag (HMAC-SHA256 under the swarm file's
  key), whose header names another swarm or a sender that is not a neighbour,
  that cannot be used (wrong dimension, indefinite matrix), or whose step is far
  from the agent's (replayed, or too far ahead) are rejected and counted; the
  agent goes on.
- ``edccif sensor --swarm FILE --node I`` runs sensor ``I`` (:func:`run_sensor`):
  at each step's start it takes its measurement (simulated from the scenario and
  seed, or replayed from an MCAP or TUM file) and runs its event trigger; only
  triggered measurements are published.
- ``edccif swarm --nodes N`` (:func:`run_swarm`) writes a swarm file with free
  loopback ports, starts ``N`` agents and ``N`` sensors, starts them together,
  injects the faults asked for (kill and restart an agent), waits, gathers every
  agent's estimates and prints the position RMSE, the trigger rate and the bytes
  sent per link type — measured on the agents' and sensors' TCP sockets — beside
  the in-process accounting of ``run``.

Key expressions (one per swarm, node and kind)::

    edccif/<swarm>/<node>/measurement    sensor <node> -> its agent
    edccif/<swarm>/<node>/contribution   agent <node> -> neighbours (diffusion adaptation)
    edccif/<swarm>/<node>/information    agent <node> -> neighbours (CI combination, consensus rounds)
    edccif/<swarm>/<node>/estimate       agent <node> -> neighbours (convex combination)
    edccif/<swarm>/<node>/alive          liveliness token of agent <node>

Payloads are signed packets of the wire format (``edccif.encode_packet(...,
key=)``, docs/formats.md); the tag, then the header's swarm, sender, step and
round are checked against the key expression, the receiver's swarm and its step.
See docs/agents.md (and its threat model).

This module needs the ``agents`` extra (``pip install 'edccif[agents]'``, the
``eclipse-zenoh`` wheel); it is imported only by the commands above.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import secrets
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _edccif

KINDS = ("measurement", "contribution", "information", "estimate")
"""Message kinds, as in the key expressions and the wire format."""

DEFAULTS: Dict[str, Any] = {
    "swarm": 1,
    "algorithm": "edc-cif",
    "options": {},
    "seed": 0,
    "period_s": 0.05,
    "sensor_wait_s": 0.025,
    "deadline_s": 1.0,
    "start_margin_s": 0.5,
    "ready_timeout_s": 60.0,
    "linger_s": 0.3,
    "faults": {},
    "source": {"kind": "simulate"},
    "zenoh_config": None,
    "start_ns": None,
    "key": None,
    "step_window": 8,
}
"""Swarm-file defaults (every key may be overridden in the file). ``key``: the
packets' authentication key, hex (at least 16 bytes; :func:`write_swarm` draws 32
random bytes when none is given); ``step_window``: how many steps before or
after its own an agent accepts a packet for."""

MAX_PROCESSES_PER_CORE = 16
"""``edccif swarm`` starts 2 processes per node (agent and sensor), at most this
many per core of the machine."""


class AgentError(_edccif.EdccifError):
    """A swarm file or an agent run is invalid (a ``ValueError``)."""


def key(swarm: int, node: int, kind: str) -> str:
    """The key expression of ``kind`` messages of ``node`` in ``swarm``.

    >>> key(1, 3, "contribution")
    'edccif/1/3/contribution'
    """
    return f"edccif/{swarm}/{node}/{kind}"


def free_ports(n: int) -> List[int]:
    """``n`` distinct TCP ports free on 127.0.0.1 now (the OS picks them)."""
    socks, ports = [], []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind(("127.0.0.1", 0))
            socks.append(s)
            ports.append(s.getsockname()[1])
    finally:
        for s in socks:
            s.close()
    return ports


# --------------------------------------------------------------------------- swarm file


def write_swarm(
    path: os.PathLike[str] | str,
    scenario: _edccif.Scenario,
    *,
    algorithm: str = "edc-cif",
    seed: int = 0,
    x0: Optional[Sequence[float]] = None,
    host: str = "127.0.0.1",
    ports: Optional[Sequence[int]] = None,
    run_dir: os.PathLike[str] | str | None = None,
    **settings: Any,
) -> Dict[str, Any]:
    """Writes a swarm file and returns its content.

    ``ports``: 2 per node (estimator links ``ports[2i]``, sensor link
    ``ports[2i+1]``; default: free loopback ports). ``settings`` override
    :data:`DEFAULTS` (``options``, ``period_s``, ``sensor_wait_s``, ``deadline_s``,
    ``faults`` {``loss``, ``loss_seed``, ``delay``: [[from, to, seconds], ...]},
    ``source`` {``kind``: "simulate" | "mcap" | "tum", ``path``/``paths``}, ...).
    """
    k = scenario.nodes
    ports = list(ports) if ports is not None else free_ports(2 * k)
    if len(ports) != 2 * k:
        raise AgentError(f"ports: expected {2 * k} ports (2 per node), got {len(ports)}")
    unknown = set(settings) - set(DEFAULTS)
    if unknown:
        raise _edccif.UnknownOptionError(
            f"unknown swarm setting(s) {sorted(unknown)}; expected some of {sorted(DEFAULTS)}"
        )
    if x0 is None:
        x0 = scenario.simulate(seed=seed)[2] if settings.get("source", DEFAULTS["source"])["kind"] == "simulate" \
            else scenario.x0
    path = Path(path)
    spec: Dict[str, Any] = dict(DEFAULTS)
    spec.update(settings)
    if spec["key"] is None:
        spec["key"] = secrets.token_hex(32)
    spec.update(
        {
            "algorithm": algorithm,
            "seed": seed,
            "scenario": _portable_scenario(scenario),
            "x0": [float(v) for v in np.asarray(x0, dtype=float)],
            "agents": [
                {
                    "node": i,
                    "listen": f"tcp/{host}:{ports[2 * i]}",
                    "sensor_listen": f"tcp/{host}:{ports[2 * i + 1]}",
                }
                for i in range(k)
            ],
            "run_dir": str(Path(run_dir) if run_dir is not None else path.parent / f"{path.stem}-run"),
        }
    )
    load_swarm_dict(spec)  # validate
    path.parent.mkdir(parents=True, exist_ok=True)
    # the file holds the swarm's key: readable by its owner only
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(json.dumps(spec, indent=1))
    return spec


def _portable_scenario(sc: _edccif.Scenario) -> Dict[str, Any]:
    """The scenario's dict for a swarm file, its ``python_path`` (the
    directories of its referenced Python models, relative to the scenario
    file) made absolute, so that every agent and sensor process imports the
    same modules wherever the swarm file is."""
    d = sc.to_dict()
    if d.get("python_path"):
        base = Path(sc.base_dir or os.getcwd())
        d["python_path"] = [str((base / p).resolve()) for p in d["python_path"]]
    return d


def swarm_key(spec: Dict[str, Any]) -> bytes:
    """The packets' authentication key of a (validated) swarm dict."""
    return bytes.fromhex(spec["key"])


def load_swarm_dict(spec: Dict[str, Any], base_dir: Optional[os.PathLike[str] | str] = None
                    ) -> Tuple[Dict[str, Any], _edccif.Scenario]:
    """Validates a swarm dict; returns it with defaults filled in, and its scenario.
    ``base_dir``: where a relative ``python_path`` of the scenario (the
    directories of its Python models named by reference) starts; default the
    working directory (:func:`load_swarm` passes the swarm file's directory)."""
    out = dict(DEFAULTS)
    out.update(spec)
    for name in ("scenario", "agents", "x0", "run_dir"):
        if name not in out:
            raise AgentError(f"swarm file: missing {name!r}")
    sc = _edccif.Scenario.from_dict(out["scenario"], base_dir=base_dir)
    if len(out["agents"]) != sc.nodes:
        raise AgentError(f"swarm file: expected {sc.nodes} agents (one per node), got {len(out['agents'])}")
    if not 0 <= int(out["swarm"]) <= 0xFFFFFFFF:
        raise AgentError(f"swarm: expected an id in 0..=4294967295, got {out['swarm']}")
    for name in ("period_s", "sensor_wait_s", "deadline_s"):
        v = float(out[name])
        if not (np.isfinite(v) and v > 0):
            raise _edccif.ParameterError(f"{name}: expected a finite number > 0, got {out[name]}")
    loss = float(out["faults"].get("loss", 0.0))
    if not 0.0 <= loss < 1.0:
        raise _edccif.ParameterError(f"faults.loss: expected a probability in [0, 1), got {loss}")
    for d in out["faults"].get("delay", []):
        if len(d) != 3 or not (0 <= int(d[0]) < sc.nodes and 0 <= int(d[1]) < sc.nodes) or float(d[2]) < 0:
            raise _edccif.ParameterError(f"faults.delay: expected [from, to, seconds >= 0] entries, got {d}")
    k = out.get("key")
    try:
        ok = isinstance(k, str) and len(bytes.fromhex(k)) >= 16
    except ValueError:
        ok = False
    if not ok:
        raise AgentError("swarm file: 'key' must be the packets' authentication key as hex, at least 16 bytes "
                         "(32 hex digits); write_swarm draws one")
    w = out["step_window"]
    if isinstance(w, bool) or not isinstance(w, int) or w < 1:
        raise _edccif.ParameterError(f"step_window: expected an integer >= 1, got {w!r}")
    if out["source"].get("kind") not in ("simulate", "mcap", "tum"):
        raise _edccif.ParameterError(
            f"source.kind: expected 'simulate', 'mcap' or 'tum', got {out['source'].get('kind')!r}"
        )
    return out, sc


def load_swarm(path: os.PathLike[str] | str) -> Tuple[Dict[str, Any], _edccif.Scenario]:
    """Reads and validates a swarm file (see :func:`write_swarm`)."""
    try:
        spec = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise AgentError(f"swarm file {path}: {e}") from e
    return load_swarm_dict(spec, base_dir=Path(path).resolve().parent)


# --------------------------------------------------------------------------- zenoh


def _zenoh() -> Any:
    try:
        import zenoh
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise AgentError(
            "the agents need the eclipse-zenoh package: pip install 'edccif[agents]'"
        ) from e
    return zenoh


def zenoh_config(listen: Sequence[str], connect: Sequence[str], base: Optional[str] = None) -> Any:
    """A peer configuration on explicit endpoints with every kind of scouting off, so
    that a process talks exactly to the endpoints it is given. ``base``: a Zenoh
    JSON5 configuration file to start from (TLS, access control; docs/agents.md)."""
    zenoh = _zenoh()
    c = zenoh.Config.from_file(base) if base else zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    return c


def _port(endpoint: str) -> int:
    return int(endpoint.rsplit(":", 1)[1])


def tcp_bytes(sensor_ports: Sequence[int], agent_ports: Sequence[int]) -> Dict[str, Dict[str, int]]:
    """Bytes this process sent and received on its TCP connections, from the
    kernel (``TCP_INFO``: ``tcpi_bytes_acked``, ``tcpi_bytes_received``), by link
    type: a connection to or from a sensor port is a sensor link, to or from an
    agent port an estimator link. Zenoh's own framing, keep-alives and
    declarations are included; TCP/IP headers are not."""
    out = {"sensor_link": {"sent": 0, "received": 0}, "estimator_link": {"sent": 0, "received": 0}}
    sp, ap = set(sensor_ports), set(agent_ports)
    for fd in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                continue
            s = socket.socket(fileno=os.dup(int(fd)))
        except (OSError, ValueError):
            continue
        try:
            if s.type != socket.SOCK_STREAM or s.family != socket.AF_INET:
                continue
            try:
                local, peer = s.getsockname()[1], s.getpeername()[1]
            except OSError:
                continue
            info = s.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 256)
            if len(info) < 136:
                continue
            acked, received = struct.unpack_from("QQ", info, 120)
            kind = "sensor_link" if (local in sp or peer in sp) else "estimator_link" if (
                local in ap or peer in ap) else None
            if kind:
                out[kind]["sent"] += acked
                out[kind]["received"] += received
        finally:
            s.close()
    return out


COUNTERS = ("received", "late", "foreign_swarm", "unknown_sender", "malformed", "unauthenticated", "unusable",
            "replayed", "out_of_window", "duplicate", "fusion_fallbacks")
"""An agent's inbox counters (``agent{i}.json``'s ``inbox``, summed by ``edccif swarm``):
packets kept (``received``) and every reason a packet was dropped (docs/agents.md)."""


def unusable(p: Any, state_dim: int, measurement_dim: int, rounds: int) -> Optional[str]:
    """Why a decoded, authenticated packet cannot be used by an agent, or ``None``:
    a dimension other than its kind's, a round out of range, an information or
    covariance matrix that is not positive definite (Cholesky). A contribution's
    ``Ī`` may be indefinite by design (an untriggered step's has a negative part,
    ALGORITHM.md §3); the adaptation guard handles a sum that is not positive
    definite."""
    d = int(p.vector.shape[0])
    if p.kind == "measurement":
        if d != measurement_dim:
            return f"measurement of dimension {d}, expected {measurement_dim}"
        return None if int(p.round) == 0 else f"measurement with round {p.round}, expected 0"
    if d != state_dim:
        return f"{p.kind} of dimension {d}, expected {state_dim}"
    if int(p.round) >= (max(rounds, 1) if p.kind == "information" else 1):
        return f"{p.kind} with round {p.round}, expected below {max(rounds, 1) if p.kind == 'information' else 1}"
    if p.kind == "contribution":
        return None
    try:
        np.linalg.cholesky(np.asarray(p.matrix))
    except np.linalg.LinAlgError:
        return f"{p.kind} matrix is not positive definite"
    return None


class _Inbox:
    """Packets received, by (kind, step, round) and sender; callbacks run on Zenoh's
    threads, the step loop waits on the condition.

    A packet is kept only when its tag verifies under ``key``, its header names
    this swarm and the sender of its key expression (a neighbour, or this node's
    own sensor), it is usable (:func:`unusable`), its step is neither more than
    ``window`` steps behind the step being waited for nor more than ``window``
    steps ahead of the step the swarm's clock says, its timestamp is its step's
    time in this run (once :meth:`start` gave the clock; a packet of an earlier
    run with the same key has another), its phase is not over, and no packet of
    the same sender, kind, step and round came before."""

    def __init__(self, swarm: int, me: int, neighbours: Sequence[int], delays: Dict[int, float], *,
                 key: bytes, state_dim: int, measurement_dim: int = 3, rounds: int = 0, window: int = 8):
        self.cv = threading.Condition()
        self.swarm, self.me, self.neighbours = swarm, me, set(neighbours)
        self.delays = delays
        self.key, self.n, self.m, self.rounds, self.window = key, state_dim, measurement_dim, rounds, window
        self.slots: Dict[Tuple[str, int, int], Dict[int, Tuple[float, Any]]] = {}
        self.cursor: Tuple[int, int] = (-1, 0)  # (step, phase) being waited for
        self.clock: Optional[Tuple[int, float]] = None  # (start_ns, period_s)
        self.alive: set = set()
        self.counts = {c: 0 for c in COUNTERS}
        self.counts["bytes_received"] = 0

    def start(self, start_ns: int, period_s: float) -> None:
        """Gives the swarm's clock (step ``t`` starts at ``start_ns + round(t ·
        period_s · 1e9)`` ns, the packets' timestamp); packets kept before that
        are checked against it now."""
        with self.cv:
            self.clock = (int(start_ns), float(period_s))
            for k in list(self.slots):
                slot = self.slots[k]
                for j in [j for j, (_, p) in slot.items() if not self._stamp_ok(p)]:
                    del slot[j]
                    self.counts["received"] -= 1
                    self.counts["replayed"] += 1

    def _stamp_ok(self, p: Any) -> bool:
        if self.clock is None:
            return True
        return int(p.stamp_ns) == self.clock[0] + int(round(int(p.step) * self.clock[1] * 1e9))

    def _ahead_limit(self) -> int:
        step = max(self.cursor[0], 0)
        if self.clock is not None:
            step = max(step, (time.time_ns() - self.clock[0]) // max(1, int(self.clock[1] * 1e9)))
        return step + self.window

    @staticmethod
    def phase_of(kind: str, rnd: int) -> int:
        return 0 if kind == "measurement" else 1 if kind == "contribution" else 2 + rnd

    def on_sample(self, sample: Any) -> None:
        try:
            data = sample.payload.to_bytes()
            parts = str(sample.key_expr).split("/")
        except Exception:  # noqa: BLE001 - nothing from the network may end the agent
            with self.cv:
                self.counts["malformed"] += 1
            return
        try:
            p = _edccif.decode_packet(data, key=self.key)
            bad = None
        except _edccif.EdccifError as e:
            p, bad = None, "unauthenticated" if "authentication tag" in str(e) else "malformed"
        why = None
        if p is not None and p.swarm == self.swarm:
            try:
                why = unusable(p, self.n, self.m, self.rounds)
            except Exception:  # noqa: BLE001
                why = "cannot be checked"
        with self.cv:
            self.counts["bytes_received"] += len(data)
            if p is None:
                self.counts[bad or "malformed"] += 1
                return
            if p.swarm != self.swarm:
                self.counts["foreign_swarm"] += 1
                return
            if len(parts) != 4 or parts[3] != p.kind or parts[2] != str(p.sender):
                self.counts["unknown_sender"] += 1
                return
            if p.kind == "measurement":
                ok = p.sender == self.me
            else:
                ok = p.sender in self.neighbours
            if not ok:
                self.counts["unknown_sender"] += 1
                return
            if why is not None:
                self.counts["unusable"] += 1
                return
            step = int(p.step)
            if step > self._ahead_limit():
                self.counts["out_of_window"] += 1
                return
            at = (step, self.phase_of(p.kind, int(p.round)))
            if step < self.cursor[0] - self.window or not self._stamp_ok(p):
                self.counts["replayed"] += 1
                return
            if at < self.cursor:
                self.counts["late"] += 1
                return
            slot = self.slots.setdefault((p.kind, step, int(p.round)), {})
            if int(p.sender) in slot:
                self.counts["duplicate"] += 1
                return
            visible = time.monotonic() + self.delays.get(int(p.sender), 0.0) if p.kind != "measurement" \
                else time.monotonic()
            slot[int(p.sender)] = (visible, p)
            self.counts["received"] += 1
            self.cv.notify_all()

    def on_alive(self, sample: Any) -> None:
        parts = str(sample.key_expr).split("/")
        try:
            j = int(parts[2])
        except (IndexError, ValueError):
            return
        zenoh = _zenoh()
        with self.cv:
            if sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(j)
            else:
                self.alive.discard(j)
            self.cv.notify_all()

    def wait(self, kind: str, step: int, rnd: int, expect: Sequence[int], until: float) -> Dict[int, Any]:
        """Waits until every expected sender that is alive has a visible packet of
        (kind, step, round), or the monotonic time ``until``; returns the visible
        packets by sender and counts the others (arriving later) as late."""
        k = (kind, step, rnd)
        with self.cv:
            self.cursor = (step, self.phase_of(kind, rnd))
            while True:
                now = time.monotonic()
                slot = self.slots.get(k, {})
                have = {j for j, (vis, _) in slot.items() if vis <= now}
                missing = [j for j in expect if j not in have and (kind == "measurement" or j in self.alive)]
                if not missing or now >= until:
                    break
                pending = [vis for j, (vis, _) in slot.items() if vis > now]
                self.cv.wait(timeout=max(0.0, min([until] + pending) - now))
            now = time.monotonic()
            slot = self.slots.pop(k, {})
            got = {j: p for j, (vis, p) in slot.items() if vis <= now and j in expect}
            self.counts["late"] += sum(1 for _, (vis, _) in slot.items() if vis > now)
            # the next phase starts: everything at or before this one is late from now on
            self.cursor = (step, self.phase_of(kind, rnd) + 1)
            for old in [s for s in self.slots if (s[1], self.phase_of(s[0], s[2])) < self.cursor]:
                self.counts["late"] += len(self.slots.pop(old))
            return got

    def alive_now(self) -> set:
        with self.cv:
            return set(self.alive)

    def forget_before(self, step: int) -> None:
        """Drops the packets of steps before ``step`` (a rejoining agent's backlog)."""
        with self.cv:
            for s in [s for s in self.slots if s[1] < step]:
                del self.slots[s]
            self.cursor = (step, 0)

    def first_estimate(self, until: float) -> Optional[Tuple[int, Any]]:
        """The newest neighbour packet carrying an estimate (information or estimate
        kind), waiting for one until ``until``: (step, packet)."""
        with self.cv:
            while True:
                best = None
                for (kind, step, _rnd), slot in self.slots.items():
                    if kind in ("information", "estimate") and slot and (best is None or step > best[0]):
                        best = (step, next(iter(slot.values()))[1])
                if best is not None or time.monotonic() >= until:
                    return best
                self.cv.wait(timeout=max(0.0, until - time.monotonic()))


class _Sender:
    """Publishes packets on one key per kind, dropping a fraction at the sender."""

    def __init__(self, session: Any, swarm: int, me: int, kinds: Sequence[str], loss: float, seed: int,
                 fanout: int = 1, *, tag_key: bytes):
        self.fanout, self.tag_key = fanout, tag_key
        self.pubs = {kd: session.declare_publisher(key(swarm, me, kd)) for kd in kinds}
        self.swarm, self.me, self.loss = swarm, me, loss
        self.rng = random.Random(seed)
        self.counts: Dict[str, Dict[str, int]] = {
            kd: {"packets": 0, "bytes": 0, "link_bytes": 0, "dropped": 0} for kd in kinds}

    def send(self, kind: str, vector: Any, matrix: Any, step: int, rnd: int, stamp_ns: int) -> None:
        data = _edccif.encode_packet(kind, vector, matrix, swarm=self.swarm, sender=self.me, step=step,
                                     round=rnd, stamp_ns=stamp_ns, key=self.tag_key)
        c = self.counts[kind]
        if self.loss > 0 and self.rng.random() < self.loss:
            c["dropped"] += 1
            return
        self.pubs[kind].put(data)
        c["packets"] += 1
        c["bytes"] += len(data)
        c["link_bytes"] += len(data) * self.fanout

    def matched(self) -> bool:
        return all(p.matching_status.matching for p in self.pubs.values())


def _wait_start(spec: Dict[str, Any], role: str, node: int) -> int:
    """Marks this process ready and returns the start time (ns since the epoch):
    the swarm file's ``start_ns``, or the run directory's ``start.json``."""
    run = Path(spec["run_dir"])
    (run / "ready").mkdir(parents=True, exist_ok=True)
    (run / "ready" / f"{role}{node}").write_text(str(os.getpid()))
    if spec.get("start_ns") is not None:
        return int(spec["start_ns"])
    until = time.monotonic() + float(spec["ready_timeout_s"])
    start = run / "start.json"
    while time.monotonic() < until:
        if start.exists():
            try:
                return int(json.loads(start.read_text())["start_ns"])
            except (ValueError, KeyError):
                pass
        time.sleep(0.005)
    raise AgentError(f"{role} {node}: no start.json in {run} after {spec['ready_timeout_s']} s")


def _sleep_until_ns(t_ns: int) -> None:
    d = (t_ns - time.time_ns()) / 1e9
    if d > 0:
        time.sleep(d)


def _info_to_gaussian(p: Any) -> Tuple[np.ndarray, np.ndarray]:
    if p.kind == "estimate":
        return np.asarray(p.vector), np.asarray(p.matrix)
    cov = np.linalg.inv(np.asarray(p.matrix))
    cov = 0.5 * (cov + cov.T)
    return cov @ np.asarray(p.vector), cov


def _ready_wait(cond: Any, timeout: float) -> None:
    until = time.monotonic() + timeout
    while not cond() and time.monotonic() < until:
        time.sleep(0.01)


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


# --------------------------------------------------------------------------- processes


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


def node_columns(sc: _edccif.Scenario, z: np.ndarray, node: int) -> np.ndarray:
    """Node ``node``'s measurements (T, m_i) of ``z`` as ``Scenario.simulate``
    gives it: (T, N, m) when the nodes share ``m``, else (T, Σ m_i) in node order."""
    z = np.asarray(z)
    if z.ndim == 3:
        return z[:, node]
    dims = sc.meas_dims
    start = sum(dims[:node])
    return z[:, start:start + dims[node]]


def sensor_measurements(spec: Dict[str, Any], sc: _edccif.Scenario, node: int) -> np.ndarray:
    """Sensor ``node``'s measurements (T, 3): simulated from the scenario and seed,
    or replayed from the swarm's ``source`` (an MCAP file's ``/node{i}/measurement``,
    or TUM files — one per node, positions as the measurement of a position sensor).
    Rows of NaN: no measurement."""
    src = spec["source"]
    if src["kind"] == "simulate":
        return node_columns(sc, sc.simulate(seed=int(spec["seed"]))[1], node)
    if src["kind"] == "mcap":
        _, z, _ = _edccif.read_mcap_measurements(src["path"])
        # (T, N, 3), or (T, Σ m_i) for nodes of different sizes
        if z.ndim == 2 and z.shape[1] != sum(sc.meas_dims):
            raise AgentError(f"source {src['path']}: the recording holds {z.shape[1]} values per step, the "
                             f"scenario's nodes measure {sc.meas_dims} (record the swarm's own scenario)")
        if node >= (z.shape[1] if z.ndim == 3 else sc.nodes):
            raise AgentError(f"source {src['path']}: no measurements of node {node}")
        return np.asarray(node_columns(sc, z, node))
    paths = src.get("paths", [])
    if node >= len(paths):
        raise AgentError(f"source.paths: expected a TUM file for node {node}, got {len(paths)} files")
    _, p, _ = _edccif.read_tum(paths[node])
    return np.asarray(p)


def run_sensor(path: os.PathLike[str] | str, node: int) -> Dict[str, Any]:
    """Runs sensor ``node`` of the swarm file ``path``: at each step's start, its
    measurement through its event trigger; only triggered measurements are
    published. Writes ``sensor{node}.json`` and returns the summary."""
    spec, sc = load_swarm(path)
    k, swarm = sc.nodes, int(spec["swarm"])
    if not 0 <= node < k:
        raise AgentError(f"node: expected an index in 0..{k}, got {node}")
    z = sensor_measurements(spec, sc, node)
    steps = min(sc.steps, z.shape[0])
    trigger = _edccif.SensorTrigger(sc, spec["algorithm"], node=node, **spec["options"])
    period = float(spec["period_s"])
    agents = spec["agents"]
    faults = spec["faults"]
    zenoh = _zenoh()
    session = zenoh.open(zenoh_config([], [agents[node]["sensor_listen"]],
                                      agents[node].get("sensor_zenoh_config", spec["zenoh_config"])))
    try:
        seed = int(faults.get("loss_seed", 0)) * 100_003 + 2 * node + 1
        tx = _Sender(session, swarm, node, ["measurement"], float(faults.get("loss", 0.0)), seed,
                     tag_key=swarm_key(spec))
        _ready_wait(tx.matched, float(spec["ready_timeout_s"]))
        start_ns = _wait_start(spec, "sensor", node)
        for t in range(steps):
            t_ns = start_ns + int(round(t * period * 1e9))
            _sleep_until_ns(t_ns)
            if trigger.decide(z[t]):
                tx.send("measurement", z[t], None, t, 0, t_ns)
        time.sleep(0.05)
        wire = tcp_bytes([_port(a["sensor_listen"]) for a in agents], [_port(a["listen"]) for a in agents])
        time.sleep(float(spec["linger_s"]))
    finally:
        session.close()
    summary = {"role": "sensor", "node": node, "steps": steps, "measured": trigger.measured,
               "triggered": trigger.sent, "sent": tx.counts, "wire": wire}
    (Path(spec["run_dir"]) / f"sensor{node}.json").write_text(json.dumps(summary, indent=1))
    return summary


# --------------------------------------------------------------------------- swarm


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
    from ._args import Progress

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


# --------------------------------------------------------------------------- CLI


def cmd_agent(args: argparse.Namespace) -> int:
    s = run_agent(args.swarm, args.node, rejoin=args.rejoin)
    print(json.dumps({k: s[k] for k in ("node", "first_step", "steps", "inbox")}))
    return 0


def cmd_sensor(args: argparse.Namespace) -> int:
    s = run_sensor(args.swarm, args.node)
    print(json.dumps({k: s[k] for k in ("node", "measured", "triggered")}))
    return 0


def cmd_swarm(args: argparse.Namespace) -> int:
    from . import _args

    _args.check_output_file(args.json, args.force, "json")
    if args.scenario:
        sc = _edccif.Scenario.from_toml(args.scenario)
    else:
        _check_swarm_size(args.nodes)  # before building a scenario of that size
        sc = _edccif.Scenario.paper(nodes=args.nodes)
    if args.steps is not None:
        sc = sc.replace(steps=args.steps)
    check_swarm_request(sc, loss=args.loss, delay=args.delay, kill=args.kill)
    settings: Dict[str, Any] = {"period_s": args.period, "deadline_s": args.deadline}
    if args.sensor_wait is not None:
        settings["sensor_wait_s"] = args.sensor_wait
    res = run_swarm(sc.nodes, args.algorithm, scenario=sc, seed=args.seed, out=args.out,
                    loss=args.loss, loss_seed=args.seed, delay=args.delay, kill=args.kill, force=args.force,
                    progress=not args.quiet, **settings)
    # the summary file first: printing may meet a closed pipe
    if args.json:
        Path(args.json).write_text(json.dumps(res["summary"], indent=1))
    print(format_summary(res["summary"]))
    return 0


def add_subcommands(sub: Any) -> None:
    """Adds ``agent``, ``sensor`` and ``swarm`` to the ``edccif`` command."""
    from . import _args

    a = sub.add_parser("agent", help="run one estimator node of a swarm as this process (Zenoh)")
    a.add_argument("--swarm", required=True, help="swarm file (JSON, see docs/agents.md)")
    a.add_argument("--node", type=_args.node_index, required=True, help="node index")
    a.add_argument("--rejoin", action="store_true", help="join a running swarm from a neighbour's estimate")
    a.set_defaults(func=cmd_agent)
    s = sub.add_parser("sensor", help="run one sensor of a swarm as this process: triggered measurements only")
    s.add_argument("--swarm", required=True, help="swarm file (JSON); its 'source' says simulate, mcap or tum")
    s.add_argument("--node", type=_args.node_index, required=True, help="node index of the sensor")
    s.set_defaults(func=cmd_sensor)
    w = sub.add_parser("swarm", help="run N agents and N sensors as processes over Zenoh on loopback")
    w.add_argument("--nodes", type=_args.count, default=4, help="nodes of the built-in scenario (default 4)")
    w.add_argument("--scenario", help="a scenario TOML file instead of the built-in one")
    w.add_argument("--algorithm", default="edc-cif", type=_args.algorithm,
                   help="the row to run, any case (default edc-cif)")
    w.add_argument("--seed", type=_args.seed, default=0)
    w.add_argument("--steps", type=_args.count, help="steps (default: the scenario's)")
    w.add_argument("--period", type=_args.positive, default=DEFAULTS["period_s"],
                   help="step period in s (default 0.05)")
    w.add_argument("--sensor-wait", type=_args.positive, help="how long a step waits for its sensor (s)")
    w.add_argument("--deadline", type=_args.positive, default=DEFAULTS["deadline_s"],
                   help="how long a fusion phase waits for the neighbours (s, default 1)")
    w.add_argument("--loss", type=_args.real(0.0, 1.0, hi_open=True, meaning="a probability"), default=0.0,
                   help="fraction of packets dropped at every sender, in [0, 1)")
    w.add_argument("--delay", type=_args.delay, action="append", default=[], metavar="FROM:TO:SECONDS",
                   help="delay agent FROM's packets to agent TO (repeatable)")
    w.add_argument("--kill", type=_args.kill, metavar="NODE@STEP[+DOWN_S]",
                   help="kill agent NODE at STEP, restart it DOWN_S later (default 1 s)")
    w.add_argument("--out", type=_args.output_dir, default="swarm",
                   help="directory for the swarm file, logs and outputs (default swarm); an earlier run there "
                   "needs --force")
    w.add_argument("--json", type=_args.output_path, help="also write the summary to this JSON file")
    w.add_argument("--force", action="store_true",
                   help="replace an earlier swarm run in --out (only the files a run writes) and --json")
    w.add_argument("--quiet", action="store_true", help="no progress lines")
    w.set_defaults(func=cmd_swarm)
