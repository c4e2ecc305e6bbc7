"""Python-side overhead of edccif, measured side by side in one process.

1. `edccif.run()` over a 200-step 8-node sequence: wall time of the Python call
   against the Rust runner's own loop time (`RunResult.elapsed_s`, measured inside
   Rust around the stepping loop). Target: within 1.5x.
2. `Network.step` per call against the Rust step time (the per-step share of the
   Rust loop time of the same algorithm on the same measurements). Target: the
   call adds <= 2 us.

Every repetition runs both, in alternating order, and the overhead is taken per
repetition before the median, so that load drifting between repetitions
cancels; quartiles are printed beside it. Two estimates of the Rust step:

- "Rust loop": `RunResult.elapsed_s / T` (wall clock, measured inside Rust);
- "CPU": the thread's CPU time of `run()` over the T steps minus that of `run()`
  over the first step only, per step (the fixed costs of the call, converting
  the inputs and building the result, cancel), against the thread's CPU time of
  `Network.step` over steps 2..T (step 1 untimed, so both cover the same steps).
  CPU time does not count the time the thread is descheduled, which dominates
  the wall-clock noise on a loaded machine.

The step loop iterates over a pre-built list of the (N, 3) measurement arrays,
so the figure is the call itself (argument conversion, time handling, the step,
the estimates array returned), not the slicing of a (T, N, 3) array (the script
prints that cost separately).

`--instructions` runs the step loop again under callgrind (valgrind must be
installed) and prints the instructions per call inside the Rust network step
(`Network::step_dt_with`, inclusive) and inside the binding's wrapper
(`PyNetwork::step`, inclusive: argument parsing and conversion, time handling,
the step, the returned array). Their difference is the binding's cost,
independent of the machine's load; it leaves out the interpreter's own call
and freeing the returned array.

`--single` instead times the single filters (EKF, CKF, ETCIF on node 0 of the
paper's scenario, 200 steps): the Python loop `predict(); update(z)` against
one `batch_filter(zs)` call over the same steps (the same numbers bit for bit,
tested in `python/tests/test_batch_filter.py`), thread CPU time per step,
interleaved repetitions, medians with quartiles and the median per-repetition
ratio.

Usage: python3 benchmarks/python_overhead.py [--reps 31] [--nodes 8] [--instructions] [--single]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import edccif
import edccif.models

ALGS = ("edc-cif", "ec-ckf")


def quartiles(xs: list[float]) -> tuple[float, float, float]:
    q1, q2, q3 = statistics.quantiles(xs, n=4, method="inclusive")
    return q1, q2, q3


def step_loop(net: edccif.Network, zs: list) -> tuple[float, float]:
    """Wall and thread-CPU seconds of `net.step` over `zs`."""
    step = net.step
    c0, t0 = time.thread_time(), time.perf_counter()
    for zk in zs:
        step(zk)
    return time.perf_counter() - t0, time.thread_time() - c0


def timed_run(alg: str, sc: edccif.Scenario, z, x0) -> tuple[float, float, float]:
    """Wall and thread-CPU seconds of `edccif.run`, and its Rust loop time."""
    c0, t0 = time.thread_time(), time.perf_counter()
    res = edccif.run(alg, sc, z, x0=x0, record_covariances=False)
    return time.perf_counter() - t0, time.thread_time() - c0, res.elapsed_s


def fmt(xs: list[float]) -> str:
    q1, q2, q3 = quartiles(xs)
    return f"{1e6 * q2:6.2f} us [q1 {1e6 * q1:.2f}, q3 {1e6 * q3:.2f}]"


def timing(args: argparse.Namespace) -> None:
    sc = edccif.Scenario.paper(nodes=args.nodes)
    _, z, x0 = sc.simulate(seed=0)
    zs = list(z)  # views of z, made once
    steps = len(zs)
    for alg in ALGS:
        py_wall, rust_loop, step_wall, step_cpu, rust_cpu = [], [], [], [], []
        over_loop, over_cpu, slicing = [], [], []
        # warm-up
        timed_run(alg, sc, z, x0)
        step_loop(edccif.Network(sc, alg, x0=x0), zs)
        for rep in range(args.reps):
            order = (0, 1) if rep % 2 == 0 else (1, 0)
            for which in order:
                if which == 0:
                    wall, cpu, loop = timed_run(alg, sc, z, x0)
                    _, cpu1, _ = timed_run(alg, sc, z[:1], x0)
                    py_wall.append(wall)
                    rust_loop.append(loop)
                    rust_cpu.append((cpu - cpu1) / (steps - 1))
                else:
                    net = edccif.Network(sc, alg, x0=x0)
                    net.step(zs[0])
                    wall, cpu = step_loop(net, zs[1:])
                    step_wall.append(wall / (steps - 1))
                    step_cpu.append(cpu / (steps - 1))
            over_loop.append(step_wall[-1] - rust_loop[-1] / steps)
            over_cpu.append(step_cpu[-1] - rust_cpu[-1])
            t0 = time.perf_counter()
            for _zk in z:
                pass
            slicing.append((time.perf_counter() - t0) / steps)
        wall = statistics.median(py_wall)
        loop = statistics.median(rust_loop)
        print(f"{alg}, {args.nodes} nodes, {steps} steps, median of {args.reps} interleaved repetitions:")
        print(f"  run() from Python  {1e3 * wall:8.3f} ms   Rust loop {1e3 * loop:8.3f} ms   "
              f"ratio {wall / loop:5.2f}x (target <= 1.5x)")
        print(f"  Network.step, wall {1e6 * statistics.median(step_wall):8.2f} us   "
              f"Rust loop per step {1e6 * loop / steps:8.2f} us   overhead {fmt(over_loop)}")
        print(f"  Network.step, CPU  {1e6 * statistics.median(step_cpu):8.2f} us   "
              f"run() per step     {1e6 * statistics.median(rust_cpu):8.2f} us   overhead {fmt(over_cpu)}   "
              "(target <= 2 us)")
        print(f"  (iterating `for zk in z` over the (T, N, 3) array adds "
              f"{1e6 * statistics.median(slicing):.2f} us per step on the caller's side)")


CALLGRIND_CHILD = """
import sys, edccif
sc = edccif.Scenario.paper(nodes=int(sys.argv[1]))
_, z, x0 = sc.simulate(seed=0)
zs = list(z)[: int(sys.argv[3])]
net = edccif.Network(sc, sys.argv[2], x0=x0)
step = net.step
for zk in zs:
    step(zk)
