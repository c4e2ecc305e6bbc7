"""The `edccif` command line."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import List, Optional

import numpy as np

from . import _args, _edccif


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
    from .reproduce import OUTPUT_FILES, SCENARIO_OUTPUT_FILES, reproduce, reproduce_scenario

    if args.flight and args.no_flights:
        raise _edccif.ParameterError("--flight and --no-flights: give one or the other")
    sc = None
    if args.scenario:
        given = [flag for flag, v in (("--nodes", args.nodes), ("--data-dir", args.data_dir),
                                      ("--flight", args.flight), ("--no-flights", args.no_flights or None),
                                      ("--timing-reps", args.timing_reps),
                                      ("--duplicates", args.duplicates)) if v is not None]
        if given:
            raise _edccif.ParameterError(
                f"{', '.join(given)}: not with --scenario (the file fixes the nodes; the real flights and the "
                "timing pass belong to the paper's reproduction without --scenario)")
        sc = _edccif.Scenario.from_toml(args.scenario)
    out = Path(args.out)
    if not args.force and out.is_dir():
        there = [f for f in (SCENARIO_OUTPUT_FILES if sc else OUTPUT_FILES) if (out / f).exists()]
        if there:
            raise _edccif.ParameterError(
                f"out: {out} already holds {', '.join(there)}; choose another directory or pass --force to replace them"
            )
    _set_jobs(args)
    if sc is not None:
        data = reproduce_scenario(sc, runs=args.runs, seed=args.seed, out=out, figures=not args.no_figures,
                                  progress=not args.quiet)
    else:
        data = reproduce(
            nodes=args.nodes or [3, 4, 8],
            runs=args.runs,
            seed=args.seed,
            out=out,
            figures=not args.no_figures,
            progress=not args.quiet,
            timing_reps=args.timing_reps or 11,
            flights=not args.no_flights,
            data_dir=None if args.data_dir is None else Path(args.data_dir),
            flight_files=args.flight,
            duplicates=args.duplicates or "drop",
        )
    if not args.quiet:
        print(data["markdown"])
    if args.json:
        path = out / "results.json"
        print(f"numbers written to {path}", file=sys.stderr)
    print(f"results written to {out}/", file=sys.stderr)
    return 0


_threads = _args.threads("1: the serial step; n >= 2: the parallel network step")
"""`--threads`: an integer in 1..=4 x cores."""
_jobs = _args.threads("worker threads")
"""`--jobs`: an integer in 1..=4 x cores."""


_THREADS_HELP = (
    "threads of the network step (default 1: serial; n >= 2: each step's nodes on n threads, "
    "the same numbers bit for bit, faster from about 64 nodes)"
)


def _npz_path(path: Path) -> Path:
    """Where ``np.savez_compressed(path)`` writes (it appends ``.npz`` when missing)."""
    return path if path.name.endswith(".npz") else path.with_name(path.name + ".npz")


def _check_tum_dir(tum: Optional[Path], force: bool) -> None:
    """Refuses a ``--tum`` directory that already holds TUM files of a run, unless ``force``."""
    if tum is None:
        return
    if tum.exists() and not tum.is_dir():
        raise _edccif.ParameterError(f"tum: {tum} is a file; expected a directory")
    there = sorted(p.name for p in tum.glob("*.txt") if p.name == "truth.txt" or p.name.startswith("node"))
    if there and not force:
        raise _edccif.ParameterError(
            f"tum: {tum} already holds {', '.join(there)}; choose another directory or pass --force to replace them")


def cmd_simulate(args: argparse.Namespace) -> int:
    out = _npz_path(Path(args.out))
    _args.check_output_files([(out, "out"), (args.mcap, "mcap")], args.force)
    _check_tum_dir(args.tum, args.force)
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
    # the uniform form's node positions (N, 3); a per-node scenario's are in its [[nodes]]
    uniform = "sensors" in sc.to_dict()
    np.savez_compressed(
        out,
        truth=truth,
        z=z,
        x0=x0,
        estimates=res.estimates,
        covariances=res.covariances,
        triggered=res.triggered,
        **({"sensors": sc.sensors} if uniform else {}),
    )
    # the target's position: the first 2 or 3 states (a Python motion does not say: as many as
    # the nodes' positions have)
    d = sc.position_dim or int(sc.sensors.shape[1]) or min(3, sc.state_dim)
    err = np.linalg.norm(res.estimates[:, :, :d] - truth[:, None, :d], axis=2)
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
        "mcap": None if args.mcap is None else str(args.mcap),
        "tum_dir": None if args.tum is None else str(args.tum),
    }
    print(json.dumps(summary, indent=2))
    return 0


def _noise(text: str) -> str:
    """`--noise`: `message`, `scenario` or a standard deviation > 0 (m)."""
    if text in ("message", "scenario"):
        return text
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not (np.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(
            f"expected `message`, `scenario` or a standard deviation > 0 in metres, got {text!r}"
        )
    return text


def _frame_pair(text: str) -> str:
    """`--same-frame`: `FRAME=OTHER` (two different, non-empty names)."""
    a, sep, b = text.partition("=")
    if not sep or not a or not b or a == b:
        raise argparse.ArgumentTypeError(f"expected FRAME=OTHER_FRAME (two different frame names), got {text!r}")
    return text


_MOTION_Q = {"cv3": 0.5, "ca3": 10.0, "ct": 0.5}
"""Default noise intensity of each `--motion` (q; for ct the turn rate's is 0.01)."""


def _motion_model(kind: str, q: Optional[float]):
    from . import models

    q = _MOTION_Q[kind] if q is None else q
    if kind == "cv3":
        return models.ConstantVelocity(3, q)
    if kind == "ca3":
        return models.ConstantAcceleration(3, q)
    return models.CoordinatedTurn(q, 0.01)


def _print_report(rep: dict) -> None:
    """The replay's report in words (`--json` prints it as JSON)."""
    kind = "ROS 2 recording" if rep["kind"] == "ros2" else "edccif recording"
    out = [f"replay of {rep['file']} ({kind})"]

    def line(label: str, text: str) -> None:
        out.append(f"  {label:<18}{text}")

    line("algorithm", rep["algorithm"])
    line("models", rep["models"])
    line("initial estimate", rep["x0"])
    line("rows", f"{rep['steps']} steps, {rep['nodes']} nodes")
    line("timing", rep["timing"])
    line("offsets applied", rep["offsets"])
    stored = rep.get("stored")
    if stored:
        line("stored run", "yes" if stored["stored"] else "none in the file")
        line("scenario", stored["scenario"] + (f" (differs in {', '.join(stored['differences'])})"
                                                 if stored["differences"] else ""))
        if stored["seed"] is not None:
            line("seed", str(stored["seed"]))
    inp = rep.get("input")
    if inp:
        line("frame", f"{inp['frame']} (chosen by {inp['frame_chosen_by']})")
        for src in inp["sources"]:
            for use in src["frames"]:
                if use["transforms"]:
                    chain = ", ".join(
                        f"{e['parent']} → {e['child']} ({e['topic']}, "
                        + ("fixed" if e["fixed"] else f"interpolated between {e['samples']} samples")
                        + ")"
                        for e in use["transforms"]
                    )
                else:
                    chain = "no transform"
                line("", f"{src['role']} {src['source']}: {use['samples']} message(s) in {use['frame']}: {chain}")
            if src["dropped"]:
                line("", f"{src['role']} {src['source']}: {src['dropped']} message(s) dropped "
                         "(outside the span of a /tf transform)")
        line("messages dropped", str(inp["dropped"]))
        for n in inp["noise"]:
            extra = f", {n['from_messages']} from the messages" if n["noise"] == "message" else ""
            if n["unknown_fallbacks"]:
                extra += f", {n['unknown_fallbacks']} unknown → the model's"
            line("noise", f"{n['source']}: {n['detail']}{extra}")
    rates = ", ".join(
        f"{p['source']} {100 * p['trigger_rate']:.1f} %" if p["trigger_rate"] is not None else f"{p['source']} -"
        for p in rep["per_node"]
    )
    line("trigger rate", f"{100 * rep['trigger_rate']:.1f} % ({rates})")
    if rep["position_rmse_m"] is not None:
        truth = (inp or {}).get("truth") or {}
        same = rep["truth_same_frame"]
        where = f" in frame {truth['compared_in']}" if truth else ""
        line("truth", f"position RMSE {rep['position_rmse_m']:.6g} m{where} "
                      f"(same frame as the estimates: {'yes' if same else 'no'})")
    else:
        line("truth", "none compared")
    print("\n".join(out))


def cmd_replay(args: argparse.Namespace) -> int:
    import warnings

    ros2 = bool(args.measurement)
    if not ros2:
        only = [f for f, v in (("--truth", args.truth), ("--rate", args.rate), ("--frame", args.frame),
                               ("--same-frame", args.same_frame)) if v]
        if only:
            raise _edccif.ParameterError(
                f"{', '.join(only)}: only with --measurement (the ROS 2 topics to read)"
            )
    if args.out is not None:
        args.out = _npz_path(args.out)
        _args.check_output_file(args.out, args.force, "out")
    if args.sensor == "scenario" and not args.scenario:
        raise _edccif.ParameterError("--sensor scenario: only with --scenario (its sensors then read the messages)")
    for flag, v in (("--q", args.q), ("--sigma", args.sigma)):
        if v is not None and args.scenario:
            raise _edccif.ParameterError(f"{flag}: only with the models of --motion (a scenario has its own)")
    kw: dict = {"threads": args.threads}
    if args.scenario:
        kw["scenario"] = _edccif.Scenario.from_toml(args.scenario)
    elif args.motion or ros2:
        from . import models

        if ros2:
            k = len(args.measurement)
        else:
            z = _edccif.read_mcap_measurements(args.file)[1]
            if z.ndim != 3:
                raise _edccif.ShapeError(
                    f"--motion: {args.file} is a recording whose nodes measure different sizes (a per-node "
                    "scenario), and --motion gives every node a 3-D position sensor; replay it without --motion "
                    "(the scenario stored in the file), or with --scenario FILE --override, or from Python with "
                    "models of the recording's sizes (edccif.replay(path, motion=..., sensors=[...], x0=..., "
                    "P0=..., override=True))")
            k = z.shape[1]
        kw["motion"] = _motion_model(args.motion or "cv3", args.q)
        kw["sensors"] = [models.Position([0.01 if args.sigma is None else args.sigma] * 3)] * k
        kw["delta"] = args.delta if args.delta is not None else 3e-4
    if args.delta is not None:
        kw["delta"] = args.delta
    if ros2:
        kw.update(
            measurements=args.measurement,
            truth=args.truth,
            rate_hz=args.rate,
            frame=args.frame,
            same_frames=args.same_frame,
            scenario_sensors=args.sensor == "scenario",
        )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = _edccif.replay(args.file, algorithm=args.algorithm, noise=args.noise, override=args.override, **kw)
    for w in caught:
        print(f"edccif: warning: {w.message}", file=sys.stderr)
    rep = res.report
    summary = dict(rep)
    summary["values_sent"] = res.values_sent
    summary["final_estimates"] = res.estimates[-1, :, :3].tolist()
    if args.out:
        if ros2:
            rec = _edccif.read_ros2(args.file, args.measurement, truth=args.truth, rate_hz=args.rate,
                                    frame=args.frame, same_frames=args.same_frame)
            t_ns, z, truth = rec["t_ns"], rec["z"], rec["truth"]
            if args.rate:
                dt = np.full(len(t_ns), 1.0 / args.rate)
            else:
                first = kw["scenario"].dt if args.scenario else float(np.median(np.diff(t_ns) * 1e-9))
                dt = np.r_[first, rec["dt"][1:]]
        else:
            t_ns, z, _ = _edccif.read_mcap_measurements(args.file)
            truth, dt = None, None
        arrays = {"t_ns": t_ns, "z": z, "estimates": res.estimates, "triggered": res.triggered}
        if dt is not None:
            # The step lengths the filter ran with (dt[0]: from x0 to the first row).
            arrays["dt"] = dt
        if truth is not None:
            arrays["truth"] = truth
        np.savez_compressed(args.out, **arrays)
        summary["arrays"] = str(args.out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        _print_report(rep)
        if args.out:
            print(f"arrays written to {args.out}")
    return 0


def cmd_preprocess(args: argparse.Namespace) -> int:
    import warnings

    if args.out is not None:
        args.out = _npz_path(args.out)
        _args.check_output_file(args.out, args.force, "out")
    offsets = {}
    for stream, secs in args.offset or []:
        if stream in offsets:
            raise _edccif.ParameterError(f"--offset: {stream} given twice")
        offsets[stream] = secs
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = _edccif.preprocess(
            args.truth,
            args.observer,
            rate_hz=args.rate,
            spatial=not args.no_spatial,
            with_scale=args.scale,
            align=args.align,
            offsets=offsets,
            offset_window=args.offset_window,
            residual_factor=args.residual_factor,
            duplicates=args.duplicates,
            progress=not args.quiet,
        )
    for w in caught:
        print(f"edccif: warning: {w.message}", file=sys.stderr)
    if args.out:
        np.savez_compressed(args.out, t=out["t"], truth=out["truth"], z=out["z"])
    clock = out["report"]["clock"]
    if not args.quiet:
        # One line per stream: the offset applied and how well it fits.
        names = [Path(o).name for o in args.observer]
        for i, name in enumerate(names):
            dup = out["report"]["duplicates"][i + 1]["dropped"]
            print(
                f"{name}: clock offset {clock['offsets_s'][i]:+.4f} s ({clock['sources'][i]}), "
                f"residual {1e3 * clock['residual_m'][i]:.1f} mm, noise {1e3 * clock['noise_m'][i]:.1f} mm"
                + (f", {dup} repeated stamp(s) dropped" if dup else ""),
                file=sys.stderr,
            )
        dup = out["report"]["duplicates"][0]["dropped"]
        if dup:
            print(f"{Path(args.truth).name}: {dup} repeated stamp(s) dropped", file=sys.stderr)
    print(json.dumps({"steps": int(out["t"].shape[0]), "dt": out["dt"], "report": out["report"],
                      "arrays": None if args.out is None else str(args.out)}, indent=2))
    return 0


def cmd_reliability(args: argparse.Namespace) -> int:
    _args.check_output_files([(args.out, "out"), (args.json, "json")], args.force)
    _set_jobs(args)
    md = _edccif.reliability_report(
        str(args.out),
        runs=args.runs,
        seed=args.seed,
        nodes=args.nodes,
        soak=args.soak,
        robustness=not args.no_robustness,
        json=None if args.json is None else str(args.json),
        progress=not args.quiet,
    )
    print(md)
    return 0


def cmd_algorithms(_args: argparse.Namespace) -> int:
    for a in _edccif.algorithms():
        print(a)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _args.Parser(
        prog="edccif",
        description="Event-triggered diffusion cubature information filtering (EDC-CIF) and its baselines.",
    )
    p.add_argument("--version", action="version", version=f"edccif {_edccif.__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser(
        "reproduce",
        help="reproduce the paper's tables and figures on the built-in default scenario (or the studies of its "
        "tables on a scenario file of one's own with --scenario)",
    )
    r.add_argument("--scenario", help="a scenario TOML file (any model, mixed sensors): every row, the ablations "
                   "and the δ and σ sweeps on it; the real-world and flight sections are left out")
    r.add_argument("--nodes", type=_args.count, nargs="+", help="node counts (default: 3 4 8)")
    r.add_argument("--runs", type=_args.count, default=100, help="Monte Carlo runs per configuration (default 100)")
    r.add_argument("--seed", type=_args.seed, default=0, help="seed of run 0; run r uses seed + r")
    r.add_argument("--out", type=_args.output_dir, default="results",
                   help="output directory (default: results; created when missing)")
    r.add_argument("--force", action="store_true", help="replace the files of an earlier reproduction in --out")
    r.add_argument("--json", action="store_true", help="also report where the numbers (results.json) are")
    r.add_argument("--no-figures", action="store_true", help="skip the figures and the timing pass")
    r.add_argument("--timing-reps", type=_args.count, help="repetitions of the timing pass (>= 1, default 11)")
    r.add_argument("--quiet", action="store_true",
                   help="no progress bars and no tables on stdout (they are in OUT/results.md)")
    r.add_argument("--jobs", type=_jobs, help=_JOBS_HELP)
    flights = r.add_mutually_exclusive_group()
    flights.add_argument("--data-dir", help="the real flights' ground-truth files (EuRoC V102_groundtruth.csv, "
                   "TUM freiburg1_xyz-groundtruth.txt; default: ../shared/data from the working directory, "
                   "else beside the source tree, unless --flight is given; the section is skipped when "
                   "neither exists)")
    flights.add_argument("--no-flights", action="store_true", help="leave out the real-flight section")
    r.add_argument(
        "--flight",
        action="append",
        type=_args.readable_file,
        metavar="FILE",
        help="a TUM or EuRoC ground-truth file as a real flight (repeat for more; after those of --data-dir, "
        "instead of the default directory's); every file is read and checked before the studies run",
    )
    r.add_argument(
        "--duplicates",
        choices=["drop", "refuse"],
        help="a flight's repeated timestamps: dropped and counted (default) or the file refused",
    )
    r.set_defaults(func=cmd_reproduce)

    s = sub.add_parser("simulate", help="simulate one scenario, run one algorithm, save the arrays (.npz)")
    s.add_argument("--nodes", type=_args.count, default=4, help="nodes of the built-in scenario (default 4)")
    s.add_argument("--scenario", help="a scenario TOML file instead of the built-in one")
    s.add_argument("--algorithm", default="edc-cif", type=_args.algorithm,
                   help="the row to run, any case (default edc-cif; see `edccif algorithms`)")
    s.add_argument("--seed", type=_args.seed, default=0)
    s.add_argument("--out", type=_args.output_path, default="run.npz",
                   help="output .npz file (default run.npz; .npz is appended when missing)")
    s.add_argument("--force", action="store_true", help="replace --out, --mcap and --tum files if they exist")
    s.add_argument("--mcap", type=_args.output_path,
                   help="also write the run as an MCAP file (opens in Foxglove); an existing one needs --force")
    s.add_argument("--tum", type=Path,
                   help="also write truth.txt and node{i}.txt (TUM, for evo) into this directory; "
                        "one that holds them needs --force")
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

    rp = sub.add_parser(
        "replay",
        help="replay the measurements of an MCAP file (an edccif recording, or a ROS 2 bag) and report what was done",
    )
    rp.add_argument(
        "file", help="MCAP file: an edccif recording (/node{i}/measurement), or a ROS 2 bag with --measurement"
    )
    rp.add_argument(
        "--algorithm",
        type=_args.algorithm,
        help="the row to run, any case (default: the recording's stored one, else edc-cif)",
    )
    models = rp.add_mutually_exclusive_group()
    models.add_argument(
        "--scenario",
        help="a scenario TOML file: its models, parameters, graph and x0 (an edccif recording that stores "
        "another scenario is refused unless --override)",
    )
    models.add_argument(
        "--motion",
        choices=sorted(_MOTION_Q),
        help="models for position messages: a motion model (cv3: constant velocity, ca3: constant acceleration, "
        "ct: coordinated turn, all 3-D) and a position sensor per source (default for ROS 2 messages: cv3)",
    )
    rp.add_argument(
        "--sensor",
        choices=["position", "scenario"],
        default="position",
        help="how ROS 2 messages' x, y, z are read: as a position (default), or with --scenario as the "
        "scenario's measurement (e.g. range/pitch/azimuth; only when the messages really hold that)",
    )
    rp.add_argument("--q", type=_args.real(0.0, lo_open=True, meaning="the motion model's noise intensity"),
                    help="noise intensity of --motion (default: cv3 0.5 m²/s³, ca3 10 m²/s⁵, ct 0.5)")
    rp.add_argument("--sigma", type=_args.real(0.0, lo_open=True, meaning="metres"),
                    help="the position sensors' own noise σ in metres (default 0.01), used where a message "
                    "gives no covariance")
    rp.add_argument("--delta", type=_args.real(0.0, lo_open=True, meaning="the trigger threshold"),
                    help="send-on-delta threshold (default: 3e-4 m² with --motion models, else the scenario's "
                    "or the stored one)")
    rp.add_argument(
        "--noise",
        type=_noise,
        default="message",
        help="measurement noise of each step: message (default: each message's position covariance, where it "
        "has one), scenario (the sensor model's), or a standard deviation in metres",
    )
    rp.add_argument(
        "--measurement",
        action="append",
        metavar="TOPIC[#FRAME]",
        help="ROS 2 source of one node's measurements (repeat per node; for /tf give the child frame)",
    )
    rp.add_argument("--truth", metavar="TOPIC[#FRAME]", help="ROS 2 source of the ground truth")
    rp.add_argument("--frame", help="the frame every source is brought into (default: the first measurement's)")
    rp.add_argument("--same-frame", action="append", type=_frame_pair, metavar="FRAME=OTHER",
                    help="declare two frame names one frame (an identity transform; repeatable)")
    rp.add_argument(
        "--rate",
        type=_args.real(0.0, lo_open=True, meaning="Hz"),
        help="resample to a uniform grid at this rate in Hz (default: run on the messages' own stamps)",
    )
    rp.add_argument("--override", action="store_true",
                    help="replay an edccif recording with a --scenario (or --motion) other than the stored one")
    rp.add_argument("--json", action="store_true", help="print the report as JSON")
    rp.add_argument("--out", type=_args.output_path,
                    help="write the estimates to this .npz file (.npz is appended when missing)")
    rp.add_argument("--force", action="store_true", help="replace --out if it exists")
    rp.add_argument("--threads", type=_threads, default=1, help=_THREADS_HELP)
    rp.set_defaults(func=cmd_replay)

    pp = sub.add_parser("preprocess", help="the real-world preprocessing pipeline on TUM files")
    pp.add_argument("--truth", required=True, type=_args.readable_file, help="ground truth (TUM), e.g. motion capture")
    pp.add_argument(
        "--observer", required=True, nargs="+", type=_args.readable_file, help="each observer's target track (TUM)"
    )
    pp.add_argument(
        "--rate",
        type=_args.real(0.0, lo_open=True, meaning="frame rate in Hz"),
        help="common frame rate in Hz (default: the observers' median)",
    )
    pp.add_argument("--scale", action="store_true", help="spatial alignment with scale")
    pp.add_argument("--no-spatial", action="store_true", help="observers are already in the truth's frame")
    pp.add_argument(
        "--align",
        choices=["none", "start", "estimate"],
        default="estimate",
        help="observers' clocks against the truth's: estimate each offset from the data (default), assume the "
        "recordings started together (start), or take the clocks as synchronised (none)",
    )
    pp.add_argument(
        "--offset",
        action="append",
        type=_args.stream_offset,
        metavar="STREAM=SECONDS",
        help="an observer's clock offset (t_truth = t_observer + SECONDS), by index or file stem; overrides "
        "--align for it (repeat per observer)",
    )
    pp.add_argument(
        "--offset-window",
        type=_args.real(0.0, meaning="seconds"),
        default=2.0,
        metavar="SECONDS",
        help="--align estimate searches this far either side of the start alignment (default 2)",
    )
    pp.add_argument(
        "--residual-factor",
        type=_args.real(0.0, lo_open=True, meaning="multiple of the noise"),
        default=3.0,
        help="warn when an observer's alignment residual exceeds this multiple of its noise (default 3)",
    )
    pp.add_argument(
        "--duplicates",
        choices=["drop", "refuse"],
        default="drop",
        help="repeated timestamps: dropped and counted (default), or the input refused before any work",
    )
    pp.add_argument("--quiet", action="store_true", help="no progress and no per-stream summary on stderr")
    pp.add_argument("--out", type=_args.output_path,
                    help="write the aligned arrays to this .npz file (.npz is appended when missing)")
    pp.add_argument("--force", action="store_true", help="replace --out if it exists")
    pp.set_defaults(func=cmd_preprocess)

    rel = sub.add_parser(
        "reliability",
        help="robustness under faults (and a soak run); writes a Markdown report",
    )
    rel.add_argument("--out", type=_args.output_path, default="reliability.md",
                     help="the Markdown report (default reliability.md); an existing one needs --force, "
                     "and then only its robustness/soak blocks are replaced")
    rel.add_argument("--force", action="store_true", help="update --out (and replace --json) if they exist")
    rel.add_argument("--runs", type=_args.count, default=50, help="Monte Carlo runs per row (default 50)")
    rel.add_argument("--seed", type=_args.seed, default=0, help="seed of run 0")
    rel.add_argument("--nodes", type=_args.count, nargs="+", default=[4, 8], help="node counts (default: 4 8)")
    rel.add_argument("--soak", type=_args.count, help="also run the soak test with this many steps (e.g. 1000000)")
    rel.add_argument("--no-robustness", action="store_true", help="skip the Monte Carlo study")
    rel.add_argument("--json", type=_args.output_path, help="also write the numbers to this JSON file")
    rel.add_argument("--quiet", action="store_true", help="no progress messages")
    rel.add_argument("--jobs", type=_jobs, help=_JOBS_HELP)
    rel.set_defaults(func=cmd_reliability)

    from .sweep import add_subcommand as add_sweep

    add_sweep(sub)

    from .agents.cli import add_subcommands as add_agents

    add_agents(sub)

    a = sub.add_parser("algorithms", help="list the algorithm rows")
    a.set_defaults(func=cmd_algorithms)
    return p


def _quiet_stdout() -> None:
    """After a broken pipe: stdout goes to /dev/null, so that flushing it again at
    exit raises nothing (the recipe of Python's `signal` documentation)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout without a file descriptor (tests)
        pass


BROKEN_PIPE_EXIT = 141
"""Exit code when stdout's reader went away (`edccif simulate | head -1`): 128 +
SIGPIPE, what a shell reports for a command a broken pipe ended."""


def main(argv: Optional[List[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        rc = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return rc
    except _edccif.EdccifError as e:
        print(f"edccif: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Ctrl-C: one line, the shell's code for SIGINT (128 + 2). What was
        # finished stays: a sweep's table holds its finished cells.
        print("edccif: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _quiet_stdout()
        return BROKEN_PIPE_EXIT


if __name__ == "__main__":
    sys.exit(main())
