"""No import cycles between the modules of any crate or of the Python package:
`scripts/check_imports.py` (pure Python, about a second) run on each, plus its
own self-test and a two-module crate with a cycle, so a checker that finds
nothing (or exits 0 on a cycle) cannot pass."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "check_imports.py"

CRATES = sorted(p.name for p in (ROOT / "crates").iterdir() if (p / "src").is_dir())


def run(*args: str, root: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), "--root", str(root), *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_checker_finds_known_cycles():
    r = run("--self-test")
    assert r.returncode == 0, r.stderr
    assert "self-test passed" in r.stderr


def test_every_crate_is_checked():
    assert {"edccif-core", "edccif-io", "edccif-sim", "edccif-py", "edccif-bench"} <= set(CRATES)


def test_cycle_exits_one(tmp_path):
    """A crate of two modules that use each other: exit 1, the loop and its lines named;
    the same crate with one direction removed: exit 0."""
    src = tmp_path / "crates" / "two" / "src"
    src.mkdir(parents=True)
    (src / "lib.rs").write_text("mod a;\nmod b;\n")
    (src / "a.rs").write_text("use crate::b::B;\npub struct A(pub B);\n")
    (src / "b.rs").write_text("pub struct B;\nfn f(_: crate::a::A) {}\n")
    r = run("--no-python", root=tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "two: 1 import cycle(s)" in r.stdout, r.stdout
    assert "a -> b -> a" in r.stdout and "src/b.rs:2" in r.stdout, r.stdout
    (src / "b.rs").write_text("pub struct B;\n")
    r = run("--no-python", root=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "two: no import cycles (2 modules)" in r.stdout, r.stdout


@pytest.mark.parametrize("crate", CRATES)
def test_crate_has_no_import_cycle(crate):
    r = run("--crate", crate, "--no-python")
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"{crate}: no import cycles" in r.stdout, r.stdout


def test_python_package_has_no_import_cycle():
    r = run("--python-only")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "python package edccif: no import cycles" in r.stdout, r.stdout
