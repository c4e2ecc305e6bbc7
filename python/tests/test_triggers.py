"""Triggers selected by name: the example of docs/triggers.md runs, names and
errors are the documented ones."""

import pathlib
import re

import pytest

import edccif

DOC = pathlib.Path(__file__).resolve().parents[2] / "docs" / "triggers.md"


def test_triggers_doc_example_runs():
    text = DOC.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks, "docs/triggers.md has no python example"
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), {})


def test_trigger_names():
    assert edccif.TRIGGERS == tuple(edccif.triggers())
    assert edccif.TRIGGERS[:4] == ("sod", "sod-hold", "sod-skip", "dynamic")
    for name in ("stochastic", "sod-inflated", "innovation", "always"):
        assert name in edccif.TRIGGERS


def test_unknown_trigger_is_an_option_error(sc4, sim4):
    _, z, x0 = sim4
    with pytest.raises(edccif.UnknownOptionError, match="sod-inflated"):
        edccif.run("edc-cif", sc4, z, x0=x0, trigger="sod-ball")


def test_trigger_on_network_and_monte_carlo(sc4, sim4):
    _, z, x0 = sim4
    net = edccif.Network(sc4, "edc-cif", x0=x0, trigger="innovation", delta=1.0)
    for zk in z[:20]:
        net.step(zk)
    assert net.counters["values_estimator_to_sensor"] == 9 * 4 * 20
    res = edccif.run("edc-cif", sc4, z[:20], x0=x0, trigger="innovation", delta=1.0)
    assert (net.estimates == res.estimates[-1]).all()
    mc = edccif.monte_carlo(sc4.replace(steps=40), ["edc-cif"], runs=2, trigger="stochastic", delta=3.0)
    again = edccif.monte_carlo(sc4.replace(steps=40), ["edc-cif"], runs=2, trigger="stochastic", delta=3.0)
    a, b = mc.to_dict()["variants"][0], again.to_dict()["variants"][0]
    assert a["errors"] == b["errors"] and a["trigger_rate"] == b["trigger_rate"]
