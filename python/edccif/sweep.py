"""Parameter-grid sweeps on Dask: ``edccif sweep``.

A sweep is the product algorithm × trigger × threshold × fusion rule × nodes ×
topology × message loss × seed. Each point of the grid is a *cell*: one seeded Monte Carlo
study (:func:`edccif.monte_carlo` with ``runs`` runs, run r simulated with seed
``seed + r``) whose summary becomes one row of a tidy table (CSV).

Cells are independent and deterministic (the Monte Carlo is deterministic for any
thread count), so they run anywhere: on a Dask cluster — a local one by default,
or an existing one given by its scheduler address — or in this process. The same
cells give the same numbers, bit for bit, on every executor.

Every finished cell is appended to the table at once; a sweep started again with
the same output file skips the cells already there (matched by ``cell_id``, a hash
of everything the cell's numbers depend on), so an interrupted sweep resumes
without recomputing them. At the end the table is rewritten in grid order.

>>> from edccif.sweep import Grid, run_sweep
>>> grid = Grid(algorithms=["edc-cif", "dc-cif"], thresholds=[0.02, 0.04], runs=2, steps=20)
>>> len(grid.cells())  # dc-cif sends everything: no threshold to sweep
3
>>> rows = run_sweep(grid, scheduler="inprocess", progress=False)
>>> [(r["algorithm"], r["threshold"], r["trigger_rate"] < 1.0) for r in rows]
[('edc-cif', 0.02, True), ('edc-cif', 0.04, True), ('dc-cif', None, False)]
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from . import _edccif
from ._edccif import ParameterError

#: Rows that send every measurement: a threshold or trigger does not apply to them
#: unless a trigger is chosen explicitly.
SEND_ALL = frozenset({"c-ckf", "d-cif", "dc-cif"})

#: Columns of the table, in order. ``floats_*`` are floats sent per time step by the
#: whole network (mean over runs): ``s2e`` sensor → estimator, ``e2s`` estimator →
#: sensor (what a trigger that needs the node's prediction costs), ``e2e``
#: estimator ↔ estimator, ``total`` their sum. ``nees_lo``/``nees_hi``: the 95 %
#: band of the NEES averaged over ``runs`` runs (χ² with ``n·runs`` degrees of
#: freedom divided by ``runs``). ``wall_s`` is the only column that is not
#: reproducible.
COLUMNS: Tuple[str, ...] = (
    "cell_id",
    "scenario",
    "algorithm",
    "trigger",
    "threshold",
    "fusion",
    "nodes",
    "topology",
    "loss",
    "seed",
    "runs",
    "steps",
    "state_dim",
    "pos_rmse",
    "vel_rmse",
    "nees",
    "nees_lo",
    "nees_hi",
    "nees_in_band",
    "trigger_rate",
    "floats_s2e",
    "floats_e2s",
    "floats_e2e",
    "floats_total",
    "guard_fallbacks",
    "non_finite_runs",
    "wall_s",
)

_INT = {"nodes", "seed", "runs", "steps", "state_dim", "guard_fallbacks", "non_finite_runs"}
_FLOAT = {
    "threshold",
    "loss",
    "pos_rmse",
    "vel_rmse",
    "nees",
    "nees_lo",
    "nees_hi",
    "trigger_rate",
    "floats_s2e",
    "floats_e2s",
    "floats_e2e",
    "floats_total",
    "wall_s",
}
_BOOL = {"nees_in_band"}

Thresholds = Union[Sequence[float], Mapping[str, Sequence[float]]]


def chi2_band(dof: int, runs: int, level: float = 0.95) -> Tuple[float, float]:
    """Two-sided ``level`` band of a NEES averaged over ``runs`` runs with ``dof``
    degrees of freedom in total (state dimension × runs), by the Wilson–Hilferty
    approximation of the χ² quantiles (relative error below 10⁻³ for dof ≥ 50).

    >>> lo, hi = chi2_band(7 * 100, 100)
    >>> round(lo, 2), round(hi, 2)
    (6.29, 7.75)
    """
    if dof < 1 or runs < 1:
        raise ParameterError(f"chi2_band: expected dof >= 1 and runs >= 1, got dof={dof}, runs={runs}")
    z = _normal_quantile(0.5 + level / 2.0)
    a = 2.0 / (9.0 * dof)

    def q(zz: float) -> float:
        return dof * max(1.0 - a + zz * math.sqrt(a), 0.0) ** 3 / runs

    return q(-z), q(z)


def _normal_quantile(p: float) -> float:
    """Standard normal quantile by bisection on ``erf`` (enough for a band)."""
    lo, hi = -10.0, 10.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 0.5 * (1.0 + math.erf(mid / math.sqrt(2.0))) < p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class Cell:
    """One point of the grid; :meth:`run` computes its row."""

    algorithm: str
    trigger: Optional[str]
    threshold: Optional[float]
    nodes: int
    topology: str
    loss: float
    seed: int
    runs: int
    steps: Optional[int]
    scenario_toml: str = field(repr=False)
    fusion: Optional[str] = None
    #: the directory the scenario's ``python_path`` is relative to (its file's);
    #: where the file lies, not what the cell computes: not in ``cell_id``
    scenario_dir: Optional[str] = field(default=None, repr=False)

    @property
    def cell_id(self) -> str:
        """Hash of everything the cell's numbers depend on (and the package version)."""
        d = asdict(self)
        if d["fusion"] is None:
            del d["fusion"]  # the ids of cells without a fusion axis are as before it
        del d["scenario_dir"]
        d["version"] = _edccif.__version__
        text = json.dumps(d, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def scenario(self) -> _edccif.Scenario:
        """The cell's scenario (node count, topology and steps applied)."""
        return _edccif.Scenario.from_toml_str(self.scenario_toml, base_dir=self.scenario_dir)

    def run(self) -> Dict[str, Any]:
        """Runs the cell's Monte Carlo study and returns its table row."""
        t0 = time.perf_counter()
        sc = self.scenario()
        variant: Dict[str, Any] = {"algorithm": self.algorithm}
        if self.trigger is not None:
            variant["trigger"] = self.trigger
        if self.threshold is not None:
            variant["delta"] = self.threshold
        if self.fusion is not None:
            variant["fusion"] = self.fusion
        kwargs: Dict[str, Any] = {}
        if self.loss > 0.0:
            # run r: simulated with seed + r, its lost messages drawn with fault seed seed + r
            kwargs["faults"] = {"message_loss": self.loss, "seed": self.seed}
        mc = _edccif.monte_carlo(sc, [variant], runs=self.runs, seed=self.seed, progress=False, **kwargs)
        v = mc.to_dict()["variants"][0]
        err = v["errors"]
        steps = mc.steps
        s2e = v["values_sensor_to_estimator"] / steps
        e2s = v.get("values_estimator_to_sensor", 0.0) / steps
        e2e = v["values_estimator_to_estimator"] / steps
        nees = err["nees"]
        lo, hi = chi2_band(sc.state_dim * self.runs, self.runs)
        return {
            "cell_id": self.cell_id,
            "scenario": sc.name,
            "algorithm": self.algorithm,
            "trigger": self.trigger,
            "threshold": self.threshold,
            "fusion": self.fusion,
            "nodes": sc.nodes,
            "topology": self.topology,
            "loss": self.loss,
            "seed": self.seed,
            "runs": self.runs,
            "steps": steps,
            "state_dim": sc.state_dim,
            "pos_rmse": err["pos_rmse"],
            "vel_rmse": err["vel_rmse"],
            "nees": nees,
            "nees_lo": lo,
            "nees_hi": hi,
            "nees_in_band": None if nees is None else bool(lo <= nees <= hi),
            "trigger_rate": v["trigger_rate"],
            "floats_s2e": s2e,
            "floats_e2s": e2s,
            "floats_e2e": e2e,
            "floats_total": s2e + e2s + e2e,
            "guard_fallbacks": v["guard_fallbacks"],
            "non_finite_runs": err.get("non_finite_runs", 0),
            "wall_s": time.perf_counter() - t0,
        }


def _topology(name: str) -> Dict[str, Any]:
    """``ring``, ``line``, ``star``, ``complete`` or ``random-geometric:RADIUS:SEED``."""
    parts = name.split(":")
    if parts[0] in ("ring", "line", "star", "complete") and len(parts) == 1:
        return {"kind": parts[0]}
    if parts[0] == "random-geometric" and len(parts) == 3:
        try:
            return {"kind": "random-geometric", "radius": float(parts[1]), "seed": int(parts[2])}
        except ValueError:
            pass
    raise ParameterError(
        f"topology: expected ring, line, star, complete or random-geometric:RADIUS:SEED, got {name!r}"
    )


@dataclass
class Grid:
    """The sweep's grid.

    ``triggers``: trigger names (``edccif.TRIGGERS``) or ``None`` for the row's own
    trigger. ``thresholds``: one list for every trigger, or a dict from trigger
    name (``"row"`` for ``None``, ``"*"`` for the others) to its list; an empty
    list or a missing entry means the default threshold. Rows in :data:`SEND_ALL` run once per other
    coordinate when no trigger is chosen (the threshold does not apply).
    ``scenario``: a TOML file or a :class:`edccif.Scenario` to use instead of
    ``Scenario.paper(nodes)`` (then ``nodes`` must be its node count or empty).
    ``steps``: shorten runs (``None``: the scenario's). ``fusions``: fusion
    names for ``fusion=`` (a rule of ``edccif.FUSION_RULES``, or a structural
    fusion such as ``consensus``), ``None`` for the row's own.
    """

    algorithms: Sequence[str] = ("edc-cif",)
    triggers: Sequence[Optional[str]] = (None,)
    thresholds: Thresholds = ()
    nodes: Sequence[int] = (4,)
    topologies: Sequence[str] = ("ring",)
    losses: Sequence[float] = (0.0,)
    seeds: Sequence[int] = (0,)
    runs: int = 100
    steps: Optional[int] = None
    scenario: Union[None, str, os.PathLike, _edccif.Scenario] = None
    fusions: Sequence[Optional[str]] = (None,)

    def _thresholds_for(self, trigger: Optional[str]) -> List[Optional[float]]:
        if isinstance(self.thresholds, Mapping):
            vals = self.thresholds.get(trigger if trigger is not None else "row", self.thresholds.get("*", ()))
        else:
            vals = self.thresholds
        out: List[Optional[float]] = [float(v) for v in vals]
        return out or [None]

    def _base(self, nodes: int) -> _edccif.Scenario:
        if self.scenario is None:
            return _edccif.Scenario.paper(nodes=nodes)
        sc = self.scenario if isinstance(self.scenario, _edccif.Scenario) else _edccif.Scenario.from_toml(self.scenario)
        if sc.nodes != nodes:
            raise ParameterError(f"nodes: the scenario {sc.name!r} has {sc.nodes} nodes, the grid asks for {nodes}")
        return sc

    def _node_counts(self) -> List[int]:
        if self.scenario is not None and not self.nodes:
            return [self._base_any().nodes]
        return [int(n) for n in self.nodes]

    def _base_any(self) -> _edccif.Scenario:
        s = self.scenario
        return s if isinstance(s, _edccif.Scenario) else _edccif.Scenario.from_toml(s)  # type: ignore[arg-type]

    def validate(self) -> None:
        """Checks names and ranges before anything runs."""
        if self.runs < 1:
            raise ParameterError(f"runs: expected >= 1, got {self.runs}")
        if self.steps is not None and self.steps < 1:
            raise ParameterError(f"steps: expected >= 1 or None, got {self.steps}")
        for sd in self.seeds:
            if not 0 <= int(sd) <= 2**64 - 1:
                raise ParameterError(f"seeds: expected integers in 0..=2**64-1, got {sd}")
        for n in self.nodes:
            if int(n) < 1:
                raise ParameterError(f"nodes: expected node counts >= 1, got {n}")
        # names in any spelling the library accepts (`EDC-CIF`), kept as it spells them
        names = []
        for a in self.algorithms:
            try:
                names.append(_edccif.algorithm_name(a))
            except _edccif.UnknownAlgorithmError:
                raise _edccif.UnknownAlgorithmError(
                    f"algorithms: unknown algorithm {a!r}, expected one of {', '.join(_edccif.algorithms())}"
                ) from None
        self.algorithms = names
        known = _trigger_names()
        spelled: Dict[str, str] = {}
        for t in self.triggers:
            if t is None:
                continue
            try:
                spelled[t] = _edccif.trigger_name(t)
            except _edccif.UnknownOptionError:
                spelled[t] = t
            if spelled[t] not in known:
                raise _edccif.UnknownOptionError(
                    f"triggers: unknown trigger {t!r}, expected one of {', '.join(known) or '(none in this build)'}"
                )
        self.triggers = [None if t is None else spelled[t] for t in self.triggers]
        if isinstance(self.thresholds, Mapping):
            self.thresholds = {spelled.get(k, k): v for k, v in self.thresholds.items()}
        if isinstance(self.thresholds, Mapping):
            for k in self.thresholds:
                if k not in ("row", "*") and k not in self.triggers:
                    raise ParameterError(f"thresholds: {k!r} is not one of the grid's triggers {list(self.triggers)}")
        fusions = _fusion_names()
        for f in self.fusions:
            if f is not None and f not in fusions:
                raise _edccif.UnknownOptionError(
                    f"fusions: unknown fusion {f!r}, expected one of {', '.join(fusions)}"
                )
        for p in self.losses:
            if not 0.0 <= float(p) <= 1.0:
                raise ParameterError(f"losses: expected probabilities in [0, 1], got {p}")
        for t in self.topologies:
            _topology(t)

    def cells(self) -> List[Cell]:
        """Every cell, in grid order (nodes, topology, loss, algorithm, trigger,
        threshold, fusion, seed)."""
        self.validate()
        out: List[Cell] = []
        for n in self._node_counts():
            base = self._base(n)
            for topo in self.topologies:
                over: Dict[str, Any] = {"topology": _topology(topo)}
                if self.steps is not None:
                    over["steps"] = int(self.steps)
                toml = base.replace(**over).to_toml()
                where = None if base.base_dir is None else os.path.abspath(base.base_dir)
                for loss in self.losses:
                    for alg in self.algorithms:
                        for trig in self.triggers:
                            if alg in SEND_ALL and trig is None:
                                ths: List[Optional[float]] = [None]
                            else:
                                ths = self._thresholds_for(trig)
                            for th in ths:
                                for fus in self.fusions:
                                    for seed in self.seeds:
                                        out.append(
                                            Cell(alg, trig, th, n, topo, float(loss), int(seed), int(self.runs),
                                                 self.steps, toml, fus, where)
                                        )
        # a grid may list the same cell twice (e.g. SEND_ALL rows × triggers): keep the first
        seen = set()
        unique = []
        for c in out:
            if c.cell_id not in seen:
                seen.add(c.cell_id)
                unique.append(c)
        return unique


def _fusion_names() -> Tuple[str, ...]:
    rules = getattr(_edccif, "fusion_rules", None)
    structural = ("diffusion-ci", "diffusion-convex", "consensus", "local")
    return structural + (tuple(rules()) if rules is not None else ())


def _fusion_arg(text: str) -> str:
    """An argparse type: a fusion name of ``--fusion`` (or ``row``)."""
    names = ("row",) + _fusion_names()
    if text not in names:
        raise argparse.ArgumentTypeError(f"expected one of {', '.join(names)}, got {text!r}")
    return text


def _trigger_names() -> Tuple[str, ...]:
    names = getattr(_edccif, "triggers", None)
    return tuple(names()) if names is not None else ()


def _run_cell(cell: Cell) -> Dict[str, Any]:
    return cell.run()


# ---------------------------------------------------------------------------
# The table


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)  # shortest text that reads back to the same double
    return str(v)


