"""The command line end to end on small runs, and the README quick start as written."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from edccif import reproduce as reproduce_mod

README = Path(__file__).resolve().parents[2] / "README.md"
RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results.md"
SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"


def _edccif(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True, check=False
    )


def test_reproduce_small(tmp_path):
    out = tmp_path / "res"
    p = _edccif("reproduce", "--nodes", "3", "4", "--runs", "2", "--out", str(out), "--json",
                "--timing-reps", "1", "--quiet", "--no-flights", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    # --quiet: the tables are in results.md, not on stdout
    assert p.stdout == ""
    md = (out / "results.md").read_text()
    assert "Table II" in md and "| EDC-CIF |" in md and "(0.0645)" in md
    for f in ("results.md", "results.json", "trajectory_3d.png", "rmse_over_time.png",
              "trigger_instants.png", "delta_sweep.png", "computation_time.png"):
        assert (out / f).stat().st_size > 0, f
    data = json.loads((out / "results.json").read_text())
    assert [t["nodes"] for t in data["table2"]] == [3, 4]
    assert len(data["table2"][0]["variants"]) == 9
    assert data["settings"]["runs"] == 2
    assert set(data["timing_ms"]) == {"3", "4"}
    assert "flights" not in data and "Real flights" not in md


def _strip_times(obj):
    """The numbers of a results.json without its wall-clock entries."""
    if isinstance(obj, dict):
        return {k: _strip_times(v) for k, v in obj.items() if "time" not in k and "elapsed" not in k}
    if isinstance(obj, list):
        return [_strip_times(v) for v in obj]
    return obj


def test_reproduce_jobs_sets_the_pool_and_keeps_the_numbers(tmp_path):
    runs = {}
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}"
        p = _edccif("reproduce", "--nodes", "3", "--runs", "3", "--out", str(out), "--no-figures",
                    "--no-flights", "--jobs", jobs, cwd=tmp_path)
        assert p.returncode == 0, p.stderr
        assert f"Monte Carlo on {jobs} worker thread(s)" in p.stderr
        runs[jobs] = _strip_times(json.loads((out / "results.json").read_text())["table2"])
    assert runs["1"] == runs["2"] and runs["1"]
    bad = _edccif("reproduce", "--jobs", "0", "--out", str(tmp_path / "bad"), cwd=tmp_path)
    assert bad.returncode == 2 and "--jobs" in bad.stderr and "integer >= 1" in bad.stderr


def test_set_worker_threads_errors():
    code = (
        "import edccif\n"
        "for bad in (0, -3):\n"
        "    try:\n"
        "        edccif.set_worker_threads(bad)\n"
        "    except edccif.ParameterError as e:\n"
        "        print('bad', e)\n"
        "edccif.set_worker_threads(2)\n"
        "edccif.set_worker_threads(2)\n"
        "print('threads', edccif.worker_threads())\n"
        "try:\n"
        "    edccif.set_worker_threads(3)\n"
        "except edccif.ParameterError as e:\n"
        "    print('resize', e)\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    expected = r"bad worker threads \(jobs\): expected an integer in 1\.\.=\d+ \(4 per core .*\), got 0"
    assert re.fullmatch(expected, lines[0])
    assert lines[1].startswith("bad worker threads (jobs): expected an integer in 1..=") and lines[1].endswith("got -3")
    assert lines[2] == "threads 2"
    assert lines[3].startswith("resize worker threads (jobs): the worker pool already runs 2 threads")


def _flight_section(markdown):
    a = markdown.index("## Real flights as targets")
    end = re.search(r"\n(## |<!--)", markdown[a + 3:])
    return markdown[a:a + 3 + end.start() if end else len(markdown)].strip()


def test_reproduce_real_flights_equal_the_rust_report(tmp_path):
    # The section's numbers depend on neither --runs nor --seed (fixed flight
    # seeds), so a small run prints docs/results.md's section word for word.
    # The data beside this source tree (CI puts ../shared beside the clone); the
    # suite runs from outside the tree against the installed package, whose own
    # default cannot see it.
    data_dir = SHARED_DATA
    if not data_dir.is_dir():
        pytest.skip(f"no real-flight data at {data_dir}")
    out = tmp_path / "res"
    p = _edccif("reproduce", "--nodes", "3", "--runs", "1", "--out", str(out), "--no-figures",
                "--quiet", "--data-dir", str(data_dir), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stdout == ""
    assert _flight_section((out / "results.md").read_text()) == _flight_section(RESULTS.read_text())
    data = json.loads((out / "results.json").read_text())
    assert [f["flight"] for f in data["flights"]["flights"]] == ["euroc-v102", "tum-fr1-xyz"]


def test_reproduce_flight_data_missing(tmp_path, monkeypatch, capsys):
    # an explicit directory that is not there is an error naming it
    p = _edccif("reproduce", "--nodes", "3", "--runs", "1", "--out", str(tmp_path / "r"),
                "--no-figures", "--quiet", "--data-dir", str(tmp_path / "nope"), cwd=tmp_path)
    assert p.returncode == 2 and "data_dir" in p.stderr and "nope" in p.stderr, p.stderr
    # the default one absent: a notice, and the section is left out
    monkeypatch.setattr(reproduce_mod, "default_data_dir", lambda: tmp_path / "absent")
    assert reproduce_mod.flight_data_dir() is None
    err = capsys.readouterr().err
    assert "skipped" in err and str(tmp_path / "absent") in err and "--data-dir" in err
    assert reproduce_mod.flight_data_dir(flights=False) is None
    assert reproduce_mod.flight_data_dir(data_dir=tmp_path) == tmp_path


def test_reproduce_finds_the_data_from_the_working_directory(tmp_path, monkeypatch):
    # An installed (not editable) package cannot see its source tree, so the
    # default looks at ../shared/data from where the command runs first.
    repo = tmp_path / "main"
    data = tmp_path / "shared" / "data"
    repo.mkdir()
    data.mkdir(parents=True)
    monkeypatch.chdir(repo)
    assert reproduce_mod.data_dir_candidates()[0] == data.resolve()
    assert reproduce_mod.default_data_dir() == data.resolve()
    assert reproduce_mod.flight_data_dir() == data.resolve()
    # without it there, the first candidate is what the notice names
    data.rmdir()
    monkeypatch.setattr(reproduce_mod, "data_dir_candidates", lambda: [data, tmp_path / "nowhere"])
    assert reproduce_mod.default_data_dir() == data


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
    assert p.returncode == 2 and "unknown algorithm 'nope'" in p.stderr


@pytest.mark.parametrize("name, nodes, width", [("bearing-only-2d", 6, 7), ("mixed-3d", 5, 13)])
def test_simulate_runs_the_catalogue_scenario_files(tmp_path, name, nodes, width):
    """A scenario file with a sensor of its own per node runs through `edccif simulate`."""
    path = Path(__file__).resolve().parents[2] / "scenarios" / f"{name}.toml"
    p = _edccif("simulate", "--scenario", str(path), "--algorithm", "EDC-CIF", "--out", "r.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert summary["scenario"] == name and summary["nodes"] == nodes
    assert summary["mean_position_error_m"] < 1.0
    arrays = np.load(tmp_path / "r.npz")
    assert arrays["z"].shape == (200, width)


def test_simulate_takes_the_papers_spelling(tmp_path):
    """`EDC-CIF` (the paper's spelling) is `edc-cif` on the command line as in Python."""
    p = _edccif("simulate", "--nodes", "3", "--algorithm", "EDC-CIF", "--out", "r.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["algorithm"] == "edc-cif"


@pytest.mark.parametrize(
    "flag,value,expected",
    [
        ("--rate", "0", "finite number > 0 (Hz)"),
        ("--rate", "nan", "finite number > 0 (Hz)"),
        ("--noise", "loud", "`message`, `scenario` or a standard deviation"),
        ("--noise", "-0.1", "`message`, `scenario` or a standard deviation"),
        ("--same-frame", "map", "FRAME=OTHER_FRAME"),
        ("--same-frame", "map=map", "FRAME=OTHER_FRAME"),
        ("--sigma", "-1", "metres"),
        ("--q", "0", "noise intensity"),
        ("--delta", "inf", "trigger threshold"),
        ("--motion", "cv2", "invalid choice"),
        ("--sensor", "range", "invalid choice"),
    ],
)
def test_replay_bad_values(tmp_path, flag, value, expected):
    p = _edccif("replay", "x.mcap", "--measurement", "/a", flag, value, cwd=tmp_path)
    assert p.returncode == 2 and expected in p.stderr and flag in p.stderr, p.stderr
    assert "Traceback" not in p.stderr


def test_replay_inconsistent_flags(tmp_path):
    p = _edccif("simulate", "--nodes", "3", "--mcap", "r.mcap", "--out", "r.npz", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    for args, expected in [
        (["--rate", "10"], "--rate: only with --measurement"),
        (["--frame", "map"], "--frame: only with --measurement"),
        (["--sensor", "scenario"], "--sensor scenario: only with --scenario"),
        (["--scenario", "s.toml", "--motion", "cv3"], "not allowed with argument"),
        (["--noise", "0.1"], "noise=VALUE: only for ROS 2 position messages"),
    ]:
        p = _edccif("replay", "r.mcap", *args, cwd=tmp_path)
        assert p.returncode == 2 and expected in p.stderr, (args, p.stderr)
        assert "Traceback" not in p.stderr


def test_readme_quick_start_runs_as_written(tmp_path, capsys):
    text = README.read_text()
    block = re.search(r"## Python quick start\s+```python\n(.*?)```", text, re.S).group(1)
    assert len(block.strip().splitlines()) <= 22
    exec(compile(block, "README quick start", "exec"), {"__name__": "__readme__"})
    out = capsys.readouterr().out
    assert "mean position error" in out and "| EDC-CIF |" in out
