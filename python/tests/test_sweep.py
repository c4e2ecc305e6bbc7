"""`edccif sweep`: the grid, the table, resuming, the CLI, and the same numbers on
a two-worker Dask cluster as in this process."""

import doctest
import os
import re
from pathlib import Path

import numpy as np
import pytest

import edccif
import edccif.sweep as sweep
from edccif.cli import main
from edccif.sweep import Cell, Grid, read_table, run_sweep

# Columns that must agree bit for bit between executors (all but the wall time).
SAME = [c for c in sweep.COLUMNS if c != "wall_s"]


def small_grid(**kw):
    d = dict(algorithms=["edc-cif", "ec-ckf", "dc-cif"], thresholds=[0.02, 0.08], nodes=[3, 4], runs=3, steps=30)
    d.update(kw)
    return Grid(**d)


def test_docstring_examples():
    r = doctest.testmod(sweep)
    assert r.attempted >= 8 and r.failed == 0


def test_grid_cells_and_ids():
    g = small_grid()
    cells = g.cells()
    # 2 node counts × (2 ET rows × 2 thresholds + 1 send-all row)
    assert len(cells) == 10
    assert len({c.cell_id for c in cells}) == 10
    assert cells[0].algorithm == "edc-cif" and cells[0].threshold == 0.02 and cells[0].nodes == 3
    # the id depends on everything the numbers depend on
    assert Grid(runs=3, steps=30, seeds=[1]).cells()[0].cell_id != Grid(runs=3, steps=30).cells()[0].cell_id
    assert Grid(runs=3, steps=31).cells()[0].cell_id != Grid(runs=3, steps=30).cells()[0].cell_id


def test_cell_equals_monte_carlo():
    c = Grid(thresholds=[0.05], runs=4, steps=40, seeds=[7]).cells()[0]
    row = c.run()
    sc = edccif.Scenario.paper(nodes=4).replace(steps=40)
    mc = edccif.monte_carlo(sc, [{"algorithm": "edc-cif", "delta": 0.05}], runs=4, seed=7, progress=False)
    assert row["pos_rmse"] == mc.pos_rmse["EDC-CIF"]
    assert row["nees"] == mc.nees["EDC-CIF"]
    assert row["trigger_rate"] == mc.trigger_rate["EDC-CIF"]
    assert row["nees_lo"] < 7 < row["nees_hi"]


def test_cell_with_message_loss_equals_runs_with_faults(tmp_path):
    """A cell with loss p: run r is `run(..., faults={"message_loss": p, "seed": seed + r})` on the
    simulation of seed + r; its row from those runs by the metrics' definitions (numpy)."""
    runs, seed, loss, steps = 3, 5, 0.3, 40
    row = Grid(losses=[loss], runs=runs, steps=steps, seeds=[seed], thresholds=[0.05]).cells()[0].run()
    sc = edccif.Scenario.paper(nodes=4).replace(steps=steps)
    pos_sq, nees, trig, meas, s2e, e2e, lost = [], [], 0, 0, 0, 0, 0
    for r in range(runs):
        truth, z, x0 = sc.simulate(seed=seed + r)
        res = edccif.run("edc-cif", sc, z, x0=x0, delta=0.05, faults={"message_loss": loss, "seed": seed + r})
        full = edccif.run("edc-cif", sc, z, x0=x0, delta=0.05)
        err = res.estimates - truth[:, None, :]
        pos_sq.append((err[:, :, :3] ** 2).sum(axis=2))
        nees.append(np.einsum("tni,tni->tn", err, np.linalg.solve(res.covariances, err[..., None])[..., 0]))
        trig, meas = trig + res.triggered.sum(), meas + res.measured.sum()
        s2e += res.values_sent["sensor_to_estimator"]
        e2e += res.values_sent["estimator_to_estimator"]
        lost += full.values_sent["estimator_to_estimator"] - res.values_sent["estimator_to_estimator"]
    assert lost > 0  # messages were lost
    assert row["loss"] == loss
    assert row["pos_rmse"] == pytest.approx(np.sqrt(np.mean(pos_sq, axis=0)).mean(), rel=1e-12)
    assert row["nees"] == pytest.approx(np.mean(nees), rel=1e-9)
    assert row["trigger_rate"] == trig / meas
    assert row["floats_s2e"] == pytest.approx(s2e / runs / steps, rel=1e-15)
    assert row["floats_e2e"] == pytest.approx(e2e / runs / steps, rel=1e-15)
    # the CLI's --loss gives the same row
    out = tmp_path / "loss.csv"
    assert main(["sweep", "--in-process", "--quiet", "--loss", str(loss), "--runs", str(runs), "--steps", str(steps),
                 "--seeds", str(seed), "--thresholds", "0.05", "--out", str(out), "--no-figure"]) == 0
    (cli_row,) = read_table(out)
    assert {k: cli_row[k] for k in SAME} == {k: row[k] for k in SAME}


