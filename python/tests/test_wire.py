"""The wire format from Python: round trips, named errors, and the example in
docs/formats.md (executed here)."""

import re
from pathlib import Path

import numpy as np
import pytest

import edccif

DOCS = Path(__file__).resolve().parents[2] / "docs" / "formats.md"


def test_docs_example_runs():
    text = DOCS.read_text(encoding="utf-8")
    section = text.split("## Wire format", 1)[1]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert blocks
    for b in blocks:
        exec(compile(b, str(DOCS), "exec"), {})


def test_round_trip_every_kind():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(7, 7))
    m = a @ a.T + np.eye(7)
    v = rng.normal(size=7)
    for kind in ("contribution", "estimate", "information"):
        data = edccif.encode_packet(kind, v, m, swarm=2**32 - 1, sender=65535, step=2**40, round=4, stamp_ns=5)
        assert len(data) == 308
        p = edccif.decode_packet(data)
        assert p.kind == kind and p.round == 4 and p.swarm == 2**32 - 1 and p.sender == 65535
        assert p.step == 2**40 and p.stamp_ns == 5 and p.nbytes == 308
        assert np.array_equal(p.vector, v) and np.array_equal(p.matrix, m)
    z = edccif.decode_packet(edccif.encode_packet("measurement", [1.0, 2.0, 3.0]))
    assert z.matrix is None and z.vector.tolist() == [1.0, 2.0, 3.0]
    assert "measurement" in repr(z)


def test_decode_errors_are_named():
    good = edccif.encode_packet("measurement", [1.0, 2.0, 3.0])
    cases = {
        good[:5]: "truncated packet: 5 bytes, expected 28",
        good[:-1]: "truncated packet: 51 bytes, expected 52",
        good + b"\0": "oversized packet: 53 bytes, expected 52",
        b"xx" + good[2:]: "not an edccif packet",
        good[:2] + b"\x02" + good[3:]: "wrong wire format version 2, expected 1",
        good[:3] + b"\x09" + good[4:]: "unknown packet kind 9",
        good[:36] + np.float64(np.nan).tobytes() + good[44:]: r"packet vector\[1\] is NaN",
    }
    for data, msg in cases.items():
        with pytest.raises(edccif.WireFormatError, match=msg):
            edccif.decode_packet(data)
    assert issubclass(edccif.WireFormatError, edccif.EdccifError)


def test_encode_errors_are_named():
    with pytest.raises(edccif.UnknownOptionError, match="kind"):
        edccif.encode_packet("pose", [1.0])
    with pytest.raises(edccif.NonFiniteError, match="vector"):
        edccif.encode_packet("measurement", [np.nan])
    with pytest.raises(edccif.ShapeError, match="matrix"):
        edccif.encode_packet("estimate", [1.0, 2.0])
    with pytest.raises(edccif.ShapeError, match="matrix"):
        edccif.encode_packet("estimate", [1.0, 2.0], np.eye(3))
    with pytest.raises(edccif.ShapeError, match="no matrix"):
        edccif.encode_packet("measurement", [1.0], np.eye(1))
    with pytest.raises(edccif.ParameterError, match="sender"):
        edccif.encode_packet("measurement", [1.0], sender=70000)
    with pytest.raises(edccif.ShapeError, match="at most 32"):
        edccif.encode_packet("measurement", np.zeros(33))