def _parse(col: str, s: str) -> Any:
    if s == "":
        return None
    if col in _INT:
        return int(s)
    if col in _FLOAT:
        return float(s)
    if col in _BOOL:
        if s not in ("true", "false"):
            raise ValueError(s)
        return s == "true"
    return s


def read_table(path: Union[str, os.PathLike]) -> List[Dict[str, Any]]:
    """Reads a sweep table; rows that do not parse (an interrupted write) are left
    out, so their cells run again.

    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> write_table(p, [{"cell_id": "a", "pos_rmse": 0.1, "nees_in_band": True}])
    >>> read_table(p)[0]["pos_rmse"], read_table(p)[0]["trigger"]
    (0.1, None)
    """
    rows: List[Dict[str, Any]] = []
    with open(path, newline="") as f:
        r = csv.reader(f)
        header = next(r, None)
        if header is None:
            return rows
        for rec in r:
            if len(rec) != len(header):
                continue
            try:
                rows.append({h: _parse(h, s) for h, s in zip(header, rec)})
            except ValueError:
                continue
    return rows


def is_sweep_table(path: Union[str, os.PathLike]) -> bool:
    """Whether ``path`` is empty or a CSV whose header is a sweep table's: ``cell_id``
    first, every column one of :data:`COLUMNS` (what :func:`run_sweep` resumes).

    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> write_table(d / "t.csv", [])
    >>> _ = (d / "notes.txt").write_text("my notes")
    >>> is_sweep_table(d / "t.csv"), is_sweep_table(d / "notes.txt")
    (True, False)
    """
    try:
        with open(path, newline="") as f:
            first = f.readline(1 << 16)
    except UnicodeDecodeError:
        return False
    if not first.strip():
        return Path(path).stat().st_size == 0
    header = next(csv.reader([first]), [])
    return bool(header) and header[0] == "cell_id" and set(header) <= set(COLUMNS)


