"""The figures say what they show: node count and runs in every title, curves that
coincide named and drawn distinguishably, a legend and units on every panel, the
front's thresholds labelled and its scale set by the points that are not
over-confident."""

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from edccif import plots, sweep  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture
def figures(monkeypatch):
    """The figures the plotting functions make, kept open instead of closed."""
    kept = []

    def save(fig, path):
        # what plots._save does before writing the file
        plots.fit_titles(fig)
        fig.tight_layout()
        kept.append(fig)
        return path

    close = plt.close
    monkeypatch.setattr(plots, "_save", save)
    monkeypatch.setattr(plt, "close", lambda fig=None: kept.append(fig) if fig is not None else None)
    yield kept
    close("all")


def _legend_texts(ax):
    leg = ax.get_legend()
    assert leg is not None, ax.get_title()
    return [t.get_text() for t in leg.get_texts()]


def test_coincident_groups():
    a = np.linspace(0.0, 1.0, 50)
    groups = plots.coincident_groups({"EC-EKF": a, "EC-UKF": a.copy(), "EC-CKF": a + 0.0, "D-CIF": a + 1e-3})
    assert groups == [["EC-EKF", "EC-UKF", "EC-CKF"], ["D-CIF"]]
    assert plots.coincidence_note(groups) == "EC-EKF = EC-UKF = EC-CKF"
    assert plots.coincidence_note([["A"], ["B"]]) == ""


def test_rmse_over_time_names_the_curves_under_others(figures, tmp_path):
    t = np.linspace(0.1, 1.0, 20)
    pos = {"C-CKF": t, "EC-EKF": 2 * t, "EC-UKF": 2 * t, "EC-CKF": 2 * t, "D-CIF": 3 * t, "DC-CIF": 3 * t}
    vel = {k: v + 1 for k, v in pos.items()}
    plots.rmse_over_time(pos, vel, 0.1, tmp_path / "r.png", context="paper scenario, 4 nodes, ring; 100 runs (seed 0)")
    fig = figures[0]
    top, bottom = fig.axes
    title = top.get_title()
    assert "4 nodes" in title and "100 runs" in title
    assert "EC-EKF = EC-UKF = EC-CKF" in title and "D-CIF = DC-CIF" in title
    texts = _legend_texts(top)
    assert len(texts) == 6 and "EC-UKF (= EC-EKF, EC-CKF)" in texts and "C-CKF" in texts
    # the coinciding curves differ in line style or marker
    lines = {ln.get_label(): ln for ln in top.get_lines()}
    styles = {(lines[k].get_linestyle(), lines[k].get_marker()) for k in ("EC-EKF (= EC-UKF, EC-CKF)",
                                                                          "EC-UKF (= EC-EKF, EC-CKF)",
                                                                          "EC-CKF (= EC-EKF, EC-UKF)")}
    assert len(styles) == 3
    assert "(m)" in top.get_ylabel() and "(m/s)" in bottom.get_ylabel() and "(s)" in bottom.get_xlabel()


def test_rmse_over_time_groups_curves_that_overlap_at_the_figures_size(figures, tmp_path):
    # EC-EKF 1 % of the axis away from EC-CKF: drawn as one group, marked "≈";
    # DEC-CKF 10 % away: a curve of its own
    t = np.linspace(0.1, 1.0, 20)
    pos = {"C-CKF": t, "EC-EKF": 2 * t + 0.019, "EC-CKF": 2 * t, "DEC-CKF": 2 * t + 0.19}
    vel = {k: v + 1 for k, v in pos.items()}
    plots.rmse_over_time(pos, vel, 0.1, tmp_path / "r.png", context="4 nodes; 100 runs")
    top = figures[0].axes[0]
    assert "EC-EKF ≈ EC-CKF" in top.get_title() and "DEC-CKF" not in top.get_title()
    texts = _legend_texts(top)
    assert "EC-EKF (≈ EC-CKF)" in texts and "DEC-CKF" in texts


def test_long_names_break_the_title_into_lines_inside_the_figure(figures, tmp_path):
    # eight variants with long labels, pairwise on top of each other: the
    # coincidence note alone is several times the figure's width
    t = np.linspace(0.1, 1.0, 20)
    names = [f"EDC-CIF sod-hold delta={d} gate=chi2-0.999 fusion=trace" for d in (0.01, 0.02, 0.04, 0.08)]
    pos = {}
    for i, n in enumerate(names):
        pos[n] = (i + 1) * t
        pos[n + " (copy)"] = (i + 1) * t
    vel = {k: v + 1 for k, v in pos.items()}
    context = "a scenario with a long name, 12 nodes, random geometric graph; 100 runs (seed 0)"
    plots.rmse_over_time(pos, vel, 0.1, tmp_path / "r.png", context=context)
    fig = figures[0]
    top = fig.axes[0]
    title = top.get_title()
    assert title.count("\n") >= 4, title
    # nothing lost: every pair is named, whole, and the context is there
    flat = " ".join(title.split())
    for n in names:
        assert f"{n} = {n} (copy)" in flat
    assert context in flat
    # every line lies inside the figure
    fig.canvas.draw()
    box = top.title.get_window_extent(fig.canvas.get_renderer())
    assert box.x0 >= 0 and box.x1 <= fig.bbox.width, (box, fig.bbox.width)


def test_delta_sweep_has_a_legend_and_units_on_both_panels(figures, tmp_path):
    deltas = [0.01, 0.04, 0.16]
    rmse = {"EDC-CIF": [0.1, 0.11, 0.13], "ED-CIF": [0.1, 0.12, 0.15], "DEC-CKF": [0.2, 0.2, 0.3]}
    rate = {"EDC-CIF": [0.9, 0.5, 0.2], "ED-CIF": [0.9, 0.5, 0.2], "DEC-CKF": [0.8, 0.6, 0.3]}
    plots.delta_sweep(deltas, rmse, rate, tmp_path / "d.png", context="paper scenario, 4 nodes, 100 runs per δ")
    fig = figures[0]
    left, right = fig.axes
    assert "4 nodes" in fig._suptitle.get_text() and "100 runs" in fig._suptitle.get_text()
    for ax in (left, right):
        assert "δ (" in ax.get_xlabel() and "m²" in ax.get_xlabel()
        assert len(_legend_texts(ax)) == 3
    assert "EDC-CIF (= ED-CIF)" in _legend_texts(right) and "EDC-CIF" in _legend_texts(left)
    assert "(%)" in right.get_ylabel() and "(m)" in left.get_ylabel()


def test_front_labels_thresholds_and_runs_and_clips_the_over_confident(figures, tmp_path):
    rows = sweep.read_table(ROOT / "docs" / "front" / "front.csv")
    sweep.plot_front(rows, tmp_path / "front.png")
    fig = [f for f in figures if f is not None][0]
    axes = fig.axes
    assert len(axes) >= 2
    for ax in axes:
        assert "nodes" in ax.get_title() and "runs per point" in ax.get_title()
        texts = [t.get_text() for t in ax.texts]
        assert any(t.startswith("0.04 | ") for t in texts)  # the threshold beside its point
        # sod-hold's over-confident points (up to 1.3 m) do not set the scale
        top = ax.get_ylim()[1]
        assert top < 0.6, top
        assert any("off scale" in t and "sod-hold" in t for t in texts)
    pts = [p for p in sweep.aggregate(rows) if p["nodes"] == 4]
    top, clipped = sweep.front_scale(pts)
    assert "edc-cif / sod-hold" in clipped
    assert all(p["pos_rmse"] <= top for p in pts if p["nees"] is None or p["nees"] <= p["nees_hi"])
