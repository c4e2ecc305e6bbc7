"""Hostile inputs to the Python API: what each class of them does now
(docs/reliability.md, "Hostile inputs"). One section per promise:

1. long calls stop on Ctrl-C (``KeyboardInterrupt``) and leave objects as
   they were; a Monte Carlo study keeps the runs it finished;
2. sizes are checked before allocating (``SizeError``), thread counts are
   bounded;
3. every argument error is an ``EdccifError`` naming the argument;
4. nothing is silently wrong (indefinite covariances, read-only ``x``/``P``,
   complex input, non-symmetric packets, duplicate labels, NaN thresholds);
7. long calls report progress to a callback, and to stderr when it is not a
   terminal.

The signals themselves are sent in test_hostile_signals.py, the largest sizes
in test_hostile_sizes.py (subprocesses).
"""

from __future__ import annotations

import _thread
import io
import threading

import numpy as np
import pytest
from hostile_probe import HOSTILE, run_probes

import edccif
from edccif import models
from edccif._progress import Reporter


def _cv_filter(cls, **kw):
    return cls(models.ConstantVelocity(1, 0.1), models.LinearMeasurement([[1.0, 0.0]], [[0.01]]),
               [0.0, 0.0], np.eye(2), dt=0.1, **kw)


class StopAfter:
    """A progress callback that raises KeyboardInterrupt (what Ctrl-C raises)
    once `done` reaches `n`, recording every call."""

    def __init__(self, n):
        self.n = n
        self.calls = []

    def __call__(self, done, total):
        self.calls.append((done, total))
        if done >= self.n:
            raise KeyboardInterrupt


# ---------------------------------------------------------------------------
# 1. Interruptible everywhere


def test_an_interrupted_monte_carlo_keeps_the_runs_it_finished():
    sc = edccif.Scenario.paper(3).replace(steps=20)
    stop = StopAfter(20)
    with pytest.raises(KeyboardInterrupt) as e:
        edccif.monte_carlo(sc, ["edc-cif", "ec-ckf"], runs=10**6, progress=stop)
    part = e.value.partial
    assert isinstance(part, edccif.MonteCarloResult)
    assert 1 <= part.runs < 10**6
    # The partial study is the study of runs 0..p, number for number.
    full = edccif.monte_carlo(sc, ["edc-cif", "ec-ckf"], runs=part.runs, progress=False)
    for lab in full.labels:
        assert part.pos_rmse[lab] == full.pos_rmse[lab]
        assert part.trigger_rate[lab] == full.trigger_rate[lab]
        np.testing.assert_array_equal(part.rmse[lab], full.rmse[lab])


def test_a_monte_carlo_interrupted_before_its_first_run_keeps_nothing():
    sc = edccif.Scenario.paper(3).replace(consensus_iters=10**12)
    with pytest.raises(KeyboardInterrupt) as e:
        edccif.monte_carlo(sc, "ec-ckf", runs=4, progress=StopAfter(0))
    assert e.value.partial is None


def test_an_interrupted_network_step_leaves_the_network_as_it_was():
    sc = edccif.Scenario.paper(4)
    _, z, x0 = sc.simulate(seed=0)
    net = edccif.Network(sc, "ec-ckf", x0, consensus_iters=10**12)
    before = (net.estimates.copy(), net.covariances.copy(), net.counters, net.t)
    # What Ctrl-C does, from another thread: the step never ends without it.
    # Should the first Ctrl-C be lost, a second one after 30 s ends the step
    # and the test fails saying so (rather than hanging).
    done = threading.Event()
    presses = []

    def press():
        for wait in (0.3, 30.0):
            if done.wait(wait):
                return
            presses.append(wait)
            _thread.interrupt_main()

    presser = threading.Thread(target=press, daemon=True)
    presser.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            net.step(z[0])
    finally:
        done.set()
        presser.join()
    assert presses == [0.3], f"the first Ctrl-C did not stop the step: {presses}"
    after = (net.estimates, net.covariances, net.counters, net.t)
    np.testing.assert_array_equal(after[0], before[0])
    np.testing.assert_array_equal(after[1], before[1])
    assert after[2:] == before[2:]


