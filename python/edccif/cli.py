"""The `edccif` command line."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Callable, List, Optional

import numpy as np

from . import _edccif


def _scenario(args: argparse.Namespace) -> _edccif.Scenario:
    if getattr(args, "scenario", None):
        return _edccif.Scenario.from_toml(args.scenario)
    return _edccif.Scenario.paper(nodes=args.nodes)


_JOBS_HELP = (
    "worker threads of the Monte Carlo runs (default: one per core, or RAYON_NUM_THREADS); "
    "the numbers do not depend on it"
)


def _set_jobs(args: argparse.Namespace) -> None:
    """Sizes the Monte Carlo worker pool from `--jobs` and says so (unless quiet)."""
    if args.jobs is not None:
        _edccif.set_worker_threads(args.jobs)
    if not args.quiet:
        print(f"Monte Carlo on {_edccif.worker_threads()} worker thread(s)", file=sys.stderr)


def cmd_reproduce(args: argparse.Namespace) -> int:
    from .reproduce import reproduce

    _set_jobs(args)
    out = Path(args.out)
    data = reproduce(
        nodes=args.nodes,
        runs=args.runs,
        seed=args.seed,
        out=out,
        figures=not args.no_figures,
        progress=not args.quiet,
        timing_reps=args.timing_reps,
        flights=not args.no_flights,
        data_dir=None if args.data_dir is None else Path(args.data_dir),
    )
    print(data["markdown"])
    if args.json:
        path = out / "results.json"
        print(f"numbers written to {path}", file=sys.stderr)
    print(f"results written to {out}/", file=sys.stderr)
    return 0


def _at_least_one(meaning: str) -> Callable[[str], int]:
    """An argparse type: an integer >= 1, with ``meaning`` in its error message."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise argparse.ArgumentTypeError(f"expected an integer >= 1 ({meaning}), got {text!r}")
        return n

    return parse


_threads = _at_least_one("1: the serial step; n >= 2: the parallel network step")
"""`--threads`: an integer >= 1."""
_jobs = _at_least_one("worker threads")
"""`--jobs`: an integer >= 1."""


_THREADS_HELP = (
    "threads of the network step (default 1: serial; n >= 2: each step's nodes on n threads, "
    "the same numbers bit for bit, faster from about 64 nodes)"
)


def cmd_simulate(args: argparse.Namespace) -> int:
    sc = _scenario(args)
    truth, z, x0 = sc.simulate(seed=args.seed)
    if args.mcap or args.tum:
        res = _edccif.record(
            args.algorithm,
            sc,
            seed=args.seed,
            mcap=args.mcap,
            tum_dir=args.tum,
            ros2=args.ros2,
            compression=args.mcap_compression,
            threads=args.threads,
        )
    else:
        res = _edccif.run(args.algorithm, sc, z, x0=x0, threads=args.threads)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out,
        truth=truth,
        z=z,
        x0=x0,
        estimates=res.estimates,
        covariances=res.covariances,
        triggered=res.triggered,
        sensors=sc.sensors,
    )
    err = np.linalg.norm(res.estimates[:, :, :3] - truth[:, None, :3], axis=2)
    summary = {
        "scenario": sc.name,
        "algorithm": res.algorithm,
        "seed": args.seed,
        "steps": res.steps,
        "nodes": res.nodes,
        "trigger_rate": res.trigger_rate,
        "mean_position_error_m": float(err.mean()),
        "values_sent": res.values_sent,
        "elapsed_s": res.elapsed_s,
        "threads": args.threads,
        "arrays": str(out),
        "mcap": args.mcap,
        "tum_dir": args.tum,
    }
    print(json.dumps(summary, indent=2))
    return 0


