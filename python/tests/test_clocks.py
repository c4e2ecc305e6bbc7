"""Clocks in the preprocessing pipeline and real flights from one's own files:
the docs/realworld.md example runs; `edccif preprocess --align/--offset/
--duplicates` and `edccif reproduce --flight` end to end, with their bad values
refused in one line (exit 2) before any work."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import edccif

DOC = Path(__file__).resolve().parents[2] / "docs" / "realworld.md"


def _edccif(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "edccif", *args], cwd=cwd, capture_output=True, text=True, check=False
    )


def test_realworld_doc_example_runs(tmp_path):
    blocks = re.findall(r"^```python\n(.*?)^```", DOC.read_text(encoding="utf-8"), flags=re.S | re.M)
    assert blocks, "docs/realworld.md has no python example"
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        for block in blocks:
            exec(compile(block, str(DOC), "exec"), {"__name__": "__doc__"})
    finally:
        os.chdir(cwd)


def _path(s):
    return np.stack([np.cos(0.6 * s) + 0.3 * np.sin(1.7 * s), np.sin(0.4 * s), 1.0 + 0.2 * np.sin(0.9 * s)],
                    axis=-1)


def _files(d, delay=0.5, repeat=None):
    """truth.txt (120 Hz, its clock at 100 s) and cam{i}.txt (30 Hz, `delay` s
    late, epoch clocks, own frames); cam1 repeats the stamp of its sample
    `repeat`."""
    s = np.arange(0.0, 20.0, 1 / 120)
    edccif.write_tum(d / "truth.txt", 100.0 + s, _path(s))
    rng = np.random.default_rng(1)
    offsets = []
    for i, (angle, shift) in enumerate([(30.0, 2.0), (-50.0, -1.0)]):
        a = np.radians(angle)
        rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        sc = np.arange(delay, 20.0, 1 / 30)
        p = (_path(sc) - [shift, 0.0, 0.0]) @ rot + 0.005 * rng.standard_normal((sc.size, 3))
        t = 1.7e9 + 10.0 * i + sc
        if i == 1 and repeat is not None:
            t[repeat + 1] = t[repeat]
        edccif.write_tum(d / f"cam{i}.txt", t, p)
        offsets.append(100.0 - 1.7e9 - 10.0 * i)
    return offsets


def test_preprocess_estimates_reports_and_warns(tmp_path):
    truth = _files(tmp_path)
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt", "--out", "a.npz",
                cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    clock = json.loads(p.stdout)["report"]["clock"]
    assert clock["align"] == "estimate" and clock["sources"] == ["estimated"] * 2
    for got, want in zip(clock["offsets_s"], truth):
        assert abs(got - want) < 1 / 30
    assert "cam0.txt: clock offset" in p.stderr and "(estimated)" in p.stderr
    assert "warning" not in p.stderr
    # the start alignment is 0.5 s off: warned about, per observer
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt", "--align", "start",
                cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    warns = [ln for ln in p.stderr.splitlines() if ln.startswith("edccif: warning: ")]
    assert len(warns) == 2 and "observer 0: the alignment residual" in warns[0], p.stderr
    # given offsets by stem and by index
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt", "--align", "start",
                "--offset", f"cam0={truth[0]}", "--offset", f"1={truth[1]}", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    clock = json.loads(p.stdout)["report"]["clock"]
    assert clock["sources"] == ["given", "given"] and clock["offsets_s"] == truth
    assert "warning" not in p.stderr


def test_preprocess_duplicates(tmp_path):
    _files(tmp_path, repeat=100)
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    report = json.loads(p.stdout)["report"]
    assert [d["dropped"] for d in report["duplicates"]] == [0, 0, 1]
    assert "cam1.txt" in p.stderr and "1 repeated stamp(s) dropped" in p.stderr
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt", "--duplicates",
                "refuse", "--out", "a.npz", cwd=tmp_path)
    assert p.returncode == 2
    assert "observer 1: t[101]" in p.stderr and "repeats t[100]" in p.stderr, p.stderr
    assert not (tmp_path / "a.npz").exists()
    # the library: the same, and a UserWarning for a bad alignment
    with pytest.raises(edccif.EdccifError, match="observer 1: t\\[101\\]"):
        edccif.preprocess(tmp_path / "truth.txt", [tmp_path / "cam0.txt", tmp_path / "cam1.txt"],
                          duplicates="refuse")
    with pytest.warns(UserWarning, match="alignment residual"):
        edccif.preprocess(tmp_path / "truth.txt", [tmp_path / "cam0.txt"], align="start")


@pytest.mark.parametrize(
    "args, message",
    [
        (["--offset", "cam0"], "expected STREAM=SECONDS"),
        (["--offset", "cam0=soon"], "expected STREAM=SECONDS"),
        (["--offset", "cam0=nan"], "expected STREAM=SECONDS"),
        (["--offset-window", "-1"], "expected a finite number >= 0"),
        (["--residual-factor", "0"], "expected a finite number > 0"),
        (["--rate", "inf"], "expected a finite number > 0"),
        (["--align", "sideways"], "invalid choice"),
        (["--duplicates", "keep"], "invalid choice"),
        (["--offset", "cam7=1.0"], "offsets: 'cam7' is not an observer"),
        (["--offset", "cam0=1", "--offset", "cam0=2"], "--offset: cam0 given twice"),
    ],
)
def test_preprocess_bad_values_are_one_line_errors(tmp_path, args, message):
    _files(tmp_path)
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", *args, cwd=tmp_path)
    assert p.returncode == 2, p.stderr
    assert message in p.stderr, p.stderr
    assert "Traceback" not in p.stderr


def test_preprocess_missing_file_is_refused_first(tmp_path):
    _files(tmp_path)
    p = _edccif("preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "nope.txt", cwd=tmp_path)
    assert p.returncode == 2 and "'nope.txt' is not a file" in p.stderr, p.stderr


def _flight(path, repeat=False):
    t = 1.6e9 + np.arange(0.0, 12.0, 0.01)
    if repeat:
        t[501] = t[500]
    s = t - t[0]
    a = 0.4 * s + 0.2 * np.sin(0.7 * s)
    edccif.write_tum(path, t, np.stack([2 * np.cos(a), 2 * np.sin(a), 1 + 0.02 * s], axis=1))


def test_reproduce_takes_any_ground_truth_file(tmp_path):
    _flight(tmp_path / "lab_run.txt", repeat=True)
    out = tmp_path / "res"
    p = _edccif("reproduce", "--nodes", "3", "--runs", "1", "--out", str(out), "--no-figures", "--quiet",
                "--flight", "lab_run.txt", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stdout == ""  # --quiet: the tables are in OUT/results.md only
    md = (out / "results.md").read_text()
    assert "`lab_run.txt` (lab_run): 1199 samples" in md
    assert "1 sample(s) with a repeated timestamp dropped" in md
    assert "edccif reproduce --flight lab_run.txt" in md
    data = json.loads((out / "results.json").read_text())
    assert [f["flight"] for f in data["flights"]["flights"]] == ["lab_run"]
    assert data["flights"]["flights"][0]["duplicates_dropped"] == 1


@pytest.mark.parametrize(
    "args, message",
    [
        (["--flight", "nope.txt"], "'nope.txt' is not a file"),
        (["--flight", "lab_run.txt", "--no-flights"], "--flight and --no-flights"),
        (["--flight", "lab_run.txt", "--duplicates", "refuse"], "t[501]"),
        (["--flight", "notes.txt"], "EuRoC"),
    ],
)
def test_reproduce_refuses_bad_flights_before_any_study(tmp_path, args, message):
    _flight(tmp_path / "lab_run.txt", repeat=True)
    (tmp_path / "notes.txt").write_text("# nothing here\n")
    out = tmp_path / "res"
    p = _edccif("reproduce", "--nodes", "3", "--runs", "1", "--out", str(out), "--no-figures", "--quiet", *args,
                cwd=tmp_path)
    assert p.returncode == 2, p.stderr
    assert message in p.stderr, p.stderr
    assert not out.exists()


# ----------------------------------------------------------------------------- progress


def test_preprocess_reports_progress_to_a_callback(tmp_path):
    _files(tmp_path)
    seen = []
    out = edccif.preprocess(tmp_path / "truth.txt", [tmp_path / "cam0.txt", tmp_path / "cam1.txt"],
                            progress=lambda done, total: seen.append((done, total)))
    assert seen, "the callback was never called"
    totals = {t for _, t in seen}
    assert len(totals) == 1, totals  # the work is declared once
    total = totals.pop()
    # 2 observers: their clocks (the offsets tried, ±2 s at 30 Hz: 121 or 123
    # by the median frame's last bit, and one each), spatial alignment (one
    # each), the truth's downsampling, 3 interpolations.
    assert 2 * (121 + 1) + 2 + 1 + 3 <= total <= 2 * (123 + 1) + 2 + 1 + 3, total
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)
    assert seen[-1] == (total, total)
    plain = edccif.preprocess(tmp_path / "truth.txt", [tmp_path / "cam0.txt", tmp_path / "cam1.txt"])
    assert np.array_equal(out["z"], plain["z"], equal_nan=True) and out["report"] == plain["report"]


def test_a_preprocess_callback_that_raises_stops_it_with_its_exception(tmp_path):
    _files(tmp_path)

    def broken(done, total):
        raise RuntimeError("the callback failed")

    with pytest.raises(RuntimeError, match="the callback failed"):
        edccif.preprocess(tmp_path / "truth.txt", [tmp_path / "cam0.txt", tmp_path / "cam1.txt"], progress=broken)
    with pytest.raises(edccif.ArgumentTypeError, match="progress: expected True, False, None or a callable"):
        edccif.preprocess(tmp_path / "truth.txt", [tmp_path / "cam0.txt"], progress="yes")


def test_preprocess_cli_prints_progress_lines_on_a_pipe(tmp_path, monkeypatch, capsys):
    import functools

    from edccif import _progress
    from edccif.cli import main

    _files(tmp_path)
    monkeypatch.chdir(tmp_path)
    # A line at every report instead of every 5 s (the extension looks the reporter up per call).
    monkeypatch.setattr(_progress, "Reporter", functools.partial(_progress.Reporter, every=0.0))
    assert main(["preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt"]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("preprocess: ")]
    assert lines and " units (100 %)" in lines[-1], lines
    done, total = lines[-1].split()[1].split("/")
    assert done == total and int(total) > 200, lines
    assert main(["preprocess", "--truth", "truth.txt", "--observer", "cam0.txt", "cam1.txt", "--quiet"]) == 0
    assert "preprocess: " not in capsys.readouterr().err
