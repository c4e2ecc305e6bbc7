"""Live agents against strangers on the network: signed packets (HMAC-SHA256 under
the swarm file's key, checked against Python's hmac), every kind of forged,
unusable, replayed or out-of-window packet rejected and counted by the inbox, a
fusion phase that refuses what arrived falling back to the node's own estimate,
and a whole swarm on loopback with an attacker process injecting such packets:
the agents finish, count them, and equal the in-process run."""

import hashlib
import hmac
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import edccif
from edccif import agents

KEY = bytes(range(32))
ATTACKER = Path(__file__).resolve().parent / "swarm_attacker.py"


def test_tag_is_hmac_sha256_truncated_to_16_bytes():
    plain = edccif.encode_packet("estimate", np.arange(3.0), np.eye(3), swarm=4, sender=2, step=9, stamp_ns=7)
    signed = edccif.encode_packet("estimate", np.arange(3.0), np.eye(3), swarm=4, sender=2, step=9, stamp_ns=7,
                                  key=KEY)
    assert signed[:-16] == plain
    assert signed[-16:] == hmac.new(KEY, plain, hashlib.sha256).digest()[:16]
    p = edccif.decode_packet(signed, key=KEY)
    assert (p.kind, p.swarm, p.sender, p.step, p.nbytes) == ("estimate", 4, 2, 9, len(signed))
    with pytest.raises(edccif.WireFormatError, match="does not verify"):
        edccif.decode_packet(signed, key=bytes(32))
    with pytest.raises(edccif.WireFormatError, match="without an authentication tag"):
        edccif.decode_packet(plain, key=KEY)
    with pytest.raises(edccif.WireFormatError, match="oversized"):
        edccif.decode_packet(signed)  # an unkeyed reader sees the tag as extra bytes
    for i in range(len(signed)):
        b = bytearray(signed)
        b[i] ^= 0x10
        with pytest.raises(edccif.WireFormatError):
            edccif.decode_packet(bytes(b), key=KEY)
    with pytest.raises(edccif.WireFormatError, match="at least 16"):
        edccif.encode_packet("measurement", [1.0], key=b"short")


class _Payload:
    def __init__(self, b):
        self.b = b

    def to_bytes(self):
        return self.b


class _Sample:
    def __init__(self, key, data):
        self.key_expr, self.payload = key, _Payload(data)


def _inbox(**kw):
    d = dict(key=KEY, state_dim=7, rounds=0, window=4)
    d.update(kw)
    inbox = agents._Inbox(swarm=5, me=1, neighbours=[0, 2], delays={}, **d)
    inbox.alive = {0, 2}
    return inbox


def _put(inbox, kind, vector, matrix=None, *, sender=0, key=KEY, kexpr=None, **h):
    h = {"swarm": 5, "sender": sender, **h}
    data = edccif.encode_packet(kind, vector, matrix, key=key, **h)
    inbox.on_sample(_Sample(kexpr or agents.key(5, sender, kind), data))


def test_inbox_rejects_forged_and_unusable_packets_and_counts_them():
    inbox = _inbox()
    spd = np.eye(7) * 2.0
    _put(inbox, "contribution", np.ones(7), spd, key=bytes(32), step=0)  # another key
    _put(inbox, "contribution", np.ones(7), spd, key=None, step=0)  # no tag
    _put(inbox, "information", np.ones(7), -np.eye(7), step=0)  # indefinite information matrix
    _put(inbox, "estimate", np.ones(7), np.diag([1, 1, 1, 1, 1, 1, 0.0]), step=0)  # singular covariance
    _put(inbox, "contribution", np.ones(3), np.eye(3), step=0)  # wrong dimension for its kind
    _put(inbox, "measurement", np.ones(2), sender=1, step=0)  # a 2-D measurement for a 3-D sensor
    _put(inbox, "contribution", np.ones(7), spd, step=0, round=1)  # a round a contribution never has
    _put(inbox, "contribution", np.ones(7), spd, step=99)  # far ahead of the agent
    _put(inbox, "contribution", np.ones(7), spd, step=0, swarm=6)  # another swarm
    _put(inbox, "contribution", np.ones(7), spd, sender=3, step=0)  # not a neighbour
    inbox.on_sample(_Sample(agents.key(5, 0, "contribution"), b"\xed\xcf\x01"))  # truncated
    c = inbox.counts
    assert (c["unauthenticated"], c["unusable"], c["out_of_window"], c["foreign_swarm"], c["unknown_sender"],
            c["malformed"], c["received"]) == (2, 5, 1, 1, 1, 1, 0)
    # a contribution Ī may be semi-definite (a measurement's, rank 3) or indefinite (an
    # untriggered step's has a negative part): both are kept, the adaptation guard decides
    h = np.zeros((7, 3))
    h[:3] = np.eye(3)
    _put(inbox, "contribution", np.ones(7), h @ h.T * 4e6, step=0)
    _put(inbox, "contribution", np.ones(7), h @ h.T * 4e6, step=0)  # the same again
    _put(inbox, "contribution", np.ones(7), np.diag([1, 1, 1, 1, 1, 1, -1.0]), step=0, sender=2)
    assert inbox.counts["received"] == 2 and inbox.counts["duplicate"] == 1
    got = inbox.wait("contribution", 0, 0, [0, 2], until=0.0)
    assert sorted(got) == [0, 2]


