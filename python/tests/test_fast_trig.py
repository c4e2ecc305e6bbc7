"""The fast trigonometry from Python, on by default (`Scenario.replace(fast_trig=False)`
and the models' `fast_trig=False` give the platform libm's, bit for bit).

The fast path changes only the last bits of the sigma-point transforms: on the
paper scenario every row keeps its trigger decisions and every estimate stays
within 1e-9 (relative to the state's scale) of the reference path. Speed is
measured in benchmarks (`edccif-timing --libm-trig`), not here.
"""

import numpy as np
import pytest

import edccif
from edccif import models


@pytest.fixture(scope="module")
def paper():
    # the reference: the platform libm's trigonometry
    sc = edccif.Scenario.paper(4).replace(steps=120, fast_trig=False)
    truth, z, x0 = sc.simulate(seed=3)
    return sc, z, x0


def test_default_is_on_and_the_key_round_trips(paper):
    sc, _, _ = paper
    default = edccif.Scenario.paper(4)
    assert default.fast_trig is True
    assert "fast_trig" not in default.to_dict()
    assert sc.fast_trig is False
    assert sc.to_dict()["fast_trig"] is False
    fast = sc.replace(fast_trig=True)
    assert fast.fast_trig is True
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


def test_catalogue_models_take_fast_trig_and_equal_the_scenario_path(paper):
    # The models' `fast_trig=True` is the same switch as the scenario key: one node's
    # single CKF with fast models equals that node in the row's local-only run of
    # the fast scenario, bit for bit, and differs from the reference (libm) models.
    sc, z, x0 = paper
    mo, me = sc.motion, sc.measurement
    res = edccif.run("c-ckf", sc.replace(fast_trig=True), z, x0=x0, fusion="local")
    filters = {}
    for on in (False, True):
        ct = models.CoordinatedTurn(mo["q1"], mo["q2"], fast_trig=on)
        rpa = models.RangePitchAzimuth(sc.sensors[1], me["sigma_r"], me["sigma_a"], fast_trig=on)
        filters[on] = edccif.CKF(ct, rpa, x0, sc.p0, dt=sc.dt)
    for k in range(len(z)):
        zk = None if np.isnan(z[k, 1]).any() else z[k, 1]
        for f in filters.values():
            f.predict()
            f.update(zk)
        assert np.array_equal(filters[True].x, res.estimates[k, 1]), k
        assert np.array_equal(filters[True].P, res.covariances[k, 1]), k
    fast, ref = filters[True].x, filters[False].x
    assert not np.array_equal(fast, ref)
    assert np.max(np.abs(fast - ref) / np.maximum(np.abs(ref), 1.0)) <= 1e-9


def test_planar_models_take_fast_trig():
    # Range-bearing and bearing-only nodes with the planar turn: the fast models
    # stay within 1e-9 (relative to the state's scale) of the default ones over a
    # 60-step run, and the option is really applied.
    x0 = np.array([10.0, 0.0, 0.0, 2.0, 0.2])
    est = {}
    for on in (False, True):
        ct2 = models.CoordinatedTurn2D(0.1, 1e-3, fast_trig=on)
        truth = [x0]
        for _ in range(60):
            truth.append(ct2.f(truth[-1][None], 0.1)[0])
        for sensor in (
            models.RangeBearing([0.0, -20.0], 0.2, 0.005, fast_trig=on),
            models.BearingOnly([-15.0, 5.0], 0.005, fast_trig=on),
        ):
            zs = sensor.h(np.array(truth[1:]))
            f = edccif.ETCIF(ct2, sensor, x0 + 0.1, np.eye(5) * 0.1, dt=0.1, delta=1e-6)
            for zk in zs:
                f.predict()
                f.update(zk)
            est[on, type(sensor).__name__] = f.x
    for name in ("RangeBearing", "BearingOnly"):
        fast, ref = est[True, name], est[False, name]
        assert not np.array_equal(fast, ref), name
        assert np.max(np.abs(fast - ref) / np.maximum(np.abs(ref), 1.0)) <= 1e-9, name


def test_model_fast_trig_repr_and_bad_values():
    ct = models.CoordinatedTurn(0.5, 1e-4, fast_trig=False)
    assert repr(ct).endswith("fast_trig=False)")
    assert "fast_trig" not in repr(models.CoordinatedTurn(0.5, 1e-4))
    assert "fast_trig" not in repr(models.CoordinatedTurn(0.5, 1e-4, fast_trig=True))
    assert "fast_trig=False" in repr(models.BearingOnly([0.0, 0.0], 0.01, fast_trig=False))
    with pytest.raises(TypeError):
        models.RangePitchAzimuth([0.0, 0.0, 0.0], 0.1, 0.01, fast_trig="yes")
    with pytest.raises(TypeError):
        models.CoordinatedTurn(0.5, 1e-4, True)  # keyword-only
