"""The `threads` option (the parallel network step) from Python: `run`,
`Network`, `monte_carlo`, `record` and the CLI give the serial step's numbers to
the bit (compared as raw float64 bits, tolerance zero) on a 64-node ring and a
small network; bad values raise `edccif.ParameterError`; the docstring examples
run; a long run releases the GIL. Speed is measured in benchmarks, not here."""

import doctest
import json
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import edccif
from edccif import models

RING = 64


def bits(a):
    """Raw bits of a float array (so -0.0 != 0.0 and NaN payloads count)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def assert_same_result(a, b):
    assert a.algorithm == b.algorithm
    assert np.array_equal(bits(a.estimates), bits(b.estimates))
    assert np.array_equal(bits(a.covariances), bits(b.covariances))
    assert np.array_equal(a.triggered, b.triggered)
    assert np.array_equal(a.measured, b.measured)
    assert a.values_sent == b.values_sent
    assert (a.guard_fallbacks, a.gated, a.trigger_rate) == (b.guard_fallbacks, b.gated, b.trigger_rate)


@pytest.fixture(scope="module")
def ring():
    sc = edccif.Scenario.paper(RING).replace(topology="ring", steps=30)
    truth, z, x0 = sc.simulate(seed=3)
    z = z.copy()
    z[::4, 5] = np.nan  # some missing measurements
    return sc, z, x0


@pytest.mark.parametrize("algorithm,options", [("edc-cif", {}), ("ec-ckf", {"consensus_iters": 6})])
def test_run_parallel_equals_serial_on_a_64_node_ring(ring, algorithm, options):
    sc, z, x0 = ring
    serial = edccif.run(algorithm, sc, z, x0=x0, **options)
    assert serial.measured.sum() > 0 and serial.triggered.sum() > 0
    for threads in (1, 2, 3):
        par = edccif.run(algorithm, sc, z, x0=x0, threads=threads, **options)
        assert_same_result(serial, par)
    faults = {"seed": 2, "message_loss": 0.2, "dropout": [(7, 3, 9)]}
    a = edccif.run(algorithm, sc, z, x0=x0, faults=faults, **options)
    b = edccif.run(algorithm, sc, z, x0=x0, faults=faults, threads=2, **options)
    assert_same_result(a, b)


def test_run_parallel_equals_serial_on_a_small_network():
    sc = edccif.Scenario.paper(4).replace(steps=50)
    truth, z, x0 = sc.simulate(seed=1)
    for algorithm in ("edc-cif", "ec-ckf"):
        assert_same_result(edccif.run(algorithm, sc, z, x0=x0), edccif.run(algorithm, sc, z, x0=x0, threads=2))


@pytest.mark.parametrize("algorithm", ["edc-cif", "ec-ckf"])
def test_network_parallel_equals_serial_step_by_step(ring, algorithm):
    sc, z, x0 = ring
    a = edccif.Network(sc, algorithm, x0, consensus_iters=5)
    b = edccif.Network(sc, algorithm, x0, consensus_iters=5, threads=2)
    assert (a.threads, b.threads) == (1, 2)
    links = np.ones((RING, RING), dtype=bool)
    links[10, 11] = False
    active = np.ones(RING, dtype=bool)
    active[40] = False
    for k, zk in enumerate(z):
        masks = (links, active) if k % 3 == 1 else (None, None)
        if k == 20:
            b.threads = 1  # switch back to the serial step mid-run...
        if k == 25:
            b.threads = 3  # ...and to three threads
        assert np.array_equal(bits(a.step(zk, *masks)), bits(b.step(zk, *masks)))
        assert np.array_equal(bits(a.covariances), bits(b.covariances))
        assert np.array_equal(bits(a.local_estimates), bits(b.local_estimates))
        assert np.array_equal(a.triggered, b.triggered)
    assert b.threads == 3
    assert a.counters == b.counters


def test_monte_carlo_with_threads_equals_serial():
    sc = edccif.Scenario.paper(RING).replace(topology="ring", steps=15)
    algs = ["edc-cif", {"label": "EC-CKF L=3", "algorithm": "ec-ckf", "consensus_iters": 3}]
    a = edccif.monte_carlo(sc, algs, runs=2, seed=5, progress=False)
    b = edccif.monte_carlo(sc, algs, runs=2, seed=5, progress=False, threads=2)
    for label in a.labels:
        assert a.pos_rmse[label] == b.pos_rmse[label]
        assert np.array_equal(bits(a.pos_rmse_curve[label]), bits(b.pos_rmse_curve[label]))
        assert a.trigger_rate[label] == b.trigger_rate[label]


def test_record_with_threads_equals_serial(tmp_path):
    sc = edccif.Scenario.paper(8).replace(steps=20)
    a = edccif.record("edc-cif", sc, seed=2, mcap=str(tmp_path / "a.mcap"))
    b = edccif.record("edc-cif", sc, seed=2, mcap=str(tmp_path / "b.mcap"), threads=2)
    assert_same_result(a, b)


@pytest.mark.parametrize("bad", [0, -1, True, 1.5, "2"])
def test_bad_thread_counts_raise_parameter_error(ring, bad):
    sc, z, x0 = ring
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.run("edc-cif", sc, z, x0=x0, threads=bad)
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.Network(sc, "edc-cif", x0, threads=bad)
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.monte_carlo(sc, "edc-cif", runs=1, progress=False, threads=bad)
    net = edccif.Network(sc, "edc-cif", x0, threads=2)
    with pytest.raises(edccif.ParameterError, match="threads"):
        net.threads = bad
    assert net.threads == 2, "a rejected value changes nothing"
    assert issubclass(edccif.ParameterError, ValueError)


def test_single_nodes_and_own_model_networks_refuse_threads():
    sc = edccif.Scenario.paper(4)
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.Node(sc, "edc-cif", node=0, threads=2)
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.SensorTrigger(sc, "edc-cif", node=0, threads=2)
    motion = models.ConstantVelocity(dim=2, q=0.1)
    sensors = [models.Position(sigma=[0.1, 0.1]) for _ in range(3)]
    kw = dict(x0=np.zeros(4), P0=np.eye(4), dt=0.1)
    edccif.ModelNetwork(motion, sensors, "edc-cif", threads=1, **kw)
    with pytest.raises(edccif.ParameterError, match="threads"):
        edccif.ModelNetwork(motion, sensors, "edc-cif", threads=2, **kw)


@pytest.mark.parametrize("obj", [edccif.run, edccif.Network])
def test_docstring_examples_run(obj):
    assert "threads=2" in obj.__doc__
    parser = doctest.DocTestParser()
    test = parser.get_doctest(obj.__doc__, {}, obj.__name__, None, 0)
    assert test.examples, "the docstring has an example"
    result = doctest.DocTestRunner(verbose=False).run(test)
    assert result.failed == 0


def test_a_long_parallel_run_releases_the_gil():
    # A Python thread ticking every millisecond keeps ticking while the run steps
    # (with the GIL held it could not tick at all during the call). At least 5
    # ticks during a run of at least 0.2 s; the run is repeated until it is that
    # long (a loaded machine makes it longer, never shorter).
    sc = edccif.Scenario.paper(128).replace(topology="ring", steps=200)
    truth, z, x0 = sc.simulate(seed=0)
    ticks = []
    stop = threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=tick)
    t.start()
    try:
        while True:
            t0 = time.perf_counter()
            res = edccif.run("edc-cif", sc, z, x0=x0, threads=2, record_covariances=False)
            t1 = time.perf_counter()
            if res.elapsed_s >= 0.2:
                break
            sc = sc.replace(steps=2 * sc.to_dict()["steps"])
            truth, z, x0 = sc.simulate(seed=0)
    finally:
        stop.set()
        t.join()
    during = [x for x in ticks if t0 < x < t1]
    assert len(during) >= 5, (len(during), res.elapsed_s)


def _cli(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True, check=False
    )


def test_cli_threads(tmp_path):
    base = ("simulate", "--nodes", "64", "--algorithm", "edc-cif", "--seed", "2")
    p1 = _cli(*base, "--out", "serial.npz", cwd=tmp_path)
    p2 = _cli(*base, "--out", "par.npz", "--threads", "2", cwd=tmp_path)
    assert p1.returncode == 0 and p2.returncode == 0, p1.stderr + p2.stderr
    assert json.loads(p2.stdout)["threads"] == 2
    a, b = np.load(tmp_path / "serial.npz"), np.load(tmp_path / "par.npz")
    assert np.array_equal(bits(a["estimates"]), bits(b["estimates"]))
    assert np.array_equal(bits(a["covariances"]), bits(b["covariances"]))
    bad = _cli(*base, "--threads", "0", cwd=tmp_path)
    assert bad.returncode == 2 and "--threads" in bad.stderr and ">= 1" in bad.stderr
    helptext = _cli("simulate", "--help", cwd=tmp_path).stdout
    assert "--threads" in helptext and "bit for bit" in helptext
    assert "--threads" in _cli("replay", "--help", cwd=tmp_path).stdout
