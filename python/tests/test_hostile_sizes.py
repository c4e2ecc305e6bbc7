"""The largest refused sizes end in a named error, never in an abort.

Each case runs in a subprocess (an abort or a Rust panic there cannot take the
test session with it) bounded by a timeout: the script catches the expected
error class, prints its name and message, and exits 0. A negative return code
(a signal such as SIGABRT) or a timeout is the failure.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

TIMEOUT_S = 60.0
"""Bound on each subprocess (import and call; a loaded CI host)."""

CASES = {
    "Scenario.paper(nodes=10**6).weights": "edccif.Scenario.paper(nodes=10**6).weights",
    "complete graph of 10**5 nodes": "edccif.Scenario.paper(nodes=10**5).replace(topology='complete')",
    "Scenario.paper(nodes=10**9)": "edccif.Scenario.paper(nodes=10**9)",
    "simulate(steps=10**9)": "edccif.Scenario.paper(4).replace(steps=10**9).simulate()",
    "simulate(steps=10**12)": "edccif.Scenario.paper(4).replace(steps=10**12).simulate()",
    "simulate(steps=2**63)": "edccif.Scenario.paper(4).replace(steps=2**63).simulate()",
    "monte_carlo(steps=10**12)": (
        "edccif.monte_carlo(edccif.Scenario.paper(4).replace(steps=10**12), 'edc-cif', runs=2, progress=False)"
    ),
    "monte_carlo(runs=10**15)": "edccif.monte_carlo(edccif.Scenario.paper(4), 'edc-cif', runs=10**15, progress=False)",
    "record(steps=10**12)": "edccif.record('edc-cif', edccif.Scenario.paper(4).replace(steps=10**12))",
    "run(z of 10**11 steps)": (
        "edccif.run('edc-cif', edccif.Scenario.paper(4), np.broadcast_to(np.float64(1.0), (10**11, 4, 3)))"
    ),
    "batch_filter(10**12 rows)": (
        "edccif.CKF(models.ConstantVelocity(3, 0.1), models.Position([0.1, 0.1, 0.1]), np.zeros(6), np.eye(6),"
        " dt=0.1).batch_filter(np.broadcast_to(np.float64(0.0), (10**12, 3)))"
    ),
    "ci_fuse(K=10**10)": (
        "edccif.ci_fuse(np.broadcast_to(0.0, (10**10, 2)), np.broadcast_to(np.eye(2), (10**10, 2, 2)))"
    ),
    "reproduce(nodes=[10**6])": "edccif._edccif.reproduce([10**6], runs=1, progress=False)",
    "preprocess(rate_hz=1e9)": (
        "f = __import__('tempfile').mkdtemp() + '/a.txt'; t = np.arange(0.0, 100.0, 0.1);"
        " edccif.write_tum(f, t, np.c_[t, np.sin(t), np.cos(t)]);"
        " edccif.preprocess(f, [f], rate_hz=1e9, spatial=False, align='none')"
    ),
}
"""What each case calls; every one must raise SizeError."""


@pytest.mark.parametrize("name", sorted(CASES))
def test_refused_without_abort(name):
    code = textwrap.dedent(
        f"""
        import numpy as np
        import edccif
        from edccif import models
        try:
            {CASES[name]}
        except edccif.SizeError as e:
            print(type(e).__name__, e)
        else:
            raise SystemExit("accepted")
        """
    )
    # The bound: TimeoutExpired is the failure.
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=TIMEOUT_S)
    assert p.returncode == 0, (p.returncode, p.stderr)
    assert p.stdout.startswith("SizeError "), p.stdout
    assert "available" in p.stdout, p.stdout


def test_the_cli_refuses_a_huge_network_in_one_line(tmp_path):
    p = subprocess.run(
        [sys.executable, "-m", "edccif", "simulate", "--nodes", "1000000000", "--out", str(tmp_path / "run.npz")],
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("edccif: error: nodes = 1000000000:"), p.stderr


LARGE_RSS_BYTES = 6 << 30
"""Bound on the peak memory of a 10⁵-node ring network stepped 3 times: its
neighbour lists are 3 × 10⁵ entries and its nodes' state about 2 GB at most
(a dense 10⁵ × 10⁵ weight matrix alone would be 80 GB)."""


def test_a_ring_of_100000_nodes_runs_with_neighbour_lists():
    # In a subprocess, whose peak memory (ru_maxrss) is its own; the memory
    # limit makes the refusal of the dense getters the same on any machine.
    code = textwrap.dedent(
        """
        import resource
        import numpy as np
        import edccif
        sc = edccif.Scenario.paper(nodes=10**5).replace(steps=3)
        offsets, indices, w = sc.neighbours
        assert offsets.shape == (10**5 + 1,) and indices.shape == w.shape == (3 * 10**5,)
        assert indices[offsets[0]:offsets[1]].tolist() == [0, 1, 99999]
        assert np.allclose(np.add.reduceat(w, offsets[:-1]), 1.0)
        for dense in ("weights", "adjacency"):
            try:
                getattr(sc, dense)
            except edccif.SizeError as e:
                assert "neighbour lists" in str(e), e
            else:
                raise SystemExit(f"{dense} accepted")
        _, z, x0 = sc.simulate(seed=0)
        r = edccif.run("edc-cif", sc, z, x0=x0, record_covariances=False)
        assert r.estimates.shape == (3, 10**5, 7) and np.isfinite(r.estimates).all()
        net = edccif.Network(sc, "edc-cif", x0=x0)
        for k in range(2):
            est = net.step(z[k])
        assert np.array_equal(est, r.estimates[1])
        assert net.neighbours[1].shape == (3 * 10**5,)
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
        """
    )
    env = dict(__import__("os").environ, EDCCIF_MEMORY_LIMIT="8G")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 0, (p.returncode, p.stdout, p.stderr)
    assert int(p.stdout.split()[-1]) < LARGE_RSS_BYTES, p.stdout
