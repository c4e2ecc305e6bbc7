"""scripts/front.py (the front section of docs/results.md) on a tiny grid: the
section is spliced after the marker, the rest of the file is kept, and a second
run replaces the section instead of appending another."""

import importlib.util
import pathlib

from edccif.sweep import run_sweep

SCRIPT = pathlib.Path(__file__).resolve().parents[2] / "scripts" / "front.py"


def _front():
    spec = importlib.util.spec_from_file_location("front", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_front_section_is_spliced_and_replaced(tmp_path):
    front = _front()
    front.TRIGGERS = ["sod", "innovation"]
    front.THRESHOLDS = {"sod": [0.04], "innovation": [1.2]}
    rows = run_sweep(front.grid(runs=2, nodes=[4], steps=30), scheduler="inprocess", progress=False)
    assert [(r["trigger"], r["threshold"]) for r in rows] == [("sod", 0.04), ("innovation", 1.2)]
    text = front.section(rows, 2, 1.0, "figures/front.png", "python scripts/front.py --runs 2")
    assert text.startswith(front.MARKER)
    assert "paper's operating point" in text
    assert "`innovation`" in text
    results = tmp_path / "results.md"
    results.write_text("# Results\n\n| a |\n|---|\n| 1 |\n", encoding="utf-8")
    front.splice(results, text)
    front.splice(results, text)
    out = results.read_text(encoding="utf-8")
    assert out.startswith("# Results\n\n| a |")
    assert out.count(front.MARKER) == 1
    assert out.endswith(text)
