"""The command line against hostile input: every bad value ends the command with
exit code 2 and one line on stderr (no traceback) before any process or thread
starts; broken pipes end quietly; no command replaces or deletes a file it did
not create in that run without --force; long commands report progress on stderr
when it is not a terminal."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import edccif
from edccif import _args, agents, sweep
from edccif.cli import BROKEN_PIPE_EXIT, main

CORES = os.cpu_count() or 1
TOO_MANY = str(_args.THREADS_PER_CORE * CORES + 1)


def _edccif(*args, cwd, timeout=120):
    return subprocess.run([sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, check=False)


def _one_line_error(err: str, *words: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "error:" in lines[0] and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, err)


def _in_process(args, capsys):
    """`edccif ARGS` in this process: (exit code, stderr)."""
    try:
        rc = main(args)
    except SystemExit as e:
        rc = e.code
    return rc, capsys.readouterr().err


# Each: arguments, words the message must hold. All are refused by argparse or
# right after it, before anything runs.
BAD = [
    # negative or zero counts and seeds
    (["simulate", "--nodes", "-3"], ["--nodes", "integer >= 1", "'-3'"]),
    (["simulate", "--seed", "-1"], ["--seed", ">= 0 and <= 18446744073709551615", "'-1'"]),
    (["simulate", "--seed", str(2**64)], ["--seed"]),
    (["reproduce", "--nodes", "3", "-4"], ["--nodes", "'-4'"]),
    (["reproduce", "--runs", "-1"], ["--runs", "integer >= 1"]),
    (["reproduce", "--runs", "0"], ["--runs"]),
    (["reproduce", "--seed", "-2"], ["--seed"]),
    (["reproduce", "--timing-reps", "-1"], ["--timing-reps", "integer >= 1"]),
    (["reliability", "--runs", "-5"], ["--runs"]),
    (["reliability", "--nodes", "-4"], ["--nodes"]),
    (["reliability", "--soak", "-1"], ["--soak", "integer >= 1"]),
    (["reliability", "--seed", "x"], ["--seed", "'x'"]),
    (["sweep", "--in-process", "--seeds", "0", "-1"], ["--seeds", "'-1'"]),
    (["sweep", "--in-process", "--runs", "-1"], ["--runs"]),
    (["sweep", "--in-process", "--nodes", "0"], ["--nodes"]),
    (["sweep", "--in-process", "--steps", "-20"], ["--steps"]),
    (["sweep", "--in-process", "--loss", "1.5"], ["--loss", "[0, 1]"]),
    (["sweep", "--in-process", "--loss", "nan"], ["--loss"]),
    (["sweep", "--in-process", "--fusion", "ei"], ["--fusion", "'ei'", "ei-unsafe", "split-ici"]),
    (["sweep", "--in-process", "--fusion", "ci", ""], ["--fusion", "''"]),
    (["swarm", "--nodes", "-1"], ["--nodes"]),
    (["swarm", "--seed", "-1"], ["--seed"]),
    (["swarm", "--steps", "0"], ["--steps"]),
    (["swarm", "--period", "0"], ["--period", "> 0"]),
    (["swarm", "--deadline", "inf"], ["--deadline"]),
    (["swarm", "--loss", "1"], ["--loss", "[0, 1)"]),
    (["agent", "--swarm", "s.json", "--node", "-1"], ["--node"]),
    # --kill and --delay that do not parse
    (["swarm", "--kill", "abc"], ["--kill", "NODE@STEP", "'abc'"]),
    (["swarm", "--kill", "1@x"], ["--kill"]),
    (["swarm", "--kill", "1@5+-2"], ["--kill", "DOWN_S >= 0"]),
    (["swarm", "--delay", "bad"], ["--delay", "FROM:TO:SECONDS", "'bad'"]),
    (["swarm", "--delay", "0:1:-0.5"], ["--delay"]),
    # a scheduler that is not an address
    (["sweep", "--scheduler", "not an address"], ["--scheduler", "HOST:PORT"]),
    (["sweep", "--scheduler", "tcp://host:99999"], ["--scheduler"]),
    # thread, job and worker counts: >= 1 and at most 4 x the cores
    (["sweep", "--workers", "0"], ["--workers", ">= 1 and <="]),
    (["sweep", "--workers", TOO_MANY], ["--workers", "cores"]),
    (["simulate", "--threads", "100000"], ["--threads", "cores"]),
    (["reproduce", "--jobs", TOO_MANY], ["--jobs"]),
    (["reliability", "--jobs", "0"], ["--jobs"]),
    (["simulate", "--algorithm", "nope"], ["--algorithm", "unknown algorithm 'nope'", "edc-cif"]),
    (["simulate", "--algorithm", ""], ["--algorithm", "unknown algorithm"]),
    (["replay", "x.mcap", "--algorithm", "EDC–CIF"], ["--algorithm", "unknown algorithm"]),  # an en dash
    (["swarm", "--algorithm", "edc cif"], ["--algorithm", "unknown algorithm"]),
]


@pytest.mark.parametrize("spelling", ["EDC-CIF", "edc_cif", " Edc-Cif ", "edc-cif"])
def test_algorithm_names_in_any_case_are_the_one_parser(spelling):
    """The command line takes an algorithm name as the library does (case, surrounding
    space and `_` for `-` ignored): the paper's `EDC-CIF` is `edc-cif`."""
    assert _args.algorithm(spelling) == "edc-cif" == edccif.algorithm_name(spelling)
    for a in edccif.ALGORITHMS:
        assert _args.algorithm(a.upper()) == a
    for t in edccif.TRIGGERS:
        assert _args.trigger(t.upper()) == t == edccif.trigger_name(t.upper())
    with pytest.raises(edccif.UnknownAlgorithmError):
        edccif.algorithm_name("edc-cif2")