def write_table(path: Union[str, os.PathLike], rows: Iterable[Mapping[str, Any]]) -> None:
    """Writes rows as CSV with :data:`COLUMNS` (atomically: a temporary file, then
    a rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for row in rows:
            w.writerow([_fmt(row.get(c)) for c in COLUMNS])
    os.replace(tmp, path)


def _append(path: Path, row: Mapping[str, Any]) -> None:
    new = not path.exists() or path.stat().st_size == 0
    with open(path, "a", newline="") as f:
        w = csv.writer(f)
        if new:
            w.writerow(COLUMNS)
        w.writerow([_fmt(row.get(c)) for c in COLUMNS])
        f.flush()
        os.fsync(f.fileno())


# ---------------------------------------------------------------------------
# Executors


class _InProcess:
    """Runs cells one after the other in this process."""

    def map_unordered(self, cells: Sequence[Cell], timeout: Optional[float]) -> Iterable[Dict[str, Any]]:
        for c in cells:
            yield _run_cell(c)

    def close(self) -> None:
        pass


class _Dask:
    """Runs cells on a Dask cluster: an existing one (``address``) or a local one
    with ``workers`` single-threaded worker processes on the loopback interface."""

    def __init__(self, address: Optional[str], workers: Optional[int]) -> None:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ParameterError(
                "scheduler: Dask is not installed; install the extra with "
                "`pip install 'edccif[sweep]'` or run with scheduler='inprocess' (--in-process)"
            ) from e
        self.cluster = None
        if workers is not None and not 1 <= workers <= 4 * (os.cpu_count() or 1):
            raise ParameterError(
                f"workers: expected 1..={4 * (os.cpu_count() or 1)} (4 x the cores), got {workers}"
            )
        if address is None:
            n = workers or os.cpu_count() or 1
            # One cell per worker and one thread per cell: the Monte Carlo inside a
            # cell would otherwise start one thread per core in every worker.
            self.cluster = LocalCluster(  # binds the scheduler and the workers to loopback only
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                env={"RAYON_NUM_THREADS": "1"},
            )
            self.client = Client(self.cluster)
        else:
            try:
                self.client = Client(address, timeout="20s")
            except (OSError, TimeoutError) as e:
                raise ParameterError(
                    f"scheduler: no Dask scheduler answered at {address} within 20 s ({e})"
                ) from None

    def map_unordered(self, cells: Sequence[Cell], timeout: Optional[float]) -> Iterable[Dict[str, Any]]:
        from dask.distributed import as_completed

        futures = [self.client.submit(_run_cell, c, key=f"edccif-cell-{c.cell_id}", pure=False) for c in cells]
        try:
            for fut in as_completed(futures, timeout=timeout):
                yield fut.result()
        finally:
            self.client.cancel(futures)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def run_sweep(
    grid: Grid,
    out: Union[None, str, os.PathLike] = None,
    *,
    scheduler: Optional[str] = None,
    workers: Optional[int] = None,
    progress: bool = True,
    timeout: Optional[float] = None,
) -> List[Dict[str, Any]]:
    """Runs every cell of ``grid`` not already in ``out`` and returns the rows of
    the grid in grid order.

    ``scheduler``: ``None`` starts a local Dask cluster (``workers`` processes,
    default one per core) and stops it afterwards; an address
    (``"tcp://host:8786"``) uses that cluster; ``"inprocess"`` runs here without
    Dask. ``out``: the CSV table, appended to as cells finish and rewritten in
    grid order at the end (rows of other cells already in it are kept after the
    grid's). A file ``out`` that is not a sweep table (:func:`is_sweep_table`) is
    refused (``ParameterError``), never overwritten. ``progress``: a progress bar
    on stderr (a terminal), else a line at most every 5 s. ``timeout``: seconds
    to wait for the Dask cells (``TimeoutError`` after; the finished ones are in
    ``out``).
    Interrupted (Ctrl-C, ``KeyboardInterrupt``), the cells finished so far are in
    ``out`` too and a rerun resumes after them. ``workers``: an integer in
    ``1..=4 × cores`` (``ParameterError`` otherwise).
    """
    if workers is not None:
        limit = 4 * (os.cpu_count() or 1)
        if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= limit:
            raise ParameterError(f"workers: expected an integer in 1..={limit} (4 per core), got {workers!r}")
    cells = grid.cells()
    path = Path(out) if out is not None else None
    done: Dict[str, Dict[str, Any]] = {}
    if path is not None and path.is_dir():
        raise ParameterError(f"out: {path} is a directory; expected a CSV file")
    if path is not None and path.exists() and not is_sweep_table(path):
        raise ParameterError(
            f"out: {path} exists and is not a sweep table (its first line is not a sweep header); "
            "choose another file"
        )
    if path is not None and path.exists():
        for row in read_table(path):
            done[row["cell_id"]] = row
        # drop a half-written last line before appending to the file
        write_table(path, done.values())
    todo = [c for c in cells if c.cell_id not in done]
    if todo:
        if scheduler == "inprocess":
            ex: Union[_InProcess, _Dask] = _InProcess()
        else:
            ex = _Dask(scheduler, workers)
        try:
            bar = _bar(len(cells), len(cells) - len(todo), progress)
            for row in ex.map_unordered(todo, timeout):
                done[row["cell_id"]] = row
                if path is not None:
                    _append(path, row)
                bar.update(1)
            bar.close()
        finally:
            ex.close()
    ordered = [done[c.cell_id] for c in cells]
    if path is not None:
        ids = {c.cell_id for c in cells}
        write_table(path, ordered + [r for k, r in done.items() if k not in ids])
    return ordered


class _Lines:
    """A progress bar's interface printing lines (stderr is not a terminal)."""

    def __init__(self, total: int, initial: int, enabled: bool) -> None:
        from ._args import Progress

        self.p = Progress("sweep", total, "cells", enabled=enabled, done=initial)

    def update(self, n: int) -> None:
        self.p.update(self.p.done + n)

    def close(self) -> None:
        self.p.finish()


def _bar(total: int, initial: int, enabled: bool) -> Any:
    if enabled and not sys.stderr.isatty():
        return _Lines(total, initial, enabled)
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        disable=not enabled,
        unit="cell",
        desc="sweep",
        file=sys.stderr,
        dynamic_ncols=True,
    )


