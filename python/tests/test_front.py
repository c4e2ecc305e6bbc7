"""scripts/front.py (the beyond-the-paper sections of docs/results.md: the
trigger front, the fusion front and the N study) on tiny grids: each section is spliced after the
marker, the rest of the file is kept, and a second run replaces the section
instead of appending another."""

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


def test_fusion_front_and_n_study_render(tmp_path):
    # the fusion rules' front (default and planar scenarios, the bounds) and the
    # accuracy-against-N section on tiny grids
    front = _front()
    front.RULES = ["ci", "split-ci"]
    front.DET_RULES = []
    front.FUSION_TRIGGERS = ["sod", "always"]
    front.FUSION_THRESHOLDS = {"sod": [0.04]}
    front.PLANAR_THRESHOLDS = {"sod": [0.02], "always": [None]}
    rows = []
    for g in front.fusion_grids(runs=2, nodes=[4], steps=20):
        rows += run_sweep(g, scheduler="inprocess", progress=False)
    assert {r["scenario"] for r in rows} == {"paper-4", front.PLANAR}
    assert {r["fusion"] for r in rows} >= {"ci", "split-ci"}
    text = "\n".join(front.fusion_section(rows, 2, {"fusion": 1.0}, "python scripts/front.py --fusion-runs 2"))
    assert "## Beyond the paper: the fusion rules" in text and "centralised filter" in text
    assert "`split-ci`" in text and "| complete | dc-cif |" in text
    assert "fewer runs than the 100" in text and "--fusion-runs 2" in text
    # the gap to DC-CIF in numbers, one line per scenario
    why = front.why(rows)
    assert len(why) == 2 and all("centralised filter" in w and " % " in w for w in why)
    front.plot_fusion(rows, tmp_path / "f.png", ["paper-4", front.PLANAR])
    assert (tmp_path / "f.png").stat().st_size > 1000
    front.N_RULES = ["ci", "ici", "ci-trace"]
    # the optimised rules and EC-CKF stop at costly_max nodes
    capped = [c for g in front.n_grids(runs=2, ns=[8, 16], steps=10, costly_max=8) for c in g.cells()]
    assert {(c.nodes, c.algorithm, c.fusion) for c in capped if c.nodes == 16} == {
        (16, "edc-cif", "ci"), (16, "edc-cif", "ici")}
    assert {(c.algorithm, c.fusion) for c in capped if c.nodes == 8} == {
        ("edc-cif", "ci"), ("edc-cif", "ici"), ("edc-cif", "ci-trace"), ("ec-ckf", None)}
    front.N_RULES = ["ci", "ici"]
    nrows = []
    for g in front.n_grids(runs=2, ns=[8], steps=10):
        nrows += run_sweep(g, scheduler="inprocess", progress=False)
    assert {(r["algorithm"], r["fusion"]) for r in nrows} == {("edc-cif", "ci"), ("edc-cif", "ici"), ("ec-ckf", None)}
    assert {r["topology"].split(":")[0] for r in nrows} == {"ring", "random-geometric"}
    ntext = "\n".join(front.n_section(nrows, {"n": 1.0}, 2, 64))
    assert "N = 8" in ntext and "ec-ckf (adequate L)" in ntext and "up to N = 64" in ntext
    front.plot_n(nrows, tmp_path / "n.png")
    assert (tmp_path / "n.png").stat().st_size > 1000
    # both spliced after the trigger front at the end of a results.md, replaced (not appended) by a second run
    doc = tmp_path / "results.md"
    doc.write_text("# Results\n\n| a |\n", encoding="utf-8")
    gen = f"{front.MARKER}; do not edit below by hand -->\n## The trigger front\n" + front.fusion_results_section(
        rows, nrows, {"fusion": 2, "n": 2}, {"fusion": 1.0, "n": 1.0}, "python scripts/front.py", 64)
    front.splice(doc, gen)
    front.splice(doc, gen)
    out = doc.read_text(encoding="utf-8")
    assert out.startswith("# Results\n\n| a |\n") and out.count(front.MARKER) == 1 and out.endswith(gen)
    assert "## Beyond the paper: the fusion rules against the send-everything bound" in out
    assert "## Beyond the paper: accuracy against the number of nodes" in out
    assert "![fusion front](figures/front_fusion.png)" in out and "![accuracy against N](figures/accuracy_n.png)" in out