def position_scenario(
    z: np.ndarray,
    dt: float,
    sigma: float = 0.01,
    q: float = 0.5,
    name: str = "ros2",
    t: Optional[np.ndarray] = None,
) -> _edccif.Scenario:
    """A constant-velocity scenario with 3-D position measurements for recorded
    positions `z` (T, N, 3) at nominal step `dt` (row times `t` (T,) in seconds
    when the rows are not uniform): x0 from the first rows (position: the first
    measured row's mean; velocity: its difference over up to 5 rows divided by
    their time apart), a ring of the N nodes (a line for 3 or fewer), sensors at
    the origin (position measurements do not use them)."""
    t_len, nodes, _ = z.shape
    times = np.arange(t_len) * dt if t is None else np.asarray(t, dtype=float)
    means = np.array([np.nanmean(r, axis=0) if np.isfinite(r).any() else np.full(3, np.nan) for r in z])
    finite = np.flatnonzero(np.isfinite(means).all(axis=1))
    if finite.size == 0:
        raise _edccif.ParameterError("z: no measurement to start from; expected at least one finite row")
    first = finite[0]
    later = finite[(finite > first) & (finite <= first + 5)]
    vel = (means[later[-1]] - means[first]) / (times[later[-1]] - times[first]) if later.size else np.zeros(3)
    x0 = [*means[first].tolist(), *vel.tolist()]
    return _edccif.Scenario.from_dict(
        {
            "name": name,
            "dt": dt,
            "steps": int(t_len),
            "delta": 3e-4,
            "sigma1": 5e-4,
            "sigma2": 5e-4,
            "x0": x0,
            "p0_diag": [1e-2, 1e-2, 1e-2, 0.04, 0.04, 0.04],
            "sensors": [[0.0, 0.0, 0.0]] * nodes,
            "motion": {"kind": "constant-velocity", "q": q},
            "measurement": {"kind": "position", "sigma": [sigma] * 3},
            "topology": {"kind": "ring" if nodes > 3 else "line"},
        }
    )


def cmd_replay(args: argparse.Namespace) -> int:
    truth = None
    if (args.truth or args.rate) and not args.measurement:
        raise _edccif.ParameterError("--truth and --rate: only with --measurement (the ROS 2 topics to read)")
    if args.measurement:
        # On the messages' own stamps, or resampled with --rate.
        rec = _edccif.read_ros2(args.file, args.measurement, truth=args.truth, rate_hz=args.rate)
        if args.scenario:
            sc = _edccif.Scenario.from_toml(args.scenario)
        else:
            if args.rate:
                step = 1.0 / args.rate
            else:
                steps = np.diff(rec["t"])
                if steps.size == 0:
                    raise _edccif.ParameterError(f"{args.file}: fewer than two stamps; pass --scenario or --rate")
                step = float(np.median(steps))
            sc = position_scenario(rec["z"], step, sigma=args.sigma, q=args.q, t=rec["t"])
        t_ns, z, truth = rec["t_ns"], rec["z"], rec["truth"]
        res = _edccif.replay(
            args.file,
            sc,
            args.algorithm,
            measurements=args.measurement,
            truth=args.truth,
            rate_hz=args.rate,
            threads=args.threads,
        )
    else:
        t_ns, z, _ = _edccif.read_mcap_measurements(args.file)
        sc = _edccif.Scenario.from_toml(args.scenario) if args.scenario else _edccif.Scenario.paper(nodes=z.shape[1])
        res = _edccif.replay(args.file, sc, args.algorithm, threads=args.threads)
    summary = {
        "file": args.file,
        "algorithm": res.algorithm,
        "steps": res.steps,
        "nodes": res.nodes,
        "timing": "resampled" if args.rate else ("stamps" if args.measurement else "log times"),
        "trigger_rate": res.trigger_rate,
        "values_sent": res.values_sent,
        "final_estimates": res.estimates[-1, :, :3].tolist(),
    }
    if truth is not None:
        err = np.linalg.norm(res.estimates[:, :, :3] - truth[:, None, :], axis=2)
        known = np.isfinite(err)
        summary["position_rmse_m"] = float(np.sqrt(np.mean(err[known] ** 2))) if known.any() else None
    if args.out:
        arrays = {"t_ns": t_ns, "z": z, "estimates": res.estimates, "triggered": res.triggered}
        if args.measurement:
            # The step lengths the filter ran with (dt[0]: from x0 to the first row).
            arrays["dt"] = np.full(len(t_ns), 1.0 / args.rate) if args.rate else np.r_[sc.dt, rec["dt"][1:]]
        if truth is not None:
            arrays["truth"] = truth
        np.savez_compressed(args.out, **arrays)
        summary["arrays"] = args.out
    print(json.dumps(summary, indent=2))
    return 0


