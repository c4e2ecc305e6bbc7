"""edccif.models: the catalogue's batch evaluators against their equations, custom
models from callables, and the errors of every entry point."""

import numpy as np
import pytest

import edccif
from edccif import models

RNG = np.random.default_rng(7)


def ct_numpy(X, dt):
    """ALGORITHM.md §1 coordinated turn, one state per row (|ω| > 1e-9 here)."""
    out = X.copy()
    w = X[:, 6]
    s, c = np.sin(w * dt), np.cos(w * dt)
    vx, vy = X[:, 3], X[:, 4]
    out[:, 0] = X[:, 0] + s / w * vx - (1 - c) / w * vy
    out[:, 1] = X[:, 1] + (1 - c) / w * vx + s / w * vy
    out[:, 2] = X[:, 2] + dt * X[:, 5]
    out[:, 3] = c * vx - s * vy
    out[:, 4] = s * vx + c * vy
    return out


def test_coordinated_turn_batch_matches_equations():
    ct = models.CoordinatedTurn(0.5, 1e-4)
    X = RNG.normal(size=(14, 7))
    X[:, 6] = RNG.uniform(0.1, 0.5, size=14)
    assert ct.n == 7
    np.testing.assert_allclose(ct.f(X, 0.1), ct_numpy(X, 0.1), rtol=0, atol=1e-12)
    Q = ct.Q(0.1)
    assert Q.shape == (7, 7)
    np.testing.assert_allclose(Q[0, 0], 0.5 * 0.1**3 / 3, rtol=1e-14)
    np.testing.assert_allclose(Q[0, 3], 0.5 * 0.1**2 / 2, rtol=1e-14)
    np.testing.assert_allclose(Q[6, 6], 1e-4 * 0.1, rtol=1e-14)
    # analytic Jacobian against central differences of the batch evaluator
    x = X[0]
    J = ct.jacobian(x, 0.1)
    eps = 1e-6
    fd = np.column_stack(
        [(ct.f((x + eps * e)[None], 0.1)[0] - ct.f((x - eps * e)[None], 0.1)[0]) / (2 * eps) for e in np.eye(7)]
    )
    np.testing.assert_allclose(J, fd, atol=1e-7)


def test_constant_velocity_and_position():
    cv = models.ConstantVelocity(3, 0.2)
    X = RNG.normal(size=(5, 6))
    expect = X.copy()
    expect[:, :3] += 0.5 * X[:, 3:]
    np.testing.assert_array_equal(cv.f(X, 0.5), expect)
    pos = models.Position([0.1, 0.2, 0.3])
    assert (pos.m, pos.n, pos.min_n, pos.angles) == (3, None, 3, [])
    np.testing.assert_array_equal(pos.h(X), X[:, :3])
    np.testing.assert_allclose(pos.R, np.diag([0.01, 0.04, 0.09]), rtol=1e-15)
    # the same sensor measures a 7-state target too
    np.testing.assert_array_equal(pos.h(np.ones((2, 7))), np.ones((2, 3)))


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_constant_velocity_and_acceleration_every_dimension(dim):
    dt, q = 0.4, 0.3
    cv = models.ConstantVelocity(dim, q)
    ca = models.ConstantAcceleration(dim, q)
    assert (cv.n, ca.n) == (2 * dim, 3 * dim)
    X = RNG.normal(size=(6, 3 * dim))
    p, v, a = X[:, :dim], X[:, dim : 2 * dim], X[:, 2 * dim :]
    np.testing.assert_allclose(cv.f(X[:, : 2 * dim], dt), np.hstack([p + dt * v, v]), rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        ca.f(X, dt), np.hstack([p + dt * v + dt**2 / 2 * a, v + dt * a, a]), rtol=0, atol=1e-14
    )
    # white-acceleration and white-jerk blocks on each axis
    blk_cv = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    np.testing.assert_allclose(cv.Q(dt), np.kron(blk_cv, np.eye(dim)), rtol=1e-14, atol=1e-16)
    blk_ca = q * np.array(
        [[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]]
    )
    np.testing.assert_allclose(ca.Q(dt), np.kron(blk_ca, np.eye(dim)), rtol=1e-14, atol=1e-16)
    with pytest.raises(edccif.ParameterError, match="dim"):
        models.ConstantVelocity(4, q)


