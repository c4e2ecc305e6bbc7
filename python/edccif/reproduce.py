"""The main job: reproduce the paper's tables and figures on the built-in default
scenario (`edccif reproduce`)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _edccif, plots


def data_dir_candidates() -> List[Path]:
    """Where the real flights' ground truths are looked for, in order:
    `../shared/data` from the working directory (the README runs the main job from
    the repository root, and an installed package no longer knows where its source
    tree was), then `../shared/data` beside the source tree of this module (an
    editable install run from elsewhere; as for `edccif-results`)."""
    here = Path.cwd().resolve().parent / "shared" / "data"
    source = Path(__file__).resolve().parents[2].parent / "shared" / "data"
    return [here] if source == here else [here, source]


def default_data_dir() -> Path:
    """The first of `data_dir_candidates()` that is a directory, else the first
    candidate (which the notice then names)."""
    candidates = data_dir_candidates()
    return next((d for d in candidates if d.is_dir()), candidates[0])


def flight_data_dir(flights: bool = True, data_dir: Optional[Path] = None) -> Optional[Path]:
    """The directory the real-flight section reads, or None to leave it out:
    `data_dir` when given (it must be a directory: else `ParameterError`), else `default_data_dir()` when it
    exists; when it does not, a notice on stderr says that the section is skipped
    and how to point at the data."""
    if not flights:
        return None
    if data_dir is not None:
        d = Path(data_dir)
        if not d.is_dir():
            raise _edccif.ParameterError(
                f"data_dir: {d} is not a directory (expected the real flights' EuRoC "
                "V102_groundtruth.csv and TUM freiburg1_xyz-groundtruth.txt there)"
            )
        return d
    d = default_data_dir()
    if d.is_dir():
        return d
    print(
        f"real flights: no data directory at {d}; the real-flight section is skipped "
        "(pass --data-dir DIR with the EuRoC and TUM ground-truth files, or --no-flights)",
        file=sys.stderr,
        flush=True,
    )
    return None


OUTPUT_FILES = (
    "results.md",
    "results.json",
    "trajectory_3d.png",
    "trigger_instants.png",
    "rmse_over_time.png",
    "delta_sweep.png",
    "computation_time.png",
)
"""The files `reproduce` writes into `out` (`edccif reproduce` refuses to replace
them without `--force`)."""


def reproduce(
    nodes: Sequence[int] = (3, 4, 8),
    runs: int = 100,
    seed: int = 0,
    out: Optional[Path] = Path("results"),
    figures: bool = True,
    progress: bool = True,
    timing_reps: int = 11,
    flights: bool = True,
    data_dir: Optional[Path] = None,
    flight_files: Optional[Sequence[Path]] = None,
    duplicates: str = "drop",
) -> Dict[str, Any]:
    """Runs the Monte Carlo studies behind the paper's tables (Table II for each node
    count, Table I ablations, the δ and σ sweeps, the real-world-like experiment and,
    with `flights`, the real flights: those of `data_dir` (see `flight_data_dir`),
    then `flight_files`, any TUM or EuRoC ground-truth files; with `flight_files`
    and no `data_dir`, only those), compares them with the paper's published
    numbers, and (with `out`) writes `results.md`, `results.json` and the figures
    there. Every flight file is read and checked before the studies run (repeated
    stamps dropped and counted, or with `duplicates="refuse"` refused). Returns
    the data as a dict with the Markdown under "markdown"."""
    files = [str(f) for f in flight_files or []]
    if files and not flights:
        raise _edccif.ParameterError("flight_files: given with flights=False; leave out one or the other")
    fdir = flight_data_dir(flights, data_dir) if data_dir is not None or not files else None
    markdown, data_json = _edccif.reproduce(  # type: ignore[attr-defined]
        list(nodes),
        runs=runs,
        seed=seed,
        progress=progress,
        flight_data_dir=None if fdir is None else str(fdir),
        flight_files=files,
        duplicates=duplicates,
    )
    data: Dict[str, Any] = json.loads(data_json)
    data["markdown"] = markdown
    if out is None:
        return data
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    def save() -> None:
        (out / "results.md").write_text(data["markdown"])
        (out / "results.json").write_text(json.dumps({k: v for k, v in data.items() if k != "markdown"}))

    # the numbers first: the figures (matplotlib, the timing pass) come after
    save()
    written: List[Path] = []
    if figures:
        written += make_figures(data, list(nodes), out, progress=progress, timing_reps=timing_reps)
        rel = "\n".join(f"- `{p.name}`" for p in written)
        data["markdown"] += f"\n## Figures\n\nWritten to `{out}`:\n{rel}\n"
        if "timing_ms" in data:
            data["markdown"] += "\n" + timing_markdown(data["timing_ms"])
        save()
    return data


def timing_markdown(timing_ms: Dict[str, Dict[str, float]]) -> str:
    """A Markdown table of the Python-side timing (median ms per 200-step run)."""
    nodes = sorted(timing_ms, key=int)
    labels = list(next(iter(timing_ms.values())).keys())
    s = "## Computation time measured by this reproduction\n\n"
    s += "Median wall time of one whole run (ms), one core, same data for every row, "
    s += "repetitions interleaved; `cargo run --release -p edccif-bench --bin edccif-timing` "
    s += "is the careful measurement.\n\n"
    s += "| algorithm | " + " | ".join(f"N = {n}" for n in nodes) + " |\n"
    s += "|---|" + "---|" * len(nodes) + "\n"
    for lab in labels:
        s += f"| {lab} | " + " | ".join(f"{timing_ms[n][lab]:.3f}" for n in nodes) + " |\n"
    return s


def make_figures(
    data: Dict[str, Any], nodes: List[int], out: Path, progress: bool = True, timing_reps: int = 11
) -> List[Path]:
    """The five figures of the reproduction."""
    n_main = 4 if 4 in nodes else nodes[0]
    sc = _edccif.Scenario.paper(nodes=n_main)
    truth, z, x0 = sc.simulate(seed=data["settings"]["seed"])
    res = _edccif.run("edc-cif", sc, z, x0=x0)
    seed = data["settings"]["seed"]
    runs = data["settings"].get("runs")
    one_run = f"paper scenario, {n_main} nodes, ring; one run (seed {seed})"
    paths = [
        plots.trajectory_3d(truth, res.estimates[:, 0, :], sc.sensors, out / "trajectory_3d.png", context=one_run),
        plots.trigger_instants(res.triggered, sc.dt, out / "trigger_instants.png", context=one_run),
    ]
    table2 = {t["nodes"]: t for t in data["table2"]}
    mc = table2.get(n_main)
    if mc is not None:
        pos = {v["label"]: np.asarray(v["errors"]["pos_rmse_curve"]) for v in mc["variants"]}
        vel = {v["label"]: np.asarray(v["errors"]["vel_rmse_curve"]) for v in mc["variants"]}
        ctx = f"paper scenario, {n_main} nodes, ring; {mc.get('runs', runs)} runs (seed {seed})"
        paths.append(plots.rmse_over_time(pos, vel, sc.dt, out / "rmse_over_time.png", context=ctx))
    sweep = data["delta_sweep"]
    if sweep:
        deltas = [p["delta"] for p in sweep]
        labels = [v["label"] for v in sweep[0]["mc"]["variants"]]
        pos_by = {lab: [p["mc"]["variants"][i]["errors"]["pos_rmse"] for p in sweep] for i, lab in enumerate(labels)}
        rate_by = {lab: [p["mc"]["variants"][i]["trigger_rate"] for p in sweep] for i, lab in enumerate(labels)}
        sweep_nodes = sweep[0]["mc"].get("nodes", n_main)
        ctx = f"paper scenario, {sweep_nodes} nodes, {sweep[0]['mc'].get('runs', runs)} runs per δ"
        paths.append(plots.delta_sweep(deltas, pos_by, rate_by, out / "delta_sweep.png", context=ctx))
    scs = {n: _edccif.Scenario.paper(nodes=n) for n in nodes}
    labels_by_name = dict(zip(_edccif.algorithms(), [
        "C-CKF", "EC-EKF", "EC-UKF", "EC-CKF", "DEC-CKF", "D-CIF", "DC-CIF", "ED-CIF", "EDC-CIF"]))
    times = plots.time_rows(scs, _edccif.algorithms(), reps=timing_reps, progress=progress)
    times_lab = {n: {labels_by_name[a]: t for a, t in row.items()} for n, row in times.items()}
    data["timing_ms"] = {str(n): row for n, row in times_lab.items()}
    ctx = f"paper scenarios; median of {timing_reps} repetitions per row and node count"
    paths.append(plots.computation_time(times_lab, out / "computation_time.png", context=ctx))
    return paths


def print_progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


SCENARIO_OUTPUT_FILES = ("results.md", "results.json", "rmse_over_time.png", "delta_sweep.png")
"""The files `reproduce(scenario=...)` writes into `out`."""

DELTA_FACTORS = (0.25, 0.5, 1.0, 2.0, 4.0)
"""The δ sweep of a scenario file: its own thresholds (every node's) times these."""

SIGMAS = (5e-4, 5e-3, 5e-2, 0.1)
"""The σ sweep's values (each applied to σ1 with σ2 = 5e-4, then to σ2 with σ1 = 5e-4), as the paper's."""

ABLATIONS = (
    {"label": "EDC-CIF", "algorithm": "edc-cif"},
    {"label": "w/o optimal ET filter (hold)", "algorithm": "edc-cif", "et_policy": "hold"},
    {"label": "w/o diffusion with CI (consensus)", "algorithm": "edc-cif", "fusion": "consensus"},
    {"label": "DEC-CKF", "algorithm": "dec-ckf"},
)
"""Table I's variants (the method, its two ablations, DEC-CKF), as `edccif_sim::report::ablation_variants`."""

NOT_RUN = {
    "realworld": "the real-world-like experiment (Table IV) runs its own pipeline (a 3-D trajectory generator, "
    "position sensors, preprocessing), not a scenario file; run `edccif reproduce` without --scenario for it",
    "flights": "the real flights replay recorded ground truths through the paper's position pipeline, not a "
    "scenario file; run `edccif reproduce` without --scenario for them",
    "paper": "the paper publishes numbers for its own scenario only; this file's numbers are not compared "
    "with them",
}
"""The sections of the paper's reproduction that `reproduce(scenario=...)` leaves out, and why."""


def _scaled_delta(delta: Any, factor: float) -> Any:
    if isinstance(delta, (list, tuple)):
        return [float(d) * factor for d in delta]
    return float(delta) * factor


def _mc_rows(sc: _edccif.Scenario, variants: Sequence[Any], runs: int, seed: int, progress: bool
             ) -> Tuple[Optional[Dict[str, Any]], Dict[str, str]]:
    """One Monte Carlo study of ``variants`` on ``sc``, each variant on its own
    (a row the scenario cannot run is refused alone, its error kept): the
    study's dict with the variants that ran, and the refused rows' errors."""
    done: Optional[Dict[str, Any]] = None
    refused: Dict[str, str] = {}
    for v in variants:
        label = v if isinstance(v, str) else v["label"]
        try:
            r = _edccif.monte_carlo(sc, [v], runs=runs, seed=seed, progress=progress).to_dict()
        except _edccif.EdccifError as e:
            refused[label] = f"{type(e).__name__}: {e}"
            continue
        if done is None:
            done = r
        else:
            done["variants"] += r["variants"]
    return done, refused


def reproduce_scenario(
    scenario: _edccif.Scenario,
    runs: int = 100,
    seed: int = 0,
    out: Optional[Path] = Path("results"),
    figures: bool = True,
    progress: bool = True,
    deltas: Sequence[float] = DELTA_FACTORS,
    sigmas: Sequence[float] = SIGMAS,
) -> Dict[str, Any]:
    """The studies of the paper's tables on a scenario of one's own (any
    catalogue or referenced Python model, mixed sensors, per-node rates and
    thresholds; `edccif reproduce --scenario FILE`): Table II (every row),
    Table I (the ablations), the δ sweep (the scenario's thresholds times
    `deltas`: EDC-CIF, ED-CIF, EC-CKF) and the σ sweep (EDC-CIF), each a seeded
    Monte Carlo study (`monte_carlo(scenario, ..., runs, seed)`, run r simulated
    with seed + r: the numbers of `Scenario.run`/`ModelNetwork` on those runs).
    A row the scenario cannot run is refused alone, and the report names it and
    the error; the sections that are not about a scenario file (the
    real-world-like experiment, the real flights, the paper's numbers) are
    listed as not run with the reason (`NOT_RUN`). With `out`, writes
    `results.md`, `results.json` and (with `figures`) `rmse_over_time.png` and
    `delta_sweep.png` there. Returns the data with the Markdown under
    "markdown"."""
    sc = scenario
    d = sc.to_dict()
    name, k = d["name"], sc.nodes
    data: Dict[str, Any] = {
        "settings": {"scenario": name, "nodes": k, "runs": runs, "seed": seed,
                     "delta_factors": list(deltas), "sigmas": list(sigmas)},
        "not_run": dict(NOT_RUN),
        "refused": {},
    }
    table2, refused = _mc_rows(sc, list(_edccif.algorithms()), runs, seed, progress)
    data["table2"], data["refused"]["table2"] = table2, refused
    table1, refused = _mc_rows(sc, list(ABLATIONS), runs, seed, progress)
    data["table1"], data["refused"]["table1"] = table1, refused
    swept = ["edc-cif", "ed-cif", "ec-ckf"]
    data["delta_sweep"] = []
    for f in deltas:
        delta = _scaled_delta(d["delta"], f)
        mc, refused = _mc_rows(sc.replace(delta=delta), swept, runs, seed, progress)
        data["delta_sweep"].append({"factor": f, "delta": delta, "mc": mc, "refused": refused})
    data["sigma_sweep"] = []
    pairs: List[Tuple[float, float]] = []
    for v in sigmas:
        for p in ((v, 5e-4), (5e-4, v)):
            if p not in pairs:
                pairs.append(p)
    for s1, s2 in pairs:
        mc, refused = _mc_rows(sc.replace(sigma1=s1, sigma2=s2), ["edc-cif"], runs, seed, progress)
        data["sigma_sweep"].append({"sigma1": s1, "sigma2": s2, "mc": mc, "refused": refused})
    data["markdown"] = scenario_markdown(data, d)
    if out is None:
        return data
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    def save() -> None:
        (out / "results.md").write_text(data["markdown"])
        (out / "results.json").write_text(json.dumps({k_: v for k_, v in data.items() if k_ != "markdown"}))

    save()
    if figures:
        written: List[Path] = []
        ctx = f"scenario {name}, {k} nodes; {runs} runs (seed {seed})"
        if table2 is not None:
            pos = {v["label"]: np.asarray(v["errors"]["pos_rmse_curve"]) for v in table2["variants"]}
            vel = {v["label"]: np.asarray(v["errors"]["vel_rmse_curve"]) for v in table2["variants"]}
            written.append(plots.rmse_over_time(pos, vel, sc.dt, out / "rmse_over_time.png", context=ctx))
        sweep = [p for p in data["delta_sweep"] if p["mc"] is not None]
        if sweep:
            labels = [v["label"] for v in sweep[0]["mc"]["variants"]]
            pos_by = {lab: [p["mc"]["variants"][i]["errors"]["pos_rmse"] for p in sweep]
                      for i, lab in enumerate(labels)}
            rate_by = {lab: [p["mc"]["variants"][i]["trigger_rate"] for p in sweep] for i, lab in enumerate(labels)}
            unit = "× the file's thresholds; " + ("σ units" if d.get("normalised") else "raw squared units")
            written.append(plots.delta_sweep([p["factor"] for p in sweep], pos_by, rate_by,
                                             out / "delta_sweep.png", context=ctx, unit=unit))
        rel = "\n".join(f"- `{p.name}`" for p in written)
        data["markdown"] += f"\n## Figures\n\nWritten to `{out}`:\n{rel}\n"
        save()
    return data


def _row_table(mc: Dict[str, Any]) -> str:
    s = "| row | position RMSE (m) | velocity RMSE | trigger rate | NEES |\n|---|---|---|---|---|\n"
    for v in mc["variants"]:
        e = v["errors"]
        nees = e.get("nees")
        s += (f"| {v['label']} | {e['pos_rmse']:.4f} | {e['vel_rmse']:.4f} | {100 * v['trigger_rate']:.1f} % | "
              f"{'–' if nees is None else f'{nees:.2f}'} |\n")
    return s


def _refused_lines(refused: Dict[str, str]) -> str:
    return "".join(f"- {lab}: refused — {msg}\n" for lab, msg in refused.items())


def scenario_markdown(data: Dict[str, Any], d: Dict[str, Any]) -> str:
    """The report of `reproduce_scenario`."""
    s = data["settings"]
    md = f"# Results on scenario `{s['scenario']}`\n\n"
    md += (f"{s['nodes']} nodes, {s['runs']} Monte Carlo runs (run r simulated with seed {s['seed']} + r); "
           f"motion `{d['motion']['kind']}`; thresholds `delta = {d['delta']}`"
           f"{' (normalised: σ units)' if d.get('normalised') else ''}. Velocity RMSE in the state's velocity "
           "units (m/s for the catalogue's motions).\n\n")
    md += "## Table II: every row\n\n"
    if data["table2"] is not None:
        md += _row_table(data["table2"])
    md += _refused_lines(data["refused"]["table2"])
    md += "\n## Table I: ablations\n\n"
    if data["table1"] is not None:
        md += _row_table(data["table1"])
    md += _refused_lines(data["refused"]["table1"])
    md += "\n## δ sweep (the scenario's thresholds × factor)\n\n"
    for p in data["delta_sweep"]:
        md += f"### δ × {p['factor']:g} (`delta = {p['delta']}`)\n\n"
        if p["mc"] is not None:
            md += _row_table(p["mc"])
        md += _refused_lines(p["refused"]) + "\n"
    md += "## σ sweep (EDC-CIF)\n\n| σ1 | σ2 | position RMSE (m) |\n|---|---|---|\n"
    for p in data["sigma_sweep"]:
        val = "refused" if p["mc"] is None else f"{p['mc']['variants'][0]['errors']['pos_rmse']:.4f}"
        md += f"| {p['sigma1']:g} | {p['sigma2']:g} | {val} |\n"
    md += "\n## Not run on a scenario file\n\n"
    md += "".join(f"- {key}: {why}\n" for key, why in data["not_run"].items())
    return md
