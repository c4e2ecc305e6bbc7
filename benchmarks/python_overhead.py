"""Python-side overhead of edccif, measured side by side in one process.

1. `edccif.run()` over a 200-step 8-node sequence: wall time of the Python call
   against the Rust runner's own loop time (`RunResult.elapsed_s`, measured inside
   Rust around the stepping loop). Target: within 1.5x.
2. `Network.step` per call against the Rust step time (the per-step share of the
   Rust loop time of the same algorithm). Target: overhead <= 5 us per call.

Usage: python3 benchmarks/python_overhead.py [--reps 31]
"""

from __future__ import annotations

import argparse
import statistics
import time

import edccif


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=31)
    ap.add_argument("--nodes", type=int, default=8)
    args = ap.parse_args()
    sc = edccif.Scenario.paper(nodes=args.nodes)
    _, z, x0 = sc.simulate(seed=0)
    for alg in ("edc-cif", "ec-ckf"):
        py_wall, rust_loop, step_calls = [], [], []
        for _ in range(args.reps):
            t0 = time.perf_counter()
            res = edccif.run(alg, sc, z, x0=x0, record_covariances=False)
            py_wall.append(time.perf_counter() - t0)
            rust_loop.append(res.elapsed_s)
            net = edccif.Network(sc, alg, x0=x0)
            t0 = time.perf_counter()
            for zk in z:
                net.step(zk)
            step_calls.append((time.perf_counter() - t0) / len(z))
        wall = statistics.median(py_wall)
        loop = statistics.median(rust_loop)
        step = statistics.median(step_calls)
        rust_step = loop / len(z)
        print(f"{alg}, {args.nodes} nodes, {len(z)} steps, median of {args.reps}:")
        print(f"  run() from Python  {1e3 * wall:8.3f} ms   Rust loop {1e3 * loop:8.3f} ms   "
              f"ratio {wall / loop:5.2f}x (target <= 1.5x)")
        print(f"  Network.step       {1e6 * step:8.2f} us   Rust step {1e6 * rust_step:8.2f} us   "
              f"overhead {1e6 * (step - rust_step):6.2f} us/call (target <= 5 us)")


if __name__ == "__main__":
    main()
