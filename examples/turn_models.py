"""Models of one's own for ``scenarios/custom-turn-2d.toml``: a planar
coordinated-turn target written in Python, and a low-rate position tag.

A scenario file names them by reference (``kind = "python"``, ``model =
"turn_models:turn_motion"``) and finds this module through its ``python_path``
(``["../examples"]``, relative to the scenario file); every process that reads
the file (the CLI, sweep cells, agents) builds the same models from it.

>>> import numpy as np
>>> m = turn_motion()
>>> m.n
5
>>> np.round(m.f(np.array([[0.0, 0.0, 1.0, 0.0, 0.0]]), 0.5), 12)
array([[0.5, 0. , 1. , 0. , 0. ]])
"""

import numpy as np

from edccif import models

Q1 = 0.1  # position/velocity noise intensity (m²/s³)
Q2 = 1e-4  # turn-rate noise intensity (rad²/s³)
TAG_SIGMA = 0.3  # the tag's standard deviation per axis (m)


def _turn(X: np.ndarray, dt: float) -> np.ndarray:
    """The coordinated turn on every row ``[x, y, vx, vy, ω]`` of ``X``."""
    x, y, vx, vy, w = X.T
    wt = w * dt
    small = np.abs(wt) < 1e-9
    safe = np.where(small, 1.0, w)
    s = np.where(small, dt, np.sin(wt) / safe)  # sin(ωT)/ω → T
    c = np.where(small, 0.0, (1.0 - np.cos(wt)) / safe)  # (1 − cos ωT)/ω → 0
    cos, sin = np.cos(wt), np.sin(wt)
    return np.stack([x + s * vx - c * vy, y + c * vx + s * vy, cos * vx - sin * vy, sin * vx + cos * vy, w], axis=1)


def _noise(dt: float) -> np.ndarray:
    """White acceleration on each axis (intensity ``Q1``), a random-walk turn rate (``Q2``)."""
    block = Q1 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    q = np.zeros((5, 5))
    for axis in (0, 1):
        idx = [axis, axis + 2]
        q[np.ix_(idx, idx)] = block
    q[4, 4] = Q2 * dt
    return q


def turn_motion() -> models.CustomMotion:
    """The planar coordinated turn as a ``CustomMotion`` (5 states)."""
    return models.CustomMotion(_turn, _noise, n=5)


def position_tag() -> models.CustomMeasurement:
    """A position tag: the target's ``[x, y]`` with ``TAG_SIGMA`` noise."""
    return models.CustomMeasurement(lambda X: X[:, :2], R=TAG_SIGMA**2 * np.eye(2), m=2, n=5)


def catalogue_turn() -> models.CoordinatedTurn2D:
    """The catalogue's planar coordinated turn, by reference (the same numbers
    as ``kind = "coordinated-turn-2d"`` with these intensities)."""
    return models.CoordinatedTurn2D(q1=Q1, q2=Q2)
