"""Every Python example of docs/guide.md runs (each block in a fresh namespace,
from a temporary directory). The Rust blocks of the guide are doctests of
`edccif_sim::guide` (run by `cargo test -p edccif-sim --doc`); the last test
checks that hook is in place."""

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guide.md"


def blocks(lang):
    return re.findall(rf"^```{lang}\n(.*?)^```", GUIDE.read_text(), flags=re.S | re.M)


PY = blocks("python")


def test_guide_has_its_examples():
    # a single CKF with timestamps, the bearing-only swarm, the mixed network, the scenario
    assert len(PY) >= 4
    assert len(blocks("rust")) >= 3


@pytest.mark.parametrize("i", range(len(PY)))
def test_python_example_runs(i, tmp_path, capsys):
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        exec(compile(PY[i], f"{GUIDE}:python block {i}", "exec"), {"__name__": "__guide__"})
    finally:
        os.chdir(cwd)


def test_rust_examples_are_doctests():
    lib = (ROOT / "crates" / "edccif-sim" / "src" / "lib.rs").read_text()
    assert 'include_str!("../../../docs/guide.md")' in lib
