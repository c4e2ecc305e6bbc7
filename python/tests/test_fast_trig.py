"""The opt-in fast trigonometry from Python (`Scenario.replace(fast_trig=True)`).

The fast path changes only the last bits of the sigma-point transforms: on the
paper scenario every row keeps its trigger decisions and every estimate stays
within 1e-9 (relative to the state's scale) of the default path. Speed is measured
in benchmarks (`edccif-timing --fast-trig`), not here.
"""

import numpy as np
import pytest

import edccif


@pytest.fixture(scope="module")
def paper():
    sc = edccif.Scenario.paper(4).replace(steps=120)
    truth, z, x0 = sc.simulate(seed=3)
    return sc, z, x0


def test_default_is_off_and_the_key_round_trips(paper):
    sc, _, _ = paper
    assert sc.fast_trig is False
    fast = sc.replace(fast_trig=True)
    assert fast.fast_trig is True
    assert fast.to_dict()["fast_trig"] is True
    assert fast.replace(fast_trig=False).fast_trig is False


@pytest.mark.parametrize("bad", [1, 1.0, "yes", None])
def test_a_non_bool_is_refused(paper, bad):
    sc, _, _ = paper
    with pytest.raises(edccif.ScenarioError, match="fast_trig"):
        sc.replace(fast_trig=bad)


@pytest.mark.parametrize("algorithm", ["edc-cif", "ed-cif", "ec-ckf", "ec-ukf", "c-ckf"])
def test_fast_path_agrees_with_the_default(paper, algorithm):
    sc, z, x0 = paper
    ref = edccif.run(algorithm, sc, z, x0=x0)
    fast = edccif.run(algorithm, sc.replace(fast_trig=True), z, x0=x0)
    assert np.array_equal(ref.triggered, fast.triggered)
    scale = np.maximum(np.abs(ref.estimates), 1.0)
    assert np.max(np.abs(fast.estimates - ref.estimates) / scale) <= 1e-9
    # The option is really applied: some last bits differ over the run.
    assert not np.array_equal(ref.estimates, fast.estimates)