def test_inbox_rejects_replays_by_step_and_by_timestamp():
    inbox = _inbox(window=4)
    period = 10.0
    start = time.time_ns() - int(10.5 * period * 1e9)  # the clock says step 10 (for 5 s)

    def stamp(t):
        return start + int(round(t * period * 1e9))

    spd = np.eye(7)
    # before the clock is known: kept, then judged when it is
    _put(inbox, "information", np.ones(7), spd, step=1, stamp_ns=stamp(1) + 5)
    _put(inbox, "information", np.ones(7), spd, step=1, stamp_ns=stamp(1), sender=2)
    assert inbox.counts["received"] == 2
    inbox.start(start, period)
    assert inbox.counts["received"] == 1 and inbox.counts["replayed"] == 1
    assert list(inbox.wait("information", 1, 0, [0, 2], until=0.0)) == [2]
    inbox.wait("contribution", 10, 0, [], until=0.0)  # the agent is at step 10
    _put(inbox, "information", np.ones(7), spd, step=11, stamp_ns=stamp(11) - 1)  # another run's stamp
    _put(inbox, "information", np.ones(7), spd, step=3, stamp_ns=stamp(3))  # an old step, genuine stamp
    _put(inbox, "information", np.ones(7), spd, step=8, stamp_ns=stamp(8))  # recent, phase over: late
    _put(inbox, "information", np.ones(7), spd, step=16, stamp_ns=stamp(16))  # beyond the window (10 + 4)
    _put(inbox, "information", np.ones(7), spd, step=12, stamp_ns=stamp(12))  # ahead, within the window: kept
    c = inbox.counts
    assert (c["replayed"], c["late"], c["out_of_window"], c["received"]) == (3, 1, 1, 2), c


def test_rejected_fusion_falls_back_to_the_own_estimate(sc4, sim4):
    """Packets that pass alone but that a phase refuses together: the node fuses
    without them (a failed phase changes nothing) and counts the fallback."""
    _, z, x0 = sim4
    nd = edccif.Node(sc4, "edc-cif", node=1, x0=x0)
    ref = edccif.Node(sc4, "edc-cif", node=1, x0=x0)
    inbox = _inbox()
    nd.local(z[0, 1])
    ref.local(z[0, 1])

    class P:
        vector = np.ones(7)
        matrix = np.full((7, 7), np.nan)  # the phase refuses it

    agents._fuse(nd.adapt, {0: P()}, inbox)
    ref.adapt([])
    assert inbox.counts["fusion_fallbacks"] == 1
    x, _ = agents._fuse(nd.combine, {}, inbox)
    assert np.array_equal(x, ref.combine([])[0])


def test_swarm_file_holds_a_key(tmp_path, sc4):
    spec = agents.write_swarm(tmp_path / "s.json", sc4, ports=list(range(9000, 9008)))
    assert len(agents.swarm_key(spec)) == 32
    assert (tmp_path / "s.json").stat().st_mode & 0o077 == 0  # the owner's only
    other = agents.write_swarm(tmp_path / "t.json", sc4, ports=list(range(9000, 9008)))
    assert other["key"] != spec["key"]  # a fresh key per swarm file
    d = json.loads((tmp_path / "s.json").read_text())
    for bad in (None, "00" * 8, "zz" * 16, 7):
        with pytest.raises(agents.AgentError, match="key"):
            agents.load_swarm_dict({**d, "key": bad})
    with pytest.raises(edccif.ParameterError, match="step_window"):
        agents.load_swarm_dict({**d, "step_window": 0})


# ----------------------------------------------------------------- over Zenoh

EXACT = {"period_s": 0.06, "sensor_wait_s": 0.045, "deadline_s": 2.0}


def test_swarm_under_attack_finishes_counts_and_equals_run(tmp_path):
    pytest.importorskip("zenoh")
    out = tmp_path / "swarm"
    report = tmp_path / "attacker.json"
    attacker = subprocess.Popen([sys.executable, str(ATTACKER), str(out), str(report)],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        res = agents.run_swarm(4, "edc-cif", seed=0, steps=80, out=out, timeout_s=240, **EXACT)
        log, _ = attacker.communicate(timeout=60)
    finally:
        if attacker.poll() is None:
            attacker.kill()
            attacker.wait()
    assert attacker.returncode == 0, log
    sent = json.loads(report.read_text())["sent"]
    agent0 = next(a for a in res["agents"] if a["node"] == 0)["inbox"]
    # everything forged was refused for what it is, at the agent it was sent to
    assert sent["unusable"] > 40 and agent0["unusable"] == sent["unusable"]
    assert agent0["unauthenticated"] == sent["unauthenticated"] > 0
    assert agent0["replayed"] == sent["replayed"] > sent["out_of_window"] > 0
    assert agent0["out_of_window"] == sent["out_of_window"]
    assert agent0["foreign_swarm"] == sent["foreign_swarm"]
    assert agent0["duplicate"] + agent0["late"] == sent["duplicate_or_late"] > 0
    assert agent0["fusion_fallbacks"] == 0
    # and the swarm's numbers are the in-process run's
    assert not np.isnan(res["estimates"]).any()
    assert np.max(np.abs(res["estimates"] - res["reference"])) <= 1e-9
    s = res["summary"]
    assert s["inbox"]["unauthenticated"] == sent["unauthenticated"]
    assert s["trigger_rate"] == pytest.approx(s["trigger_rate_in_process"])
    assert "unauthenticated" in agents.format_summary(s)
