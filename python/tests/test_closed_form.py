"""The closed form of the ET-CIF's untriggered contribution from Python, on by
default (`untriggered_closed_form`: a scenario key, a run option, an `ETCIF`
argument; `False` is the paper's stable form).

The closed form equals the paper's stable form up to rounding: on the paper
scenario the ET-CIF rows keep their trigger decisions and every estimate stays
within 1e-9 (relative to the state's scale) of the stable form; the
covariance-form rows ignore it (bit for bit). Speed is measured in benchmarks
(`edccif-timing --stable-form`), not here.
"""

import numpy as np
import pytest

import edccif
from edccif import models


@pytest.fixture(scope="module")
def paper():
    # the reference: the paper's stable form
    sc = edccif.Scenario.paper(4).replace(steps=120, untriggered_closed_form=False)
    truth, z, x0 = sc.simulate(seed=3)
    return sc, z, x0


def close(a, b):
    scale = np.maximum(np.abs(a), 1.0)
    return np.max(np.abs(b - a) / scale) <= 1e-9


def test_default_is_on_and_the_key_round_trips(paper):
    sc, _, _ = paper
    default = edccif.Scenario.paper(4)
    assert default.untriggered_closed_form is True
    assert "untriggered_closed_form" not in default.to_dict()
    assert sc.untriggered_closed_form is False
    assert sc.to_dict()["untriggered_closed_form"] is False
    on = sc.replace(untriggered_closed_form=True)
    assert on.untriggered_closed_form is True
    assert on.replace(untriggered_closed_form=False).untriggered_closed_form is False


@pytest.mark.parametrize("bad", [1, 1.0, "yes"])
def test_a_non_bool_is_refused(paper, bad):
    sc, z, x0 = paper
    with pytest.raises(edccif.ScenarioError, match="untriggered_closed_form"):
        sc.replace(untriggered_closed_form=bad)
    with pytest.raises(edccif.ParameterError, match="untriggered_closed_form"):
        edccif.run("edc-cif", sc, z, x0=x0, untriggered_closed_form=bad)


@pytest.mark.parametrize("algorithm", ["edc-cif", "ed-cif", "ec-ckf", "ec-ukf"])
def test_closed_form_agrees_with_the_stable_form(paper, algorithm):
    sc, z, x0 = paper
    ref = edccif.run(algorithm, sc, z, x0=x0, sigma1=0.05, sigma2=0.05)
    via_scenario = edccif.run(
        algorithm, sc.replace(untriggered_closed_form=True), z, x0=x0, sigma1=0.05, sigma2=0.05
    )
    via_option = edccif.run(
        algorithm, sc, z, x0=x0, sigma1=0.05, sigma2=0.05, untriggered_closed_form=True
    )
    assert np.array_equal(via_scenario.estimates, via_option.estimates)
    assert np.array_equal(ref.triggered, via_option.triggered)
    assert not ref.triggered.all()
    if algorithm.endswith("cif"):
        assert close(ref.estimates, via_option.estimates)
        # The option is really applied: some last bits differ over the run.
        assert not np.array_equal(ref.estimates, via_option.estimates)
    else:
        assert np.array_equal(ref.estimates, via_option.estimates)


def test_single_etcif_filter(paper):
    sc, z, x0 = paper
    mo, me = sc.motion, sc.measurement
    ct = models.CoordinatedTurn(mo["q1"], mo["q2"])
    rpa = models.RangePitchAzimuth(sc.sensors[0], me["sigma_r"], me["sigma_a"])
    kw = dict(dt=sc.dt, sigma1=0.05, sigma2=0.05)
    a = edccif.ETCIF(ct, rpa, x0, sc.p0, untriggered_closed_form=False, **kw)
    b = edccif.ETCIF(ct, rpa, x0, sc.p0, **kw)  # the default: closed form
    quiet = 0
    for k in range(60):
        a.predict()
        b.predict()
        sa, sb = a.update(z[k, 0]), b.update(z[k, 0])
        assert sa == sb
        quiet += sa is False
        assert close(a.x, b.x) and close(a.P, b.P)
    assert quiet > 0
    assert not np.array_equal(a.x, b.x)
    with pytest.raises(TypeError):
        edccif.ETCIF(ct, rpa, x0, sc.p0, untriggered_closed_form="yes")
