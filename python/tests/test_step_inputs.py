"""`Network.step` reads every layout and type of `z` alike: the C-contiguous
float64 array the binding reads directly and everything that goes through the
general array conversion give the same estimates (bit for bit) and the same
errors, and the returned array is the caller's own."""

import numpy as np
import pytest

import edccif


def _layouts(zk):
    """The same (N, 3) values in the forms a caller may pass."""
    wide = np.zeros((zk.shape[0], 6))
    wide[:, ::2] = zk
    return {
        "c-contiguous float64": np.ascontiguousarray(zk),
        "fortran order": np.asfortranarray(zk),
        "strided view": wide[:, ::2],
        "read-only": np.frombuffer(np.ascontiguousarray(zk).tobytes()).reshape(zk.shape),
        "big-endian": zk.astype(">f8"),
        "nested list": zk.tolist(),
    }


def test_every_layout_gives_the_same_estimates(sc4, sim4):
    _, z, x0 = sim4
    steps = 20
    runs = {}
    for name in _layouts(z[0]):
        net = edccif.Network(sc4, "edc-cif", x0=x0)
        out = [net.step(_layouts(z[k])[name]) for k in range(steps)]
        runs[name] = np.array(out)
    ref = runs["c-contiguous float64"]
    assert ref.shape == (steps, 4, 7)
    for name, est in runs.items():
        np.testing.assert_array_equal(est, ref, err_msg=name)  # tolerance: none (bit for bit)
    # and the same as the batch run
    res = edccif.run("edc-cif", sc4, z[:steps], x0=x0)
    np.testing.assert_array_equal(ref, res.estimates)


def test_integer_measurements_are_converted(sc4):
    a, b = edccif.Network(sc4), edccif.Network(sc4)
    zi = np.array([[10, 0, 1]] * 4, dtype=np.int64)
    np.testing.assert_array_equal(a.step(zi), b.step(zi.astype(float)))


@pytest.mark.parametrize("shape", [(3,), (4, 2), (3, 3), (4, 3, 1), (2, 3)])
def test_shape_errors_are_the_same_for_arrays_and_lists(sc4, shape):
    z = np.ones(shape)
    msgs = []
    for zz in (z, np.asfortranarray(z), z.tolist()):
        net = edccif.Network(sc4)
        before = net.estimates
        with pytest.raises(edccif.ShapeError) as e:
            net.step(zz)
        msgs.append(str(e.value))
        np.testing.assert_array_equal(net.estimates, before)
        assert net.t == 0.0
    got = "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"
    assert msgs[0] == msgs[1] == msgs[2] == f"z: expected shape (4, 3), got {got}"


def test_returned_estimates_are_the_callers(sc4, sim4):
    _, z, x0 = sim4
    net = edccif.Network(sc4, x0=x0)
    e1 = net.step(z[0])
    assert e1.dtype == np.float64 and e1.shape == (4, 7) and e1.flags.c_contiguous and e1.flags.writeable
    kept = e1.copy()
    e1[:] = 0.0  # writing into the result changes neither the network nor the next result
    np.testing.assert_array_equal(net.estimates, kept)
    e2 = net.step(z[1])
    np.testing.assert_array_equal(e1, 0.0)
    assert not np.shares_memory(e2, net.estimates)