# ---------------------------------------------------------------------------
# Aggregation and the front figure


def _label(row: Mapping[str, Any]) -> str:
    t, f = row["trigger"], row.get("fusion")
    label = row["algorithm"] if t is None else f"{row['algorithm']} / {t}"
    return label if f is None else f"{label} / {f}"


def aggregate(rows: Iterable[Mapping[str, Any]]) -> List[Dict[str, Any]]:
    """Pools the seeds of each configuration: metrics averaged with the runs as
    weights (RMSE and NEES are themselves run averages), the NEES band recomputed
    for the pooled runs.

    >>> rows = [dict(algorithm="a", trigger=None, threshold=0.1, nodes=4, topology="ring", loss=0.0,
    ...              scenario="s", seed=s, runs=10, steps=5, state_dim=7, pos_rmse=p, vel_rmse=1.0, nees=7.0,
    ...              trigger_rate=0.5, floats_s2e=1.0, floats_e2s=0.0, floats_e2e=2.0, floats_total=3.0,
    ...              guard_fallbacks=0, non_finite_runs=0) for s, p in [(0, 0.1), (10, 0.3)]]
    >>> a = aggregate(rows)[0]
    >>> round(a["pos_rmse"], 12), a["runs"], a["seeds"]
    (0.2, 20, 2)
    """
    groups: Dict[Tuple[Any, ...], List[Mapping[str, Any]]] = {}
    keys = ("scenario", "nodes", "topology", "loss", "algorithm", "trigger", "threshold", "fusion", "steps")
    for r in rows:
        groups.setdefault(tuple(r.get(k) for k in keys), []).append(r)
    out = []
    mean_cols = ("pos_rmse", "vel_rmse", "trigger_rate", "floats_s2e", "floats_e2s", "floats_e2e", "floats_total")
    for k, rs in groups.items():
        runs = sum(r["runs"] for r in rs)
        a: Dict[str, Any] = dict(zip(keys, k))
        a["runs"] = runs
        a["seeds"] = len(rs)
        for c in mean_cols:
            a[c] = sum(r[c] * r["runs"] for r in rs) / runs
        if any(r["nees"] is None for r in rs):
            a["nees"] = None
        else:
            a["nees"] = sum(r["nees"] * r["runs"] for r in rs) / runs
        a["nees_lo"], a["nees_hi"] = chi2_band(rs[0]["state_dim"] * runs, runs)
        a["nees_in_band"] = None if a["nees"] is None else bool(a["nees_lo"] <= a["nees"] <= a["nees_hi"])
        a["guard_fallbacks"] = sum(r["guard_fallbacks"] for r in rs)
        out.append(a)
    return out