def test_random_walk_and_planar_turn():
    rw = models.RandomWalk(4, 0.2)
    X = RNG.normal(size=(3, 4))
    assert np.array_equal(rw.f(X, 0.5), X)
    np.testing.assert_allclose(rw.Q(0.5), 0.1 * np.eye(4), rtol=1e-15)
    ct2 = models.CoordinatedTurn2D(0.5, 1e-4)
    ct3 = models.CoordinatedTurn(0.5, 1e-4)
    assert ct2.n == 5
    X5 = RNG.normal(size=(4, 5))
    X5[:, 4] = 0.3
    # the planar turn is the 3-D one without the z axis
    X7 = np.column_stack([X5[:, 0], X5[:, 1], np.zeros(4), X5[:, 2], X5[:, 3], np.zeros(4), X5[:, 4]])
    np.testing.assert_allclose(ct2.f(X5, 0.1), ct3.f(X7, 0.1)[:, [0, 1, 3, 4, 6]], rtol=0, atol=1e-14)


def test_planar_sensors_match_equations():
    s = np.array([3.0, -1.0])
    X = RNG.normal(size=(8, 4)) * 5
    d = X[:, :2] - s
    rb = models.RangeBearing(s, 0.5, 0.01)
    np.testing.assert_allclose(
        rb.h(X), np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])]), rtol=0, atol=1e-12
    )
    assert (rb.m, rb.angles, rb.min_n) == (2, [1], 2)
    bo = models.BearingOnly(s, 0.01)
    np.testing.assert_allclose(bo.h(X)[:, 0], np.arctan2(d[:, 1], d[:, 0]), rtol=0, atol=1e-12)
    assert (bo.m, bo.angles) == (1, [0])
    ro = models.RangeOnly(s, 0.2)
    np.testing.assert_allclose(ro.h(X)[:, 0], np.hypot(d[:, 0], d[:, 1]), rtol=0, atol=1e-12)
    ro3 = models.RangeOnly([0.0, 0.0, 1.0], 0.2)
    assert ro3.min_n == 3
    with pytest.raises(edccif.ShapeError, match="n >= 3"):
        ro3.h(X[:, :2])
    p2 = models.Position([0.1, 0.2])
    assert p2.m == 2 and np.array_equal(p2.h(X), X[:, :2])
    np.testing.assert_allclose(rb.R, np.diag([0.25, 1e-4]), rtol=1e-14)
    with pytest.raises(edccif.ShapeError, match="sensor_pos"):
        models.RangeOnly([1.0], 0.2)


def test_range_pitch_azimuth_matches_equations():
    s = np.array([10.0, -2.0, 3.0])
    rpa = models.RangePitchAzimuth(s, 0.1, 0.01)
    X = RNG.normal(size=(9, 7)) * 5
    d = X[:, :3] - s
    expect = np.column_stack(
        [np.linalg.norm(d, axis=1), np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])), np.arctan2(d[:, 1], d[:, 0])]
    )
    np.testing.assert_allclose(rpa.h(X), expect, rtol=0, atol=1e-12)
    assert rpa.angles == [1, 2]
    np.testing.assert_allclose(np.diag(rpa.R), [0.01, 1e-4, 1e-4], rtol=1e-14)


