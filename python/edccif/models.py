"""Models for the filters and networks: the catalogue and your own models.

Motion models (``MotionModel``: state dimension ``.n``, ``.f(X, dt)`` on a batch
of states, ``.Q(dt)``, ``.jacobian(x, dt)``) and measurement models
(``MeasurementModel``: ``.m``, ``.n``, ``.h(X)``, ``.R``, ``.angles``,
``.jacobian(x)``). Motion models take the time step at each call.

Your own model is a ``CustomMotion`` / ``CustomMeasurement`` built from Python
callables evaluated once per filter step on the whole (k, n) array of sigma
points (one point per row):

>>> import numpy as np
>>> from edccif import models
>>> cv = models.CustomMotion(lambda X, dt: X @ np.array([[1.0, 0.0], [dt, 1.0]]),
...                          Q=lambda dt: 0.01 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), n=2)
>>> cv.f(np.array([[0.0, 1.0]]), 0.5)
array([[0.5, 1. ]])
"""

from ._edccif import (
    BearingOnly,
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    CoordinatedTurn2D,
    CustomMeasurement,
    CustomMotion,
    LinearMeasurement,
    LinearMotion,
    MeasurementModel,
    MotionModel,
    Position,
    RandomWalk,
    RangeBearing,
    RangeOnly,
    RangePitchAzimuth,
)

__all__ = [
    "BearingOnly",
    "ConstantAcceleration",
    "ConstantVelocity",
    "CoordinatedTurn",
    "CoordinatedTurn2D",
    "CustomMeasurement",
    "CustomMotion",
    "LinearMeasurement",
    "LinearMotion",
    "MeasurementModel",
    "MotionModel",
    "Position",
    "RandomWalk",
    "RangeBearing",
    "RangeOnly",
    "RangePitchAzimuth",
]