def test_steps_with_many_consensus_rounds_agree_bit_for_bit():
    # 4 nodes × 20 000 rounds: each step runs round by round, checked for
    # Ctrl-C (the Rust tests compare it with the serial step of the core).
    sc = edccif.Scenario.paper(4).replace(steps=3)
    _, z, x0 = sc.simulate(seed=1)
    heavy = edccif.run("ec-ckf", sc, z, x0=x0, consensus_iters=20_000)
    net = edccif.Network(sc, "ec-ckf", x0, consensus_iters=20_000)
    steps = np.stack([net.step(zk) for zk in z])
    np.testing.assert_array_equal(heavy.estimates, steps)
    par = edccif.run("ec-ckf", sc, z, x0=x0, consensus_iters=20_000, threads=2)
    np.testing.assert_array_equal(heavy.estimates, par.estimates)


def test_an_interrupted_run_raises_keyboard_interrupt():
    sc = edccif.Scenario.paper(4)
    _, z, x0 = sc.simulate(seed=0)
    with pytest.raises(KeyboardInterrupt):
        edccif.run("ec-ckf", sc, z, x0=x0, consensus_iters=10**12, progress=StopAfter(0))


def test_an_interrupted_ci_fuse_raises_keyboard_interrupt():
    rng = np.random.default_rng(0)
    k = 300
    xs = rng.normal(size=(k, 2))
    ps = np.stack([np.eye(2) * (1 + i % 5) for i in range(k)])
    stop = StopAfter(1)
    with pytest.raises(KeyboardInterrupt):
        edccif.ci_fuse(xs, ps, weights="trace", progress=stop)
    assert stop.calls and stop.calls[-1][1] == 50 * k * (k - 1) // 2


@pytest.mark.parametrize("cls", [edccif.CKF, edccif.ETCIF])
def test_an_interrupted_batch_filter_leaves_the_filter_as_it_was(cls):
    kf = _cv_filter(cls)
    kf.predict()
    x, p = kf.x.copy(), kf.P.copy()
    zs = np.zeros((5000, 1))
    with pytest.raises(KeyboardInterrupt):
        kf.batch_filter(zs, progress=StopAfter(1024))
    np.testing.assert_array_equal(kf.x, x)
    np.testing.assert_array_equal(kf.P, p)