def test_linear_models():
    F = np.array([[1.0, 0.1], [0.0, 1.0]])
    lm = models.LinearMotion(F, 0.01 * np.eye(2))
    X = RNG.normal(size=(4, 2))
    np.testing.assert_allclose(lm.f(X, 0.3), X @ F.T, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(lm.Q(0.3), 0.01 * np.eye(2))
    H = np.array([[1.0, 0.0]])
    lh = models.LinearMeasurement(H, [[0.5]])
    assert (lh.m, lh.n) == (1, 2)
    np.testing.assert_array_equal(lh.h(X), X @ H.T)
    np.testing.assert_array_equal(lh.jacobian(X[0]), H)


def test_custom_models_equal_the_catalogue_bit_for_bit():
    ct = models.CoordinatedTurn(0.5, 1e-4)
    rpa = models.RangePitchAzimuth([10.0, 0.0, 0.0], 0.1, 0.01)
    calls = []

    def f(X, dt):
        calls.append(X.shape)
        return ct.f(X, dt)

    cm = models.CustomMotion(f, ct.Q, n=7)
    cs = models.CustomMeasurement(rpa.h, rpa.R, m=3, n=7, angles=[1, 2])
    X = RNG.normal(size=(14, 7))
    assert np.array_equal(cm.f(X, 0.1), ct.f(X, 0.1))
    assert calls == [(14, 7)]  # one call for the whole batch
    assert np.array_equal(cm.Q(0.1), ct.Q(0.1))
    assert np.array_equal(cs.h(X), rpa.h(X))
    assert cs.angles == [1, 2] and (cs.m, cs.n) == (3, 7)
    assert np.array_equal(cs.R, rpa.R)


def test_custom_model_jacobians():
    F = np.array([[1.0, 2.0], [0.0, 1.0]])
    no_jac = models.CustomMotion(lambda X, dt: X @ F.T, np.eye(2), n=2)
    np.testing.assert_allclose(no_jac.jacobian([0.3, -1.0], 0.1), F, atol=1e-8)  # finite differences
    with_jac = models.CustomMotion(lambda X, dt: X @ F.T, np.eye(2), n=2, jacobian=lambda x, dt: F)
    assert np.array_equal(with_jac.jacobian([0.3, -1.0], 0.1), F)
    h = models.CustomMeasurement(lambda X: X[:, :1] ** 2, [[1.0]], m=1, n=2, jacobian=lambda x: [[2 * x[0], 0.0]])
    assert np.array_equal(h.jacobian([3.0, 1.0]), [[6.0, 0.0]])


# --- errors -----------------------------------------------------------------


def test_unsupported_dimensions_name_the_supported_sizes():
    with pytest.raises(edccif.ParameterError, match=r"n = 13 .*n in 1\.\.=12 .*m in 1\.\.=6"):
        models.CustomMotion(lambda X, dt: X, np.eye(13), n=13)
    with pytest.raises(edccif.ParameterError, match=r"m = 7 .*n in 1\.\.=12 .*m in 1\.\.=6"):
        models.CustomMeasurement(lambda X: X, np.eye(7), m=7, n=7)
    with pytest.raises(edccif.ParameterError, match=r"n = 0 "):
        models.CustomMotion(lambda X, dt: X, np.eye(1), n=0)
    with pytest.raises(edccif.ParameterError, match=r"n = 13 "):
        models.LinearMotion(np.eye(13), np.eye(13))
    with pytest.raises(edccif.ParameterError, match=r"m = 7 "):
        models.LinearMeasurement(np.ones((7, 3)), np.eye(7))


def test_constructor_errors_are_named():
    with pytest.raises(edccif.ParameterError, match="q1"):
        models.CoordinatedTurn(-1.0, 1e-4)
    with pytest.raises(edccif.ParameterError):
        models.ConstantVelocity(3, float("nan"))
    with pytest.raises(edccif.ShapeError, match="sensor_xyz"):
        models.RangePitchAzimuth([1.0, 2.0], 0.1, 0.01)
    with pytest.raises(edccif.NonFiniteError, match="sensor_xyz"):
        models.RangePitchAzimuth([1.0, 2.0, np.nan], 0.1, 0.01)
    with pytest.raises(edccif.ShapeError, match="sigma"):
        models.Position([0.1, 0.1, 0.1, 0.1])
    with pytest.raises(edccif.ParameterError, match="sigma"):
        models.Position([0.1, 0.0])
    with pytest.raises(edccif.ShapeError, match="sensor_xy"):
        models.RangeBearing([0.0, 0.0, 0.0], 0.1, 0.01)
    with pytest.raises(edccif.ParameterError, match="sigma_b"):
        models.BearingOnly([0.0, 0.0], -0.01)
    with pytest.raises(edccif.ParameterError, match="n = 13"):
        models.RandomWalk(13, 0.1)
    with pytest.raises(edccif.ShapeError, match="F"):
        models.LinearMotion(np.ones((2, 3)), np.eye(2))
    with pytest.raises(edccif.ShapeError, match="Q"):
        models.LinearMotion(np.eye(2), np.eye(3))
    with pytest.raises(edccif.NotPositiveDefiniteError):
        models.LinearMeasurement(np.ones((1, 2)), [[-1.0]])
    with pytest.raises(edccif.ParameterError, match="f: expected a callable"):
        models.CustomMotion(3.0, np.eye(2), n=2)
    with pytest.raises(edccif.ShapeError, match="Q"):
        models.CustomMotion(lambda X, dt: X, np.eye(3), n=2)
    with pytest.raises(edccif.ParameterError, match="angles"):
        models.CustomMeasurement(lambda X: X[:, :1], [[1.0]], m=1, n=2, angles=[1])
    with pytest.raises(edccif.NotPositiveDefiniteError):
        models.CustomMeasurement(lambda X: X[:, :1], [[0.0]], m=1, n=2)


def test_evaluator_input_errors():
    ct = models.CoordinatedTurn(0.5, 1e-4)
    with pytest.raises(edccif.ShapeError, match=r"X: expected shape \(k, 7\), got \(7,\)"):
        ct.f(np.zeros(7), 0.1)
    with pytest.raises(edccif.ParameterError, match="dt"):
        ct.f(np.zeros((1, 7)), -0.1)
    with pytest.raises(edccif.NonFiniteError):
        ct.f(np.full((1, 7), np.nan), 0.1)
    rpa = models.RangePitchAzimuth([0.0, 0.0, 0.0], 0.1, 0.01)
    with pytest.raises(edccif.ShapeError, match=r"n >= 3"):
        rpa.h(np.zeros((2, 2)))


def test_callable_errors_are_named_and_chained():
    bad_shape = models.CustomMotion(lambda X, dt: X[:, :1], np.eye(2), n=2)
    msg = r"CustomMotion f\(X, dt\) result: expected shape \(3, 2\), got \(3, 1\)"
    with pytest.raises(edccif.ShapeError, match=msg):
        bad_shape.f(np.zeros((3, 2)), 0.1)
    nan = models.CustomMotion(lambda X, dt: X * np.nan, np.eye(2), n=2)
    with pytest.raises(edccif.NonFiniteError, match=r"non-finite value \(NaN\) at row 0, column 0"):
        nan.f(np.zeros((3, 2)), 0.1)

    def boom(X, dt):
        raise RuntimeError("model exploded")

    raising = models.CustomMotion(boom, np.eye(2), n=2)
    with pytest.raises(edccif.ModelError, match="model exploded") as info:
        raising.f(np.zeros((3, 2)), 0.1)
    assert isinstance(info.value.__cause__, RuntimeError)
    assert str(info.value.__cause__) == "model exploded"
    q_bad = models.CustomMotion(lambda X, dt: X, lambda dt: np.eye(3), n=2)
    with pytest.raises(edccif.ShapeError, match=r"Q\(dt\) result"):
        q_bad.Q(0.1)
    h_bad = models.CustomMeasurement(lambda X: "nope", [[1.0]], m=1, n=2)
    with pytest.raises(edccif.ShapeError, match=r"h\(X\) result"):
        h_bad.h(np.zeros((1, 2)))
