"""An attacker on the swarm's network, as its own process (test_hostile_agents.py).

    python swarm_attacker.py OUT_DIR REPORT.json

Waits for the swarm in OUT_DIR to start (``run/start.json``), connects to agent 0's
and its first neighbour j's endpoints like any process that can reach them, records
j's genuine packets, and at every step from 5 to ``steps - 10`` sends agent 0:

- keyed packets that cannot be used: an indefinite information matrix, a
  contribution with a round (contributions have none), a contribution of the wrong
  dimension, a 2-D measurement (``unusable``);
- packets with a wrong key, and without a tag (``unauthenticated``);
- j's genuine packets of 3 × step_window steps ago (``replayed``), and a keyed
  packet of the current step stamped with another run's time (``replayed``);
- a keyed packet 1000 steps ahead (``out_of_window``);
- a keyed packet of another swarm (``foreign_swarm``);
- j's newest genuine packet again (``duplicate`` or ``late``).

Every keyed packet that passed the checks would change agent 0's estimate, so the
swarm equals the in-process run only if all were dropped. Writes how many of each
it sent to REPORT.json and exits.
"""

import json
import sys
import time
from pathlib import Path

import numpy as np
import zenoh

import edccif
from edccif import agents


def main(out: Path, report: Path) -> int:
    until = time.monotonic() + 120
    start_file = out / "run" / "start.json"
    while not start_file.exists():
        if time.monotonic() > until:
            return 3
        time.sleep(0.01)
    time.sleep(0.05)
    spec, sc = agents.load_swarm(out / "swarm.json")
    start_ns = int(json.loads(start_file.read_text())["start_ns"])
    key, swarm = agents.swarm_key(spec), int(spec["swarm"])
    period, steps, n, window = float(spec["period_s"]), sc.steps, sc.state_dim, int(spec["step_window"])
    j = edccif.Node(sc, spec["algorithm"], node=0).neighbours[0]
    ends = [spec["agents"][0]["listen"], spec["agents"][j]["listen"]]
    session = zenoh.open(agents.zenoh_config([], ends))
    captured = []  # (step, key expression, bytes) of j's genuine packets

    def record(sample):
        try:
            p = edccif.decode_packet(sample.payload.to_bytes(), key=key)
        except edccif.EdccifError:
            return
        captured.append((int(p.step), str(sample.key_expr), sample.payload.to_bytes()))

    # j's packets only, not this session's own forgeries on j's keys
    sub = session.declare_subscriber(f"edccif/{swarm}/{j}/*", record, allowed_origin=zenoh.Locality.REMOTE)
    pubs = {}

    def put(kexpr, data):
        if kexpr not in pubs:
            pubs[kexpr] = session.declare_publisher(kexpr)
        pubs[kexpr].put(data)

    sent = {c: 0 for c in ("unusable", "unauthenticated", "replayed", "out_of_window", "foreign_swarm",
                           "duplicate_or_late", "unknown_sender_elsewhere")}
    good_p = np.eye(n) * 2.0
    bad = -np.eye(n)
    contribution, information = agents.key(swarm, j, "contribution"), agents.key(swarm, j, "information")
    wrong_key = bytes(32)

    def stamp(t):
        return start_ns + int(round(t * period * 1e9))

    last = -1
    while True:
        t = (time.time_ns() - start_ns) // int(period * 1e9)
        if t > steps - 10:
            break
        if t < 5 or t == last:
            time.sleep(period / 4)
            continue
        last = t
        h = dict(swarm=swarm, sender=j, step=t, stamp_ns=stamp(t))
        # well-formed but unusable, with the right key
        put(information, edccif.encode_packet("information", np.ones(n), bad, key=key, **h))
        put(contribution, edccif.encode_packet("contribution", np.ones(n), good_p, key=key, **{**h, "round": 1}))
        put(contribution, edccif.encode_packet("contribution", np.ones(3), np.eye(3), key=key, **h))
        put(agents.key(swarm, 0, "measurement"),
            edccif.encode_packet("measurement", np.ones(2), key=key, swarm=swarm, sender=0, step=t,
                                 stamp_ns=stamp(t)))
        sent["unusable"] += 4
        sent["unknown_sender_elsewhere"] += 1  # agent j hears agent 0's key too
        # usable payloads that must not be believed
        put(contribution, edccif.encode_packet("contribution", np.ones(n), good_p, key=wrong_key, **h))
        put(contribution, edccif.encode_packet("contribution", np.ones(n), good_p, **h))
        sent["unauthenticated"] += 2
        put(information, edccif.encode_packet("information", np.ones(n), good_p, key=key,
                                              **{**h, "stamp_ns": stamp(t) + 1}))
        sent["replayed"] += 1
        old = [c for c in captured if c[0] <= t - 3 * window]
        if old:
            put(old[-1][1], old[-1][2])
            sent["replayed"] += 1
        put(information, edccif.encode_packet("information", np.ones(n), good_p, key=key,
                                              **{**h, "step": t + 1000, "stamp_ns": stamp(t + 1000)}))
        sent["out_of_window"] += 1
        put(information, edccif.encode_packet("information", np.ones(n), good_p, key=key,
                                              **{**h, "swarm": swarm + 1}))
        sent["foreign_swarm"] += 1
        if captured:
            put(captured[-1][1], captured[-1][2])
            sent["duplicate_or_late"] += 1
        time.sleep(period / 4)
    sub.undeclare()
    session.close()
    report.write_text(json.dumps({"sent": sent, "captured": len(captured), "target": 0, "impersonated": j}))
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1]), Path(sys.argv[2])))
