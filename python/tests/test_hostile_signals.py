"""Ctrl-C works on every long entry point.

Each case starts a subprocess that runs one long call (the Python API or the
command line's ``main``), waits until it prints ``ready`` (imports done, the
call about to start), lets it run 1 s, sends SIGINT and waits for it to end.
The bound is ``wait(timeout=...)``: a process still running 2 s after the
signal raises ``TimeoutExpired`` (the failure), it is not a measurement of
the code. The API cases must end with ``KeyboardInterrupt`` (exit code 1 and
the traceback's last line; Python then ends by SIGINT, which a shell shows as
130), the command line's with exit code 130 and one line ``edccif: interrupted``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

GRACE_S = 2.0
"""How long a process may take to end after SIGINT (a bound, not a measurement)."""
READY_TIMEOUT_S = 120.0
"""How long the subprocess may take to import and set up (a loaded CI host)."""

PRELUDE = """
import sys
import numpy as np
import edccif
from edccif import models
"""


def interrupt(code: str, tmp_path: Path) -> subprocess.CompletedProcess:
    """Runs ``code`` (which prints ``ready`` before its long call) in a
    subprocess, sends SIGINT 1 s after ``ready``, returns the finished process
    (stderr in ``.stderr``); fails if it does not end within ``GRACE_S``."""
    script = tmp_path / "long_call.py"
    script.write_text(PRELUDE + textwrap.dedent(code))
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, str(script)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    try:
        assert proc.stdout is not None
        deadline = time.monotonic() + READY_TIMEOUT_S
        line = ""
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line or line.strip() == "ready":
                break
        assert line.strip() == "ready", f"the subprocess did not get ready: {proc.communicate(timeout=5)}"
        time.sleep(1.0)
        assert proc.poll() is None, f"the call ended before the signal: {proc.communicate(timeout=5)}"
        proc.send_signal(signal.SIGINT)
        # The bound: TimeoutExpired here is the failure.
        out, err = proc.communicate(timeout=GRACE_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def assert_keyboard_interrupt(p: subprocess.CompletedProcess) -> None:
    # Python ends on an uncaught KeyboardInterrupt by SIGINT itself, so the
    # parent sees the signal (the shell's 130).
    assert p.returncode == -signal.SIGINT, (p.returncode, p.stderr)
    assert p.stderr.strip().splitlines()[-1].startswith("KeyboardInterrupt"), p.stderr


def test_monte_carlo(tmp_path):
    p = interrupt(
        """
        sc = edccif.Scenario.paper(4)
        print("ready", flush=True)
        try:
            edccif.monte_carlo(sc, ["edc-cif", "ec-ckf"], runs=10**6, progress=False)
        except KeyboardInterrupt as e:
            part = e.partial
            print("partial runs", None if part is None else part.runs, file=sys.stderr)
            raise
        """,
        tmp_path,
    )
    assert_keyboard_interrupt(p)
    assert "partial runs" in p.stderr


def test_run_with_many_consensus_rounds(tmp_path):
    p = interrupt(
        """
        sc = edccif.Scenario.paper(4)
        truth, z, x0 = sc.simulate(seed=0)
        print("ready", flush=True)
        edccif.run("ec-ckf", sc, z, x0=x0, consensus_iters=10**12)
        """,
        tmp_path,
    )
    assert_keyboard_interrupt(p)


def test_run_with_many_steps(tmp_path):
    p = interrupt(
        """
        sc = edccif.Scenario.paper(64).replace(steps=200)
        truth, z, x0 = sc.simulate(seed=0)
        z = np.concatenate([z] * 500)
        print("ready", flush=True)
        edccif.run("edc-cif", sc, z, x0=x0)
        """,
        tmp_path,
    )
    assert_keyboard_interrupt(p)


def test_network_step_with_many_consensus_rounds(tmp_path):
    p = interrupt(
        """
        sc = edccif.Scenario.paper(4)
        truth, z, x0 = sc.simulate(seed=0)
        net = edccif.Network(sc, "ec-ckf", x0, consensus_iters=10**12)
        print("ready", flush=True)
        net.step(z[0])
        """,
        tmp_path,
    )
    assert_keyboard_interrupt(p)


def test_ci_fuse_trace(tmp_path):
    p = interrupt(
        """
        rng = np.random.default_rng(0)
        k, n = 1000, 3
        xs = rng.normal(size=(k, n))
        a = rng.normal(size=(k, n, n))
        ps = a @ a.transpose(0, 2, 1) + np.eye(n)
        print("ready", flush=True)
        edccif.ci_fuse(xs, ps, weights="trace")
        """,
        tmp_path,
    )
    assert_keyboard_interrupt(p)


def test_reproduce_api(tmp_path):
    p = interrupt(
        """
        print("ready", flush=True)
        edccif._edccif.reproduce([4], runs=10**6, progress=False)
        """,
        tmp_path,
    )
    assert_keyboard_interrupt(p)


def cli(args: list, tmp_path: Path) -> subprocess.CompletedProcess:
    return interrupt(
        f"""
        from edccif.cli import main
        print("ready", flush=True)
        sys.exit(main({args!r}))
        """,
        tmp_path,
    )


def assert_cli_interrupted(p: subprocess.CompletedProcess) -> None:
    assert p.returncode == 130, p.stderr
    assert p.stderr.strip().splitlines()[-1] == "edccif: interrupted", p.stderr
    assert "Traceback" not in p.stderr, p.stderr


def test_cli_reproduce(tmp_path):
    p = cli(["reproduce", "--nodes", "4", "--runs", "1000000", "--no-figures", "--no-flights",
             "--quiet", "--out", str(tmp_path / "out")], tmp_path)
    assert_cli_interrupted(p)


def test_cli_simulate(tmp_path):
    toml = edccif_scenario_toml(tmp_path)
    p = cli(["simulate", "--scenario", str(toml), "--algorithm", "ec-ckf", "--out", str(tmp_path / "run.npz")],
            tmp_path)
    assert_cli_interrupted(p)
    assert not (tmp_path / "run.npz").exists()


def edccif_scenario_toml(tmp_path: Path) -> Path:
    """A scenario whose consensus rows never finish a step (10¹² rounds)."""
    import edccif

    path = tmp_path / "slow.toml"
    edccif.Scenario.paper(4).replace(consensus_iters=10**12).save_toml(str(path))
    return path


def test_cli_sweep_in_process_keeps_finished_cells(tmp_path):
    table = tmp_path / "sweep.csv"
    p = cli(["sweep", "--in-process", "--runs", "1000000", "--thresholds", "0.02", "0.04",
             "--out", str(table), "--no-figure", "--quiet"], tmp_path)
    assert_cli_interrupted(p)
    # No cell finished: the table holds at most its header, and a rerun resumes.
    assert not table.exists() or len(table.read_text().splitlines()) <= 1


def test_cli_replay(tmp_path):
    """A replay of an `edccif.record` recording whose stored scenario runs
    10¹² consensus rounds a step under the consensus rows: it never finishes a
    step, and Ctrl-C ends it with nothing written."""
    import edccif

    rec = tmp_path / "slow.mcap"
    sc = edccif.Scenario.paper(4).replace(steps=50, consensus_iters=10**12)
    edccif.record("edc-cif", sc, seed=0, mcap=rec)  # diffusion: no consensus rounds
    out = tmp_path / "replay.npz"
    p = cli(["replay", str(rec), "--algorithm", "ec-ckf", "--out", str(out)], tmp_path)
    assert_cli_interrupted(p)
    assert not out.exists()
