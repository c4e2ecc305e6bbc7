"""Packets in and out: the checks a received packet passes, the inbox an agent waits on, the sender."""

from __future__ import annotations

import random
import threading
import time
from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from .. import _edccif
from .common import key
from .transport import _zenoh

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