"""


def callgrind(script: str, out: str, nodes: int, alg: str, steps: int) -> str:
    cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", "--collect-atstart=no",
           "--toggle-collect=*PyNetwork*__pymethod_step__*", sys.executable, script, str(nodes), alg, str(steps)]
    subprocess.run(cmd, check=True, capture_output=True)
    return subprocess.run(
        ["callgrind_annotate", "--inclusive=yes", "--threshold=100", out],
        check=True, capture_output=True, text=True,
    ).stdout


def inclusive(annotate: str, pattern: str) -> int:
    """Largest inclusive Ir on a line of `callgrind_annotate --inclusive=yes`
    output whose function matches `pattern` (the other matching lines are the
    parts of that function inlined from other files)."""
    best = 0
    for line in annotate.splitlines():
        m = re.match(r"\s*([\d,]+)\s", line)
        if m and re.search(pattern, line):
            best = max(best, int(m.group(1).replace(",", "")))
    return best


def instructions(args: argparse.Namespace) -> None:
    if shutil.which("valgrind") is None or shutil.which("callgrind_annotate") is None:
        sys.exit("--instructions needs valgrind and callgrind_annotate on PATH")
    sc = edccif.Scenario.paper(nodes=args.nodes)
    steps = sc.steps
    with tempfile.TemporaryDirectory() as tmp:
        script = os.path.join(tmp, "child.py")
        with open(script, "w") as f:
            f.write(CALLGRIND_CHILD)
        for alg in ALGS:
            out = os.path.join(tmp, f"cg.{alg}.out")
            ann = callgrind(script, out, args.nodes, alg, steps)
            total = inclusive(ann, r"PyNetwork.*__pymethod_step__")
            rust = inclusive(ann, r"::step_dt_with\b")
            print(f"{alg}, {args.nodes} nodes, {steps} calls under callgrind, instructions per call: "
                  f"Rust step {rust / steps:,.0f}; inside the binding's wrapper {total / steps:,.0f}, "
                  f"so the binding adds {(total - rust) / steps:,.0f}")


def single(args: argparse.Namespace) -> None:
    sc = edccif.Scenario.paper(nodes=1)
    _, z, x0 = sc.simulate(seed=0)
    zs = np.ascontiguousarray(z[:, 0])
    rows = [None if np.isnan(r).all() else r for r in zs]
    mo, me = sc.motion, sc.measurement
    ct = edccif.models.CoordinatedTurn(mo["q1"], mo["q2"])
    rpa = edccif.models.RangePitchAzimuth(sc.sensors[0], me["sigma_r"], me["sigma_a"])
    kinds = {"EKF": edccif.EKF, "CKF": edccif.CKF, "ETCIF": edccif.ETCIF}
    steps = len(rows)
    for name, cls in kinds.items():
        loop_cpu, batch_cpu, ratio = [], [], []
        for rep in range(args.reps + 1):
            a = cls(ct, rpa, x0, sc.p0, dt=sc.dt)
            b = cls(ct, rpa, x0, sc.p0, dt=sc.dt)
            predict, update = a.predict, a.update
            order = (0, 1) if rep % 2 == 0 else (1, 0)
            t = [0.0, 0.0]
            for which in order:
                c0 = time.thread_time()
                if which == 0:
                    for r in rows:
                        predict()
                        update(r)
                else:
                    b.batch_filter(zs)
                t[which] = (time.thread_time() - c0) / steps
            if rep == 0:
                continue  # warm-up
            loop_cpu.append(t[0])
            batch_cpu.append(t[1])
            ratio.append(t[0] / t[1])
        print(f"{name}, {steps} steps, median of {args.reps} interleaved repetitions, thread CPU per step:")
        print(f"  Python loop predict(); update(z)  {fmt(loop_cpu)}")
        print(f"  batch_filter(zs)                  {fmt(batch_cpu)}")
        print(f"  loop / batch                      {statistics.median(ratio):6.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=31)
    ap.add_argument("--nodes", type=int, default=8)
    ap.add_argument("--instructions", action="store_true",
                    help="also count instructions per call under callgrind")
    ap.add_argument("--single", action="store_true",
                    help="time the single filters: the Python loop against batch_filter")
    args = ap.parse_args()
    if args.single:
        single(args)
        return
    timing(args)
    if args.instructions:
        instructions(args)


if __name__ == "__main__":
    main()