def test_an_interrupted_model_network_run_leaves_the_network_as_it_was():
    net = edccif.ModelNetwork(
        models.ConstantVelocity(1, 0.1),
        [models.LinearMeasurement([[1.0, 0.0]], [[0.01]])] * 2,
        x0=[0.0, 0.0],
        P0=np.eye(2),
        dt=0.1,
    )
    net.step([[0.1], [0.2]])
    before = (net.estimates.copy(), net.covariances.copy(), net.counters, net.t)
    z = [np.zeros((10**6, 1)), np.zeros((10**6, 1))]
    with pytest.raises(KeyboardInterrupt):
        net.run(z, progress=StopAfter(1))
    np.testing.assert_array_equal(net.estimates, before[0])
    np.testing.assert_array_equal(net.covariances, before[1])
    assert (net.counters, net.t) == before[2:]
    seen = []
    net.run([np.zeros((50, 1)), None], progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (50, 50)


def test_the_cli_exits_130_with_one_line_on_ctrl_c(monkeypatch, capsys):
    from edccif import cli

    def interrupted(_args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "cmd_algorithms", interrupted)
    assert cli.main(["algorithms"]) == 130
    assert capsys.readouterr().err == "edccif: interrupted\n"


# ---------------------------------------------------------------------------
# 2. Sizes checked before allocating; thread counts bounded


def test_a_network_too_large_for_memory_is_refused_with_its_size():
    with pytest.raises(edccif.SizeError, match=r"nodes = 1000000000: .* needs .* more than the .* available"):
        edccif.Scenario.paper(nodes=10**9)


@pytest.mark.parametrize("steps", [10**12, 2**63])
def test_steps_too_many_for_memory_are_refused(steps):
    sc = edccif.Scenario.paper(4).replace(steps=steps)
    with pytest.raises(edccif.SizeError, match=f"steps = {steps}"):
        sc.simulate(seed=0)
    with pytest.raises(edccif.SizeError, match="Monte Carlo"):
        edccif.monte_carlo(sc, "edc-cif", runs=2, progress=False)


def test_runs_too_many_for_memory_are_refused():
    with pytest.raises(edccif.SizeError, match="runs = 1000000000000000"):
        edccif.monte_carlo(edccif.Scenario.paper(3), "edc-cif", runs=10**15, progress=False)


def test_a_run_too_large_for_memory_is_refused_before_z_is_copied():
    sc = edccif.Scenario.paper(4)
    z = np.broadcast_to(np.float64(1.0), (10**11, 4, 3))  # a view: no memory behind it
    with pytest.raises(edccif.SizeError, match="a run of steps = 100000000000"):
        edccif.run("edc-cif", sc, z)


def test_a_batch_filter_too_large_for_memory_is_refused():
    kf = _cv_filter(edccif.CKF)
    with pytest.raises(edccif.SizeError, match="batch_filter of rows = 1000000000000"):
        kf.batch_filter(np.broadcast_to(np.float64(0.0), (10**12, 1)))


def test_thread_counts_are_bounded_by_the_cores():
    expected = r"worker threads \(jobs\): expected an integer in 1\.\.=\d+ \(4 per core"
    with pytest.raises(edccif.ParameterError, match=expected):
        edccif.set_worker_threads(10**6)
    sc = edccif.Scenario.paper(4).replace(steps=3)
    _, z, _ = sc.simulate(seed=0)
    with pytest.raises(edccif.ParameterError, match=r"threads: expected an integer in 1\.\.=\d+ .*per core"):
        edccif.run("edc-cif", sc, z, threads=100_000)
    net = edccif.Network(sc)
    with pytest.raises(edccif.ParameterError, match="per core"):
        net.threads = 100_000
    assert net.threads == 1


# ---------------------------------------------------------------------------
# 3. One error family


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda sc, z: edccif.monte_carlo(sc, "edc-cif", runs=-1), r"runs: expected an integer >= 1, got -1"),
        (lambda sc, z: models.CustomMotion(lambda X, dt: X, np.eye(2), n=-1), r"n: expected an integer >= 0, got -1"),
        (lambda sc, z: models.ConstantVelocity(-1, 0.1), r"dim: expected an integer >= 1, got -1"),
        (lambda sc, z: edccif.Network(sc).reset_node(-1, np.zeros(7), np.eye(7)),
         r"i: node index -1 is out of range; expected a node index in 0\.\.4"),
        (lambda sc, z: edccif.run("edc-cif", sc, z, trigger_seed=-1),
         r"trigger_seed: expected an integer in 0\.\.=18446744073709551615"),
        (lambda sc, z: edccif.set_worker_threads(10**30), r"worker threads \(jobs\)"),
        (lambda sc, z: edccif.Scenario.paper(nodes=-4), r"nodes: expected an integer >= 1, got -4"),
        (lambda sc, z: sc.simulate(seed=2**64),
         r"seed: expected an integer in 0\.\.=18446744073709551615 .*got 18446744073709551616"),
    ],
)
def test_integers_out_of_range_are_parameter_errors(call, match):
    sc = edccif.Scenario.paper(4).replace(steps=3)
    _, z, _ = sc.simulate(seed=0)
    with pytest.raises(edccif.ParameterError, match=match):
        call(sc, z)


def test_wrong_types_are_argument_type_errors_that_are_also_type_errors():
    assert issubclass(edccif.ArgumentTypeError, edccif.ParameterError)
    assert issubclass(edccif.ArgumentTypeError, TypeError)
    with pytest.raises(edccif.ArgumentTypeError, match="dt: expected a real number, got str"):
        _cv_filter(edccif.CKF).predict(dt="0.1")
    with pytest.raises(TypeError, match=r"scenario: expected an instance of edccif\.Scenario, got dict"):
        edccif.Network({"nodes": 4})
    with pytest.raises(edccif.ArgumentTypeError, match="runs: expected an integer >= 1, got float"):
        edccif.monte_carlo(edccif.Scenario.paper(3), "edc-cif", runs=2.5)