def is_paper_point(row: Mapping[str, Any], paper_delta: float = 0.04) -> bool:
    """EDC-CIF with the paper's send-on-delta, its default threshold and CI."""
    return (
        row["algorithm"] == "edc-cif"
        and row.get("fusion") in (None, "ci", "diffusion-ci")
        and row["trigger"] in (None, "sod")
        and (row["threshold"] is None or abs(row["threshold"] - paper_delta) < 1e-12)
    )


def front_scale(pts: Sequence[Mapping[str, Any]]) -> Tuple[float, List[str]]:
    """The top of a front panel's RMSE axis and the curves it clips: the largest
    RMSE of the points whose NEES is not above its 95 % band (an over-confident
    configuration, e.g. ``sod-hold`` at large thresholds, would otherwise set
    the scale and squeeze the others), with 8 % headroom; with every point
    over-confident, the largest of all. Returns ``(top, labels clipped)``.

    >>> pts = [dict(algorithm="edc-cif", trigger=t, pos_rmse=r, nees=n, nees_hi=8.0)
    ...        for t, r, n in [("sod", 0.1, 7.0), ("sod", 0.2, 7.5), ("sod-hold", 1.3, 50.0)]]
    >>> top, clipped = front_scale(pts)
    >>> round(top, 3), clipped
    (0.216, ['edc-cif / sod-hold'])
    """
    trusted = [p["pos_rmse"] for p in pts if p["nees"] is None or p["nees"] <= p["nees_hi"]]
    top = 1.08 * max(trusted or [p["pos_rmse"] for p in pts])
    clipped = sorted({_label(p) for p in pts if p["pos_rmse"] > top})
    return top, clipped