def cmd_preprocess(args: argparse.Namespace) -> int:
    out = _edccif.preprocess(
        args.truth, args.observer, rate_hz=args.rate, spatial=not args.no_spatial, with_scale=args.scale
    )
    if args.out:
        np.savez_compressed(args.out, t=out["t"], truth=out["truth"], z=out["z"])
    print(json.dumps({"steps": int(out["t"].shape[0]), "dt": out["dt"], "report": out["report"],
                      "arrays": args.out}, indent=2))
    return 0


def cmd_reliability(args: argparse.Namespace) -> int:
    _set_jobs(args)
    md = _edccif.reliability_report(
        args.out,
        runs=args.runs,
        seed=args.seed,
        nodes=args.nodes,
        soak=args.soak,
        robustness=not args.no_robustness,
        json=args.json,
        progress=not args.quiet,
    )
    print(md)
    return 0


def cmd_algorithms(_args: argparse.Namespace) -> int:
    for a in _edccif.algorithms():
        print(a)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="edccif",
        description="Event-triggered diffusion cubature information filtering (EDC-CIF) and its baselines.",
    )
    p.add_argument("--version", action="version", version=f"edccif {_edccif.__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser(
        "reproduce",
        help="reproduce the paper's tables and figures on the built-in default scenario",
    )
    r.add_argument("--nodes", type=int, nargs="+", default=[3, 4, 8], help="node counts (default: 3 4 8)")
    r.add_argument("--runs", type=int, default=100, help="Monte Carlo runs per configuration (default 100)")
    r.add_argument("--seed", type=int, default=0, help="seed of run 0; run r uses seed + r")
    r.add_argument("--out", default="results", help="output directory (default: results)")
    r.add_argument("--json", action="store_true", help="also report where the numbers (results.json) are")
    r.add_argument("--no-figures", action="store_true", help="skip the figures and the timing pass")
    r.add_argument("--timing-reps", type=int, default=11, help="repetitions of the timing pass")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.add_argument("--jobs", type=_jobs, help=_JOBS_HELP)
    flights = r.add_mutually_exclusive_group()
    flights.add_argument("--data-dir", help="the real flights' ground-truth files (EuRoC V102_groundtruth.csv, "
                   "TUM freiburg1_xyz-groundtruth.txt; default: ../shared/data from the working directory, "
                   "else beside the source tree; the section is skipped when neither exists)")
    flights.add_argument("--no-flights", action="store_true", help="leave out the real-flight section")
    r.set_defaults(func=cmd_reproduce)

    s = sub.add_parser("simulate", help="simulate one scenario, run one algorithm, save the arrays (.npz)")
    s.add_argument("--nodes", type=int, default=4, help="nodes of the built-in scenario (default 4)")
    s.add_argument("--scenario", help="a scenario TOML file instead of the built-in one")
    s.add_argument("--algorithm", default="edc-cif", choices=_edccif.algorithms())
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", default="run.npz", help="output .npz file (default run.npz)")
    s.add_argument("--mcap", help="also write the run as an MCAP file (opens in Foxglove)")
    s.add_argument("--tum", help="also write truth.txt and node{i}.txt (TUM, for evo) into this directory")
    s.add_argument(
        "--ros2",
        action="store_true",
        help="MCAP: also write the measurements and truth as ROS 2 PointStamped (/node{i}/point, /truth/point)",
    )
    s.add_argument(
        "--mcap-compression", choices=["zstd", "none"], default="zstd", help="MCAP chunk compression (default zstd)"
    )
    s.add_argument("--threads", type=_threads, default=1, help=_THREADS_HELP)
    s.set_defaults(func=cmd_simulate)

    rp = sub.add_parser("replay", help="replay the measurements of an MCAP file (edccif run or ROS 2 bag)")
    rp.add_argument("file", help="MCAP file: /node{i}/measurement topics, or a ROS 2 bag with --measurement")
    rp.add_argument("--algorithm", default="edc-cif", choices=_edccif.algorithms())
    rp.add_argument(
        "--scenario",
        help="a scenario TOML file (default: the built-in one with the file's node count; with --measurement "
        "a constant-velocity position scenario at the stamps' median step)",
    )
    rp.add_argument(
        "--measurement",
        action="append",
        metavar="TOPIC[#FRAME]",
        help="ROS 2 source of one node's measurements (repeat per node; for /tf give the child frame)",
    )
    rp.add_argument("--truth", metavar="TOPIC[#FRAME]", help="ROS 2 source of the ground truth")
    rp.add_argument(
        "--rate",
        type=float,
        help="resample to a uniform grid at this rate in Hz (default: run on the messages' own stamps)",
    )
    rp.add_argument("--sigma", type=float, default=0.01, help="position noise (m) of the default scenario")
    rp.add_argument("--q", type=float, default=0.5, help="acceleration noise (m²/s³) of the default scenario")
    rp.add_argument("--out", help="write the estimates to this .npz file")
    rp.add_argument("--threads", type=_threads, default=1, help=_THREADS_HELP)
    rp.set_defaults(func=cmd_replay)

    pp = sub.add_parser("preprocess", help="the real-world preprocessing pipeline on TUM files")
    pp.add_argument("--truth", required=True, help="ground truth (TUM), e.g. motion capture")
    pp.add_argument("--observer", required=True, nargs="+", help="each observer's target track (TUM)")
    pp.add_argument("--rate", type=float, help="common frame rate in Hz (default: the observers' median)")
    pp.add_argument("--scale", action="store_true", help="spatial alignment with scale")
    pp.add_argument("--no-spatial", action="store_true", help="observers are already in the truth's frame")
    pp.add_argument("--out", help="write the aligned arrays to this .npz file")
    pp.set_defaults(func=cmd_preprocess)

    rel = sub.add_parser(
        "reliability",
        help="robustness under faults (and a soak run); updates docs/reliability.md",
    )
    rel.add_argument("--out", default="docs/reliability.md", help="document to update (default docs/reliability.md)")
    rel.add_argument("--runs", type=int, default=50, help="Monte Carlo runs per row (default 50)")
    rel.add_argument("--seed", type=int, default=0, help="seed of run 0")
    rel.add_argument("--nodes", type=int, nargs="+", default=[4, 8], help="node counts (default: 4 8)")
    rel.add_argument("--soak", type=int, help="also run the soak test with this many steps (e.g. 1000000)")
    rel.add_argument("--no-robustness", action="store_true", help="skip the Monte Carlo study")
    rel.add_argument("--json", help="also write the numbers to this JSON file")
    rel.add_argument("--quiet", action="store_true", help="no progress messages")
    rel.add_argument("--jobs", type=_jobs, help=_JOBS_HELP)
    rel.set_defaults(func=cmd_reliability)

    from .sweep import add_subcommand as add_sweep

    add_sweep(sub)

    from .agents import add_subcommands as add_agents

    add_agents(sub)

    a = sub.add_parser("algorithms", help="list the algorithm rows")
    a.set_defaults(func=cmd_algorithms)
    return p


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except _edccif.EdccifError as e:
        print(f"edccif: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Ctrl-C: one line, the shell's code for SIGINT (128 + 2). What was
        # finished stays: a sweep's table holds its finished cells.
        print("edccif: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