def test_the_wire_step_accepts_the_whole_u64_range():
    b = edccif.encode_packet("measurement", [1.0, 2.0, 3.0], step=2**64 - 1, stamp_ns=2**64 - 1)
    p = edccif.decode_packet(b)
    assert (p.step, p.stamp_ns) == (2**64 - 1, 2**64 - 1)
    expected = "step: expected an integer in 0..=18446744073709551615, got 18446744073709551616"
    with pytest.raises(edccif.ParameterError, match=expected):
        edccif.encode_packet("measurement", [1.0], step=2**64)


def test_the_api_probe_finds_no_escaping_exception():
    calls, escapes = run_probes()
    assert calls >= 40 * len(HOSTILE)
    assert escapes == [], "\n".join(escapes)


# ---------------------------------------------------------------------------
# 4. Nothing silently wrong


def test_an_indefinite_constant_q_is_refused_at_construction():
    with pytest.raises(edccif.NotPositiveDefiniteError, match="Q: .*smallest eigenvalue is -1"):
        models.LinearMotion(np.eye(2), np.diag([1.0, -1.0]))
    with pytest.raises(edccif.NotPositiveDefiniteError, match=r"Q\[0, 1\] = 0.5 differs from Q\[1, 0\] = 0"):
        models.CustomMotion(lambda X, dt: X, np.array([[1.0, 0.5], [0.0, 1.0]]), n=2)
    models.LinearMotion(np.eye(2), np.zeros((2, 2)))  # semi-definite is a valid Q


@pytest.mark.parametrize("cls", [edccif.CKF, edccif.UKF, edccif.EKF, edccif.CIF, edccif.ETCIF])
def test_a_q_that_makes_p_indefinite_is_refused_at_predict(cls):
    motion = models.CustomMotion(lambda X, dt: X, lambda dt: np.diag([1.0, -5.0]), n=2)
    kf = cls(motion, models.LinearMeasurement([[1.0, 0.0]], [[0.01]]), [0.0, 0.0], np.eye(2), dt=0.1)
    x, p = kf.x.copy(), kf.P.copy()
    with pytest.raises(edccif.NotPositiveDefiniteError, match="P⁻"):
        kf.predict()
    np.testing.assert_array_equal(kf.x, x)
    np.testing.assert_array_equal(kf.P, p)


@pytest.mark.parametrize("cls", [edccif.CKF, edccif.UKF, edccif.EKF])
def test_an_indefinite_p0_is_refused_at_construction(cls):
    with pytest.raises(edccif.NotPositiveDefiniteError):
        cls(models.ConstantVelocity(1, 0.1), models.LinearMeasurement([[1.0, 0.0]], [[0.01]]),
            [0.0, 0.0], np.diag([1.0, -1.0]), dt=0.1)


def test_x_and_p_are_read_only_copies_assign_whole_arrays_instead():
    kf = _cv_filter(edccif.CKF)
    with pytest.raises(ValueError, match="read-only"):
        kf.x[0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        kf.P[0, 0] = 9.0
    kf.x = [1.0, 0.0]
    kf.P = np.diag([9.0, 1.0])
    assert kf.x[0] == 1.0 and kf.P[0, 0] == 9.0
    cif = _cv_filter(edccif.CIF)
    with pytest.raises(ValueError, match="read-only"):
        cif.Y[0, 0] = 1.0


def test_complex_input_is_refused():
    with pytest.raises(edccif.ArgumentTypeError, match="x0: expected real numbers, got complex values"):
        edccif.CKF(models.ConstantVelocity(1, 0.1), models.LinearMeasurement([[1.0, 0.0]], [[0.01]]),
                   np.array([1 + 1j, 0]), np.eye(2))
    kf = _cv_filter(edccif.CKF)
    with pytest.raises(edccif.ArgumentTypeError, match="z: expected real numbers"):
        kf.update(np.array([0.5 + 0.1j]))


def test_encode_packet_refuses_a_non_symmetric_matrix():
    expected = r"matrix: expected a symmetric matrix .* matrix\[0, 1\] = 0.5"
    with pytest.raises(edccif.NotPositiveDefiniteError, match=expected):
        edccif.encode_packet("estimate", [1.0, 2.0], np.array([[1.0, 0.5], [0.0, 1.0]]))


def test_duplicate_monte_carlo_labels_are_refused():
    sc = edccif.Scenario.paper(3).replace(steps=5)
    with pytest.raises(edccif.ParameterError, match='two variants have the label "a"'):
        edccif.monte_carlo(sc, [{"label": "a", "algorithm": "edc-cif"}, {"label": "a", "algorithm": "ec-ckf"}],
                           runs=2, progress=False)
    with pytest.raises(edccif.ParameterError, match="EDC-CIF"):
        edccif.monte_carlo(sc, ["edc-cif", "edc-cif"], runs=2, progress=False)


@pytest.mark.parametrize("name", ["delta", "sigma1", "sigma2", "gate"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), 0.0, -1.0])
def test_thresholds_are_validated(name, bad):
    with pytest.raises(edccif.ParameterError, match=f"{name}: expected a finite number > 0"):
        _cv_filter(edccif.ETCIF, **{name: bad})
    sc = edccif.Scenario.paper(3).replace(steps=3)
    _, z, _ = sc.simulate(seed=0)
    with pytest.raises(edccif.ParameterError, match=f"{name}: expected a finite number > 0"):
        edccif.run("edc-cif", sc, z, **{name: bad})