def plot_front(rows: Iterable[Mapping[str, Any]], path: Union[str, os.PathLike], *, paper_delta: float = 0.04) -> None:
    """The accuracy–communication front: position RMSE against floats sent per step
    (left: sensor ↔ estimator, right: everything), one line per algorithm and
    trigger through its thresholds, each point labelled with its threshold and
    its average NEES (hollow markers: NEES outside its 95 % band), the paper's
    operating point starred. One row of panels per scenario, node count,
    topology and loss, titled with the runs pooled per point. The RMSE axis
    shows the points that are not over-confident (:func:`front_scale`); points
    above it are drawn as triangles on the top edge and named under the
    panel with their largest RMSE."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    agg = aggregate(rows)
    panels: Dict[Tuple[Any, ...], List[Dict[str, Any]]] = {}
    for a in agg:
        panels.setdefault((a["scenario"], a["nodes"], a["topology"], a["loss"]), []).append(a)
    keys = sorted(panels, key=lambda k: (k[0], k[1], k[2], k[3]))
    fig, axes = plt.subplots(len(keys), 2, figsize=(13, 5.2 * len(keys)), squeeze=False)
    markers = "osDvPXhp<>d"  # not "^": a triangle marks a point above the axis
    for row_i, key in enumerate(keys):
        pts = panels[key]
        labels = sorted({_label(p) for p in pts})
        colors = {lab: plt.get_cmap("tab10")(i % 10) for i, lab in enumerate(labels)}
        marker = {lab: markers[i % len(markers)] for i, lab in enumerate(labels)}
        top, clipped = front_scale(pts)
        runs = sorted({p["runs"] for p in pts})
        runs_text = f"{runs[0]} runs per point" if len(runs) == 1 else f"{runs[0]}–{runs[-1]} runs per point"
        for col, (xcol, xname) in enumerate(
            [("s2e+e2s", "floats sent per step, sensor ↔ estimator"), ("floats_total", "floats sent per step, total")]
        ):
            ax = axes[row_i][col]
            for lab in labels:
                line = [p for p in pts if _label(p) == lab]
                xs = [_x(p, xcol) for p in line]
                order = sorted(range(len(line)), key=lambda i: xs[i])
                line = [line[i] for i in order]
                xs = [xs[i] for i in order]
                ys = [min(p["pos_rmse"], top) for p in line]
                ax.plot(xs, ys, "-", color=colors[lab], lw=1, alpha=0.7, label=lab)
                for p, x, y in zip(line, xs, ys):
                    good = p["nees_in_band"]
                    off = p["pos_rmse"] > top
                    ax.plot(x, y, "^" if off else marker[lab], ms=7 if off else 5, color=colors[lab],
                            mfc=colors[lab] if good else "none", clip_on=False)
                    thr = "default" if p["threshold"] is None else f"{p['threshold']:g}"
                    nees = "" if p["nees"] is None else f" | {p['nees']:.1f}"
                    ax.annotate(f"{thr}{nees}", (x, y), xytext=(3, 3), textcoords="offset points",
                                fontsize=5.5, color=colors[lab], clip_on=True)
                    if is_paper_point(p, paper_delta):
                        ax.plot(x, y, "*", ms=16, mfc="none", mec="k", mew=1.2)
                        ax.annotate("paper's operating point", (x, y), xytext=(8, -12), textcoords="offset points",
                                    fontsize=7)
            allx = [_x(p, xcol) for p in pts]
            if min(allx) > 0 and max(allx) / min(allx) > 5:
                ax.set_xscale("log")
            ax.set_ylim(0.9 * min(p["pos_rmse"] for p in pts), top)
            ax.set_xlabel(xname)
            ax.set_ylabel("position RMSE (m)")
            sc, n, topo, loss = key
            ax.set_title(f"{sc}: {n} nodes, {topo}, loss {loss:g}; {runs_text}", fontsize=9)
            ax.grid(alpha=0.3)
            if clipped:
                worst = {lab: max(p["pos_rmse"] for p in pts if _label(p) == lab) for lab in clipped}
                ax.text(0.0, -0.16, "off scale (▲ on the top edge): "
                        + ", ".join(f"{lab} up to {worst[lab]:.2f} m" for lab in clipped),
                        transform=ax.transAxes, fontsize=7, va="top")
            if col == 0:
                ax.legend(fontsize=7, ncol=2)
    fig.text(0.01, 0.002, "beside every point: threshold | average NEES; hollow marker: NEES outside its 95 % χ² band; "
             "the RMSE axis ends above the largest point that is not over-confident (NEES not above its band)",
             fontsize=7)
    from . import plots

    plots.fit_titles(fig)
    fig.tight_layout(rect=(0, 0.015, 1, 1))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _x(p: Mapping[str, Any], xcol: str) -> float:
    if xcol == "s2e+e2s":
        return float(p["floats_s2e"] + p["floats_e2s"])
    return float(p[xcol])


def to_markdown(rows: Iterable[Mapping[str, Any]], *, paper_delta: float = 0.04) -> str:
    """One Markdown table per scenario / nodes / topology / loss of the pooled
    rows, sorted by algorithm, trigger, threshold and fusion; the paper's
    operating point in bold. A fusion column appears when a row has a fusion.

    >>> rows = [dict(algorithm="edc-cif", trigger=None, threshold=None, nodes=4, topology="ring", loss=0.0,
    ...              scenario="paper-4", seed=0, runs=10, steps=5, state_dim=7, pos_rmse=0.1, vel_rmse=1.0, nees=7.0,
    ...              nees_lo=6.0, nees_hi=8.0, trigger_rate=0.5, floats_s2e=1.0, floats_e2s=0.0,
    ...              floats_e2e=2.0, floats_total=3.0, guard_fallbacks=0, non_finite_runs=0)]
    >>> print(to_markdown(rows).splitlines()[4])
    | **edc-cif** | **row** | **default** | **50.0 %** | **1.0** | **3.0** | **0.1000** | **7.00** | **[4.88, 9.50]** |
    """
    agg = aggregate(rows)
    panels: Dict[Tuple[Any, ...], List[Dict[str, Any]]] = {}
    for a in agg:
        panels.setdefault((a["scenario"], a["nodes"], a["topology"], a["loss"]), []).append(a)
    parts = []
    for key in sorted(panels):
        sc, n, topo, loss = key
        with_fusion = any(p.get("fusion") is not None for p in panels[key])
        parts.append(f"#### {sc}: {n} nodes, {topo} topology, message loss {loss:g}\n")
        parts.append(
            "| algorithm | trigger | threshold | " + ("fusion | " if with_fusion else "") + "trigger rate "
            "| floats/step s↔e | floats/step total | pos RMSE (m) | NEES | 95 % band |\n"
            + "|---" * (10 if with_fusion else 9) + "|"
        )
        pts = sorted(
            panels[key],
            key=lambda p: (p["algorithm"], p["trigger"] or "", -1.0 if p["threshold"] is None else p["threshold"],
                           p.get("fusion") or ""),
        )
        for p in pts:
            cells = [
                p["algorithm"],
                p["trigger"] or "row",
                "default" if p["threshold"] is None else f"{p['threshold']:g}",
                *([p.get("fusion") or "row"] if with_fusion else []),
                f"{100 * p['trigger_rate']:.1f} %",
                f"{p['floats_s2e'] + p['floats_e2s']:.1f}",
                f"{p['floats_total']:.1f}",
                f"{p['pos_rmse']:.4f}",
                "–" if p["nees"] is None else f"{p['nees']:.2f}",
                f"[{p['nees_lo']:.2f}, {p['nees_hi']:.2f}]",
            ]
            if is_paper_point(p, paper_delta):
                cells = [f"**{c}**" for c in cells]
            parts.append("| " + " | ".join(cells) + " |")
        parts.append("")
    return "\n".join(parts)


# ---------------------------------------------------------------------------
# The command line: `edccif sweep`


def _parse_thresholds(items: Sequence[str]) -> Thresholds:
    """``["0.01", "0.02"]`` → a list; ``["sod=0.01,0.02", "stochastic=1,2"]`` → a
    dict; plain numbers next to named lists go to ``"*"`` (every other trigger).

    >>> _parse_thresholds(["0.01", "0.02"])
    [0.01, 0.02]
    >>> _parse_thresholds(["sod=0.01,0.02", "row=0.04", "3"])
    {'sod': [0.01, 0.02], 'row': [0.04], '*': [3.0]}
    """
    plain: List[float] = []
    named: Dict[str, List[float]] = {}
    for it in items:
        try:
            if "=" in it:
                k, v = it.split("=", 1)
                named.setdefault(k.strip(), []).extend(float(x) for x in v.split(",") if x.strip())
            else:
                plain.extend(float(x) for x in it.split(",") if x.strip())
        except ValueError:
            raise ParameterError(
                f"thresholds: expected numbers or TRIGGER=v1,v2,..., got {it!r}"
            ) from None
    if not named:
        return plain
    if plain:
        named["*"] = plain
    return named


def grid_from_file(path: Union[str, os.PathLike]) -> Grid:
    """A :class:`Grid` from a JSON file whose keys are its fields
    (``{"algorithms": [...], "triggers": ["sod", null], "thresholds": {...}, ...}``)."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ParameterError(f"grid: cannot read {str(path)!r} as JSON: {e}") from None
    unknown = set(d) - set(Grid.__dataclass_fields__)
    if unknown:
        raise _edccif.UnknownOptionError(
            f"grid: unknown keys {sorted(unknown)} in {str(path)!r}, "
            f"expected some of {sorted(Grid.__dataclass_fields__)}"
        )
    return Grid(**d)


