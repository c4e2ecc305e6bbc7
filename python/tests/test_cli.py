"""The command line end to end on small runs, and the README quick start as written."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[2] / "README.md"


def _edccif(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True, check=False
    )


def test_reproduce_small(tmp_path):
    out = tmp_path / "res"
    p = _edccif("reproduce", "--nodes", "3", "4", "--runs", "2", "--out", str(out), "--json",
                "--timing-reps", "1", "--quiet", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "Table II" in p.stdout and "| EDC-CIF |" in p.stdout and "(0.0645)" in p.stdout
    for f in ("results.md", "results.json", "trajectory_3d.png", "rmse_over_time.png",
              "trigger_instants.png", "delta_sweep.png", "computation_time.png"):
        assert (out / f).stat().st_size > 0, f
    data = json.loads((out / "results.json").read_text())
    assert [t["nodes"] for t in data["table2"]] == [3, 4]
    assert len(data["table2"][0]["variants"]) == 9
    assert data["settings"]["runs"] == 2
    assert set(data["timing_ms"]) == {"3", "4"}


def test_simulate_command(tmp_path):
    p = _edccif("simulate", "--nodes", "3", "--algorithm", "ec-ckf", "--seed", "4", "--out", "r.npz",
                cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert summary["algorithm"] == "ec-ckf" and summary["nodes"] == 3
    arrays = np.load(tmp_path / "r.npz")
    assert arrays["estimates"].shape == (200, 3, 7) and arrays["z"].shape == (200, 3, 3)


def test_cli_errors(tmp_path):
    p = _edccif("simulate", "--scenario", str(tmp_path / "nope.toml"), cwd=tmp_path)
    assert p.returncode == 2 and "cannot read" in p.stderr
    p = _edccif("simulate", "--algorithm", "nope", cwd=tmp_path)
    assert p.returncode == 2 and "invalid choice" in p.stderr


def test_readme_quick_start_runs_as_written(tmp_path, capsys):
    text = README.read_text()
    block = re.search(r"## Python quick start\s+```python\n(.*?)```", text, re.S).group(1)
    assert len(block.strip().splitlines()) <= 22
    exec(compile(block, "README quick start", "exec"), {"__name__": "__readme__"})
    out = capsys.readouterr().out
    assert "mean position error" in out and "| EDC-CIF |" in out