def test_table_round_trip_and_resume(tmp_path, monkeypatch):
    out = tmp_path / "t.csv"
    part = small_grid(nodes=[3])
    rows_part = run_sweep(part, out, scheduler="inprocess", progress=False)
    back = read_table(out)
    assert [{k: r[k] for k in SAME} for r in back] == [{k: r[k] for k in SAME} for r in rows_part]

    # simulate an interrupted write: a half line at the end is dropped and recomputed
    with open(out, "a") as f:
        f.write("deadbeef,paper-4,edc-cif,,0.0")
    calls = []
    real = Cell.run

    def counting(self):
        calls.append(self.cell_id)
        return real(self)

    monkeypatch.setattr(Cell, "run", counting)
    full = small_grid()
    rows = run_sweep(full, out, scheduler="inprocess", progress=False)
    assert len(rows) == 10 and len(calls) == 5  # only the 4-node cells ran
    assert {c.cell_id for c in full.cells() if c.nodes == 4} == set(calls)
    assert [r["cell_id"] for r in read_table(out)] == [c.cell_id for c in full.cells()]
    # nothing left to do: nothing runs, same rows
    calls.clear()
    again = run_sweep(full, out, scheduler="inprocess", progress=False)
    assert calls == [] and again == rows


def test_two_worker_dask_cluster_gives_the_same_numbers(tmp_path):
    if not os.environ.get("CI"):
        pytest.importorskip("distributed")
    # the stochastic trigger draws random numbers: its seeding must not depend on where a cell runs
    extra = [t for t in ("stochastic", "innovation") if t in getattr(edccif, "TRIGGERS", ())]
    grid = small_grid(triggers=[None, *extra], thresholds={"row": [0.02, 0.08], "*": [2.0]})
    local = run_sweep(grid, scheduler="inprocess", progress=False)
    out = tmp_path / "dask.csv"
    dist = run_sweep(grid, out, workers=2, progress=False, timeout=240)
    assert [{k: r[k] for k in SAME} for r in dist] == [{k: r[k] for k in SAME} for r in local]
    assert [{k: r[k] for k in SAME} for r in read_table(out)] == [{k: r[k] for k in SAME} for r in local]


def test_cli_sweep(tmp_path, capsys):
    out = tmp_path / "front.csv"
    rc = main(["sweep", "--in-process", "--quiet", "--algorithms", "edc-cif", "--thresholds", "0.04", "0.1",
               "--runs", "2", "--steps", "20", "--out", str(out), "--markdown", str(tmp_path / "front.md")])
    assert rc == 0
    assert (tmp_path / "front.png").stat().st_size > 1000
    assert len(read_table(out)) == 2
    md = capsys.readouterr().out
    assert "**edc-cif**" in md and md.strip() == (tmp_path / "front.md").read_text().strip()


@pytest.mark.parametrize(
    "kw, err, words",
    [
        (dict(algorithms=["nope"]), edccif.UnknownAlgorithmError, ["nope", "edc-cif"]),
        (dict(triggers=["nope"]), edccif.UnknownOptionError, ["nope"]),
        (dict(topologies=["torus"]), edccif.ParameterError, ["torus", "ring"]),
        (dict(losses=[1.5]), edccif.ParameterError, ["1.5", "[0, 1]"]),
        (dict(runs=0), edccif.ParameterError, ["runs", ">= 1"]),
        (dict(thresholds={"stochastic": [1.0]}), edccif.ParameterError, ["stochastic"]),
    ],
)
def test_grid_errors_name_what_was_wrong(kw, err, words):
    with pytest.raises(err) as e:
        Grid(**kw).cells()
    for w in words:
        assert w in str(e.value)


def test_cli_threshold_syntax_errors():
    assert main(["sweep", "--in-process", "--thresholds", "sod=abc"]) == 2


def test_docs_example_runs_as_written(capsys):
    text = (Path(__file__).resolve().parents[2] / "docs" / "sweep.md").read_text()
    block = re.search(r"## From Python\s+```python\n(.*?)```", text, re.S).group(1)
    exec(compile(block, "docs/sweep.md", "exec"), {"__name__": "__docs__"})
    assert "| edc-cif | row | 0.02 |" in capsys.readouterr().out


def test_fusion_axis(tmp_path):
    # the fusion rule as an axis: one cell per rule, `None` the row's own with
    # the id it had before the axis; a column in the table and the Markdown
    base = Grid(thresholds=[0.04], runs=2, steps=20)
    g = Grid(thresholds=[0.04], runs=2, steps=20, fusions=[None, "ici", "split-ci"])
    cells = g.cells()
    assert [c.fusion for c in cells] == [None, "ici", "split-ci"]
    assert cells[0].cell_id == base.cells()[0].cell_id
    assert len({c.cell_id for c in cells}) == 3
    rows = run_sweep(g, tmp_path / "f.csv", scheduler="inprocess", progress=False)
    assert [r["fusion"] for r in read_table(tmp_path / "f.csv")] == [None, "ici", "split-ci"]
    assert rows[1]["pos_rmse"] != rows[0]["pos_rmse"]
    md = sweep.to_markdown(rows)
    assert "| fusion |" in md and "| split-ci |" in md
    with pytest.raises(edccif.UnknownOptionError, match="split-ci"):
        Grid(fusions=["nope"]).cells()
    rc = main(["sweep", "--in-process", "--quiet", "--no-figure", "--thresholds", "0.04", "--fusion", "row", "ici",
               "--runs", "2", "--steps", "20", "--out", str(tmp_path / "cli.csv")])
    assert rc == 0 and [r["fusion"] for r in read_table(tmp_path / "cli.csv")] == [None, "ici"]