def test_grid_takes_algorithm_and_trigger_names_in_any_case():
    g = sweep.Grid(algorithms=["EDC-CIF", "DC_CIF"], triggers=[None, "SOD"], thresholds={"SOD": [0.02]}, runs=1)
    g.validate()
    assert g.algorithms == ["edc-cif", "dc-cif"] and g.triggers == [None, "sod"]
    assert dict(g.thresholds) == {"sod": [0.02]}
    with pytest.raises(edccif.UnknownAlgorithmError, match="algorithms: unknown algorithm 'nope'"):
        sweep.Grid(algorithms=["nope"]).validate()


@pytest.mark.parametrize("args, words", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_values_are_one_line_and_exit_2(args, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, err = _in_process(args, capsys)
    assert rc == 2
    _one_line_error(err, *words)
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_bad_values_from_a_real_process(tmp_path):
    """The same through `python -m edccif`: exit 2, one line, no traceback, no Monte Carlo pool."""
    for args, words in [(["reproduce", "--runs", "-1"], ["--runs"]), (["swarm", "--kill", "abc"], ["--kill"]),
                        (["reliability", "--jobs", TOO_MANY], ["--jobs"])]:
        p = _edccif(*args, cwd=tmp_path)
        assert p.returncode == 2 and p.stdout == ""
        _one_line_error(p.stderr, *words)
        assert "Monte Carlo on" not in p.stderr  # the worker pool was never started


# ----------------------------------------------------------------------------- after parsing, before starting


@pytest.mark.parametrize(
    "args, words",
    [
        (["swarm", "--nodes", "4", "--kill", "9@5"], ["kill", "node 9", "0..3"]),
        (["swarm", "--nodes", "4", "--kill", "1@500", "--steps", "100"], ["kill", "step 500", "0..99"]),
        (["swarm", "--nodes", "3", "--delay", "0:7:0.1"], ["delay", "0..2"]),
        (["swarm", "--nodes", str(agents.MAX_PROCESSES_PER_CORE * CORES)], ["nodes", "processes"]),
    ],
)
def test_swarm_requests_out_of_range_are_refused_before_any_process(args, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "sw"
    rc, err = _in_process([*args, "--out", str(out)], capsys)
    assert rc == 2
    _one_line_error(err, *words)
    assert not out.exists()  # no swarm file, no run directory: nothing was started


def test_bad_scenario_file_and_conflicting_options(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, err = _in_process(["simulate", "--scenario", str(tmp_path / "nope.toml")], capsys)
    assert rc == 2
    _one_line_error(err, "cannot read")
    rc, err = _in_process(["sweep", "--in-process", "--workers", "2"], capsys)
    assert rc == 2
    _one_line_error(err, "workers", "--in-process")


def test_unreachable_scheduler_is_a_named_error(tmp_path):
    port = agents.free_ports(1)[0]  # nothing listens there
    p = _edccif("sweep", "--scheduler", f"tcp://127.0.0.1:{port}", "--runs", "1", "--steps", "5", "--quiet",
                "--out", "t.csv", "--no-figure", cwd=tmp_path, timeout=120)
    assert p.returncode == 2
    _one_line_error(p.stderr, "scheduler", str(port))


# ----------------------------------------------------------------------------- output paths


@pytest.mark.parametrize("cmd", [["simulate"], ["reliability", "--no-robustness"],
                                 ["sweep", "--in-process", "--runs", "1"]])
def test_out_that_is_a_directory_or_in_a_missing_directory(cmd, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "adir").mkdir()
    rc, err = _in_process([*cmd, "--out", "adir"], capsys)
    assert rc == 2
    _one_line_error(err, "--out", "adir is a directory")
    rc, err = _in_process([*cmd, "--out", "missing/x.out"], capsys)
    assert rc == 2
    _one_line_error(err, "--out", "missing does not exist")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir"]


def test_reproduce_out_that_is_a_file(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "f").write_text("mine")
    rc, err = _in_process(["reproduce", "--out", "f"], capsys)
    assert rc == 2
    _one_line_error(err, "--out", "is a file")
    rc, err = _in_process(["swarm", "--out", "f"], capsys)
    assert rc == 2
    _one_line_error(err, "--out", "is a file")


def test_simulate_keeps_an_existing_file(tmp_path):
    mine = tmp_path / "run.npz"
    mine.write_bytes(b"not edccif's")
    p = _edccif("simulate", "--nodes", "3", cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == ""
    _one_line_error(p.stderr, "run.npz already exists", "--force")
    assert mine.read_bytes() == b"not edccif's"
    # numpy appends .npz: the file it would write is the one checked
    p = _edccif("simulate", "--nodes", "3", "--out", "run", cwd=tmp_path)
    assert p.returncode == 2 and mine.read_bytes() == b"not edccif's"
    p = _edccif("simulate", "--nodes", "3", "--force", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["nodes"] == 3 and mine.read_bytes()[:2] == b"PK"


def test_simulate_keeps_existing_mcap_and_tum_files(tmp_path):
    mine = tmp_path / "r.mcap"
    mine.write_bytes(b"my recording")
    p = _edccif("simulate", "--nodes", "3", "--mcap", "r.mcap", cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == ""
    _one_line_error(p.stderr, "r.mcap already exists", "--force")
    assert mine.read_bytes() == b"my recording" and not (tmp_path / "run.npz").exists()
    (tmp_path / "tum").mkdir()
    (tmp_path / "tum" / "truth.txt").write_text("my track\n")
    p = _edccif("simulate", "--nodes", "3", "--tum", "tum", cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "truth.txt", "--force")
    assert (tmp_path / "tum" / "truth.txt").read_text() == "my track\n"
    p = _edccif("simulate", "--nodes", "3", "--out", "r.npz", "--mcap", "r.npz", "--force", cwd=tmp_path)
    assert p.returncode == 2  # one file named for two outputs is refused, --force or not
    p = _edccif("simulate", "--nodes", "3", "--mcap", "r.mcap", "--tum", "tum", "--force", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert mine.read_bytes() != b"my recording" and (tmp_path / "tum" / "truth.txt").read_text() != "my track\n"


def test_replay_and_preprocess_keep_an_existing_out(tmp_path):
    rec = tmp_path / "r.mcap"
    assert _edccif("simulate", "--nodes", "3", "--mcap", str(rec), cwd=tmp_path).returncode == 0
    mine = tmp_path / "est.npz"
    mine.write_bytes(b"mine")
    p = _edccif("replay", str(rec), "--out", "est", cwd=tmp_path)
    assert p.returncode == 2 and p.stdout == ""
    _one_line_error(p.stderr, "est.npz already exists", "--force")
    assert mine.read_bytes() == b"mine"
    p = _edccif("replay", str(rec), "--out", "est", "--force", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert mine.read_bytes()[:2] == b"PK"
    t = np.arange(60) * 0.05
    track = np.c_[t, np.sin(t), np.cos(t), np.zeros_like(t), np.zeros((60, 3)), np.ones(60)]
    for name in ("truth.txt", "obs.txt"):
        np.savetxt(tmp_path / name, track)
    aligned = tmp_path / "aligned.npz"
    aligned.write_bytes(b"mine")
    args = ["preprocess", "--truth", "truth.txt", "--observer", "obs.txt", "--no-spatial", "--align", "none",
            "--quiet", "--out", "aligned.npz"]
    p = _edccif(*args, cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "aligned.npz already exists", "--force")
    assert aligned.read_bytes() == b"mine"
    p = _edccif(*args, "--force", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert aligned.read_bytes()[:2] == b"PK"


def test_sweep_refuses_a_file_that_is_not_a_sweep_table(tmp_path):
    notes = tmp_path / "existing.txt"
    notes.write_text("my notes\n")
    args = ["sweep", "--in-process", "--quiet", "--runs", "1", "--steps", "5", "--no-figure"]
    p = _edccif(*args, "--out", "existing.txt", cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "existing.txt already exists", "--force")
    assert notes.read_text() == "my notes\n"
    # the API refuses it too, whatever it is
    with pytest.raises(edccif.ParameterError, match="not a sweep table"):
        sweep.run_sweep(sweep.Grid(runs=1, steps=5), notes, scheduler="inprocess", progress=False)
    assert notes.read_text() == "my notes\n"
    # a sweep table is resumed (its rows kept), and its own figure may be replaced
    p = _edccif(*args, "--out", "t.csv", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    first = (tmp_path / "t.csv").read_text()
    p = _edccif("sweep", "--in-process", "--quiet", "--runs", "1", "--steps", "5", "--out", "t.csv",
                "--thresholds", "0.04", "0.08", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert first.splitlines()[1] in (tmp_path / "t.csv").read_text()  # resumed: the first row kept
    assert (tmp_path / "t.png").exists()
    # a markdown file that exists is not replaced without --force
    (tmp_path / "t.md").write_text("mine")
    p = _edccif(*args, "--out", "t.csv", "--markdown", "t.md", cwd=tmp_path)
    assert p.returncode == 2 and (tmp_path / "t.md").read_text() == "mine"
    # --force replaces the non-sweep file
    p = _edccif(*args, "--out", "existing.txt", "--force", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert sweep.is_sweep_table(notes) and len(sweep.read_table(notes)) == 1


def test_reliability_outside_the_repository(tmp_path):
    """Default output in the working directory; an existing report is updated only with --force."""
    args = ["reliability", "--no-robustness", "--soak", "400", "--quiet"]
    p = _edccif(*args, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    report = tmp_path / "reliability.md"
    text = report.read_text()
    assert "<!-- BEGIN soak -->" in text and "400" in p.stdout
    report.write_text(text + "\nmy own notes\n")
    p = _edccif(*args, cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "reliability.md already exists", "--force")
    p = _edccif(*args, "--json", "reliability.md", "--force", cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "json", "distinct")
    p = _edccif(*args, "--force", "--json", "numbers.json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "my own notes" in report.read_text()  # only the blocks were replaced
    assert "soak" in json.loads((tmp_path / "numbers.json").read_text())


def test_reproduce_does_not_replace_an_earlier_reproduction(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    (out / "results.md").write_text("mine")
    p = _edccif("reproduce", "--nodes", "3", "--runs", "1", "--out", str(out), "--no-figures", "--quiet",
                "--no-flights", cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "results.md", "--force")
    assert (out / "results.md").read_text() == "mine"
    p = _edccif("reproduce", "--nodes", "3", "--runs", "1", "--out", str(out), "--no-figures", "--quiet",
                "--no-flights", "--force", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "Table II" in (out / "results.md").read_text()


def test_swarm_out_with_an_earlier_run(tmp_path):
    """`edccif swarm --out DIR` never deletes a file under DIR it did not write."""
    out = tmp_path / "sw"
    (out / "run").mkdir(parents=True)
    mine = out / "run" / "my-notes.txt"
    mine.write_text("mine")
    p = _edccif("swarm", "--nodes", "3", "--steps", "5", "--out", str(out), cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "earlier swarm run", "--force")
    p = _edccif("swarm", "--nodes", "3", "--steps", "5", "--out", str(out), "--force", cwd=tmp_path)
    assert p.returncode == 2
    _one_line_error(p.stderr, "my-notes.txt", "not replacing")
    assert mine.read_text() == "mine"
    # --force removes exactly what a run writes
    mine.unlink()
    for f in ("agent0.log", "agent0.npz", "sensor0.json", "start.json", "agent1-rejoin.json"):
        (out / "run" / f).write_text("old")
    (out / "run" / "ready").mkdir()
    (out / "run" / "ready" / "agent0").write_text("1")
    (out / "swarm.json").write_text("{}")
    agents._clear_previous_run(out, force=True)
    assert list(out.iterdir()) == []
    with pytest.raises(agents.AgentError, match="earlier swarm run"):
        (out / "swarm.json").write_text("{}")
        agents._clear_previous_run(out, force=False)


# ----------------------------------------------------------------------------- broken pipes


@pytest.mark.parametrize(
    "args",
    [
        ["algorithms"],
        ["simulate", "--nodes", "3", "--out", "r.npz"],
        ["reproduce", "--nodes", "3", "--runs", "1", "--no-figures", "--no-flights", "--out", "res"],
    ],
    ids=["algorithms", "simulate", "reproduce"],
)
def test_broken_pipe_ends_quietly(args, tmp_path):
    """The reader of stdout is gone before the command prints (`edccif ... | head -0`):
    exit code 141 (128 + SIGPIPE), no traceback."""
    p = subprocess.Popen([sys.executable, "-m", "edccif", *args], cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()
    _, err = p.communicate(timeout=180)
    assert p.returncode == BROKEN_PIPE_EXIT, err.decode()
    assert "Traceback" not in err.decode() and "Exception" not in err.decode() and "Error" not in err.decode()


def test_broken_pipe_on_replay(tmp_path):
    rec = tmp_path / "rec.mcap"
    sc = edccif.Scenario.paper(nodes=3).replace(steps=20)
    edccif.record("edc-cif", sc, seed=0, mcap=str(rec))
    p = subprocess.Popen([sys.executable, "-m", "edccif", "replay", str(rec)], cwd=tmp_path,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    _, err = p.communicate(timeout=120)
    assert p.returncode == BROKEN_PIPE_EXIT and "Traceback" not in err.decode() and "Error" not in err.decode()


def test_head_on_a_shell_pipe(tmp_path):
    """`edccif algorithms | head -1` under `set -o pipefail`: head's line, then 141 or 0
    (0 when the whole output fitted in the pipe before head exited)."""
    p = subprocess.run(["bash", "-c", f"set -o pipefail; {sys.executable} -m edccif algorithms | head -1"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=60, check=False)
    assert p.stdout == "c-ckf\n" and p.returncode in (0, BROKEN_PIPE_EXIT) and "Traceback" not in p.stderr


# ----------------------------------------------------------------------------- progress without a terminal


def test_sweep_progress_lines_on_a_pipe(tmp_path):
    p = _edccif("sweep", "--in-process", "--runs", "1", "--steps", "5", "--thresholds", "0.02", "0.04",
                "--out", "t.csv", "--no-figure", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("sweep: ")]
    assert lines and lines[-1].startswith("sweep: 2/2 cells (100 %)"), p.stderr
    assert "\r" not in p.stderr


def test_reliability_progress_lines_on_a_pipe(tmp_path):
    p = _edccif("reliability", "--runs", "1", "--nodes", "3", "--out", "r.md", cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("robustness: ")]
    assert lines and lines[-1].split()[1].split("/")[0] == lines[-1].split()[1].split("/")[1], p.stderr


def test_progress_lines_are_throttled(capsys):
    bar = _args.Progress("job", 1000, "items", every_s=3600.0)
    for i in range(1000):
        bar.update(i + 1)
    bar.finish()
    err = capsys.readouterr().err.splitlines()
    assert err == ["job: 1000/1000 items (100 %), 0 s elapsed"]