def add_subcommand(sub: Any) -> None:
    """Adds ``edccif sweep`` to the command line's subparsers."""
    s = sub.add_parser(
        "sweep",
        help=("a parameter-grid sweep (algorithm × trigger × threshold × fusion × nodes × topology × loss × seed) "
              "on Dask"),
        description=(
            "Runs a Monte Carlo study per grid cell on a Dask cluster (a local one unless --scheduler is given), "
            "appends each finished cell to a CSV table (an interrupted sweep resumes where it stopped) and draws "
            "the accuracy-communication front."
        ),
    )
    s.add_argument("--grid", help="a JSON file with the grid (keys: the Grid fields); flags below override it")
    s.add_argument("--algorithms", nargs="+", help="algorithm rows (default: edc-cif)")
    s.add_argument("--triggers", nargs="+", help="trigger names, 'row' for the row's own trigger (default: row)")
    s.add_argument("--thresholds", nargs="+", help="thresholds: numbers for every trigger, or TRIGGER=v1,v2,...")
    from . import _args

    s.add_argument("--nodes", type=_args.count, nargs="+", help="node counts of the built-in scenario (default: 4)")
    s.add_argument("--fusion", nargs="+", type=_fusion_arg,
                   help="fusion rules (edccif.FUSION_RULES, docs/fusion.md) or structural fusions, "
                        "'row' for the row's own (default: row)")
    s.add_argument("--scenario", help="a scenario TOML file instead of the built-in one")
    s.add_argument("--topology", nargs="+", help="ring, line, star, complete, random-geometric:RADIUS:SEED")
    s.add_argument("--loss", type=_args.real(0.0, 1.0, meaning="a probability"), nargs="+",
                   help="message-loss probabilities per directed link and step, as run(faults=...) (default: 0)")
    s.add_argument("--seeds", type=_args.seed, nargs="+", help="seed of run 0 of each cell (default: 0)")
    s.add_argument("--runs", type=_args.count, help="Monte Carlo runs per cell (default 100)")
    s.add_argument("--steps", type=_args.count, help="steps per run (default: the scenario's)")
    s.add_argument("--out", type=_args.output_path, default="sweep.csv",
                   help="the table (CSV; default sweep.csv); resumed if it is a sweep table, "
                   "refused if it is another file (unless --force)")
    s.add_argument("--figure", type=_args.output_path,
                   help="the front figure (default: the table's name with .png)")
    s.add_argument("--no-figure", action="store_true", help="do not draw the figure")
    s.add_argument("--markdown", type=_args.output_path,
                   help="also write the pooled tables as Markdown to this file")
    s.add_argument("--force", action="store_true",
                   help="replace an --out that is not a sweep table, and an existing --figure/--markdown")
    s.add_argument("--scheduler", type=_args.scheduler_address,
                   help="address of an existing Dask scheduler, [tcp://]HOST:PORT (default: start a local cluster)")
    s.add_argument("--workers", type=_args.threads("worker processes of the local cluster"),
                   help="worker processes of the local cluster (default: one per core)")
    s.add_argument("--in-process", action="store_true", help="run the cells in this process, without Dask")
    s.add_argument("--quiet", action="store_true", help="no progress output")
    s.set_defaults(func=cmd_sweep)