# ---------------------------------------------------------------------------
# 7. Progress anywhere


def test_a_progress_callback_sees_the_work_to_its_end():
    sc = edccif.Scenario.paper(3).replace(steps=20)
    seen = []
    edccif.monte_carlo(sc, ["edc-cif", "ec-ckf"], runs=6, progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (12, 12)
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))
    _, z, _ = sc.simulate(seed=0)
    seen.clear()
    edccif.run("edc-cif", sc, z, progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (20, 20)
    seen.clear()
    _cv_filter(edccif.CKF).batch_filter(np.zeros((3000, 1)), progress=lambda d, t: seen.append((d, t)))
    assert seen[0] == (0, 3000) and seen[-1] == (3000, 3000)


def test_record_replay_and_reliability_take_a_progress_callback(tmp_path):
    sc = edccif.Scenario.paper(3).replace(steps=20)
    seen = []
    edccif.record("edc-cif", sc, seed=1, mcap=tmp_path / "r.mcap", progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (40, 40)  # the simulation's 20 steps, then the run's
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))
    seen.clear()
    edccif.replay(tmp_path / "r.mcap", progress=lambda d, t: seen.append((d, t)))
    assert seen[-1] == (20, 20)
    seen.clear()
    edccif.reliability_report(tmp_path / "rel.md", robustness=False, soak=200,
                              progress=lambda d, t: seen.append((d, t)))
    assert seen and seen[-1][0] == seen[-1][1] > 0
    with pytest.raises(edccif.ArgumentTypeError, match="progress"):
        edccif.replay(tmp_path / "r.mcap", progress="yes")


def test_a_progress_callback_that_raises_stops_the_work_with_its_exception():
    sc = edccif.Scenario.paper(3).replace(steps=20)

    def broken(done, total):
        raise RuntimeError("the callback failed")

    with pytest.raises(RuntimeError, match="the callback failed"):
        edccif.monte_carlo(sc, "edc-cif", runs=10**6, progress=broken)


def test_progress_must_be_a_bool_or_a_callable():
    with pytest.raises(edccif.ArgumentTypeError, match="progress: expected True, False, None or a callable"):
        edccif.monte_carlo(edccif.Scenario.paper(3), "edc-cif", runs=1, progress="yes")


def test_progress_without_a_terminal_prints_a_line_every_few_seconds():
    out = io.StringIO()
    r = Reporter("monte_carlo", "runs", every=0.0, stream=out)
    r(3, 10)
    r(7, 10)
    r.close()
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("monte_carlo: 3/10 runs (30 %)") and "elapsed" in lines[0] and "ETA" in lines[0]
    assert lines[-1].startswith("monte_carlo: 7/10 runs (70 %)")
    quiet = io.StringIO()
    r = Reporter("run", "steps", every=3600.0, stream=quiet)
    r(1, 2)
    r.close()
    assert quiet.getvalue() == ""  # a short call prints nothing


def test_sweep_worker_counts_are_validated():
    from edccif.sweep import Grid, run_sweep

    for bad in (0, -1, 10**6, 2.5, True):
        with pytest.raises(edccif.ParameterError, match=r"workers: expected an integer in 1\.\.="):
            run_sweep(Grid(), None, scheduler="inprocess", workers=bad)
