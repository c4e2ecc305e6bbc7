"""Python models named in scenario files by reference (``kind = "python"``).

A reference ``"module:attribute"`` names an ``edccif.models`` model object, or a
callable of no arguments returning one (a factory), in an importable module.
The scenario's ``python_path`` directories (relative to the scenario file) are
put at the front of ``sys.path`` first, so that separate processes (agents,
sensors, sweep cells) reading the same file build the same model. The
extension calls :func:`resolve` whenever it builds a scenario's models; the
errors name the reference and what was expected.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Any

from . import models
from ._edccif import ScenarioError

_KINDS = {"motion": models.MotionModel, "measurement": models.MeasurementModel}


def _use_path(dirs: list[str]) -> None:
    for d in reversed(dirs):
        d = os.path.abspath(d)
        if d not in sys.path:
            sys.path.insert(0, d)


def resolve(reference: str, kind: str, dirs: list[str]) -> Any:
    """The model ``reference`` (``module:attribute``) names, of ``kind``
    (``"motion"`` or ``"measurement"``); ``dirs``: the scenario's
    ``python_path`` resolved. The extension puts the scenario key in front
    of the errors' messages."""
    expected = _KINDS[kind]
    what = f"an edccif.models.{expected.__name__} (e.g. a Custom{'Motion' if kind == 'motion' else 'Measurement'})"
    module_name, _, attr = reference.partition(":")
    _use_path(dirs)
    try:
        obj: Any = importlib.import_module(module_name)
    except Exception as e:  # an import error, or whatever the module raised
        searched = ", ".join(os.path.abspath(d) for d in dirs) or "no python_path"
        raise ScenarioError(
            f"cannot import module `{module_name}` of the Python model "
            f"`{reference}`: {type(e).__name__}: {e} (searched the scenario's python_path: {searched}, "
            "then sys.path)"
        ) from e
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError as e:
            raise ScenarioError(
                f"the Python model `{reference}`: module `{module_name}` "
                f"has no attribute `{attr}`"
            ) from e
    if not isinstance(obj, expected):
        if not callable(obj):
            raise ScenarioError(
                f"the Python model `{reference}` is a {type(obj).__name__}; "
                f"expected {what} or a callable of no arguments returning one"
            )
        try:
            made = obj()
        except Exception as e:
            raise ScenarioError(
                f"calling the Python model factory `{reference}()` raised "
                f"{type(e).__name__}: {e}"
            ) from e
        if not isinstance(made, expected):
            raise ScenarioError(
                f"the Python model factory `{reference}()` returned a "
                f"{type(made).__name__}; expected {what}"
            )
        obj = made
    return obj