def cmd_sweep(args: Any) -> int:
    """``edccif sweep``: runs the grid, prints a summary line and where things are."""
    grid = grid_from_file(args.grid) if args.grid else Grid()
    if args.algorithms:
        grid.algorithms = args.algorithms
    if args.triggers:
        grid.triggers = [None if t == "row" else t for t in args.triggers]
    if args.thresholds:
        grid.thresholds = _parse_thresholds(args.thresholds)
    if args.fusion:
        grid.fusions = [None if f == "row" else f for f in args.fusion]
    if args.scenario:
        grid.scenario = args.scenario
        if not args.nodes:
            grid.nodes = ()
    if args.nodes:
        grid.nodes = args.nodes
    if args.topology:
        grid.topologies = args.topology
    if args.loss:
        grid.losses = args.loss
    if args.seeds:
        grid.seeds = args.seeds
    if args.runs is not None:
        grid.runs = args.runs
    if args.steps is not None:
        grid.steps = args.steps
    if args.in_process and args.scheduler:
        raise ParameterError("scheduler: --in-process and --scheduler exclude each other")
    if args.in_process and args.workers is not None:
        raise ParameterError("workers: --workers sizes the local Dask cluster; not with --in-process")
    out = Path(args.out)
    resume = out.exists() and is_sweep_table(out)
    fig = None if args.no_figure else (Path(args.figure) if args.figure else out.with_suffix(".png"))
    md_path = Path(args.markdown) if args.markdown else None
    from . import _args

    # the table's own figure is the sweep's when the table is resumed; any other existing file needs --force
    _args.check_output_files(
        [(None if resume else out, "out"),
         (None if resume and args.figure is None else fig, "figure"),
         (md_path, "markdown")],
        args.force,
    )
    grid.cells()  # every grid error before anything is replaced or started
    if out.exists() and not resume:
        out.unlink()  # --force: not a sweep table, replaced
    scheduler = "inprocess" if args.in_process else args.scheduler
    t0 = time.perf_counter()
    rows = run_sweep(grid, out, scheduler=scheduler, workers=args.workers, progress=not args.quiet)
    wall = time.perf_counter() - t0
    print(f"{len(rows)} cells in {wall:.1f} s wall time; table: {out}", file=sys.stderr)
    md = to_markdown(rows)
    if md_path is not None:
        md_path.write_text(md)
    if fig is not None:
        plot_front(rows, fig)
        print(f"front figure: {fig}", file=sys.stderr)
    print(md)
    return 0
