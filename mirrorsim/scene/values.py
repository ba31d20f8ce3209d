"""A scene's values held to what they can be where they are made: each dataclass of
:mod:`mirrorsim.scene.model` checks its own fields (finite, positive, two of them…), an
edit by ``dataclasses.replace`` too.  A refusal is a
:class:`~mirrorsim.errors.BadParameter` naming the field (``size[0]``); the readers name
the key path it came from.  The scene file's limits on a scene (no size beyond
MAX_BOARD_CM…) are the composer's (:func:`mirrorsim.truth.scene_checks.check_limits`):
a camera the renderer widens for a lens, or a capture record's, may exceed them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mirrorsim.errors import BadParameter


def _shown(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else repr(value) if isinstance(
        value, str) else str(value)


def number(name: str, value: Any, *, positive: bool = False, low: float | None = None,
           high: float | None = None) -> float:
    """``value`` as a finite float, optionally > 0 and within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int | float) and not hasattr(
            value, "__float__"):
        raise BadParameter(name, f"expected a number, got {_shown(value)}")
    try:
        v = float(value)
    except (OverflowError, TypeError, ValueError):
        raise BadParameter(name, f"{_shown(value)[:20]} is not a finite number") from None
    if not math.isfinite(v):
        raise BadParameter(name, f"{_shown(value)} is not a finite number")
    if positive and v <= 0.0:
        raise BadParameter(name, f"{_shown(v)} must be > 0")
    if low is not None and v < low:
        raise BadParameter(name, f"{_shown(v)} must be ≥ {low:g}")
    if high is not None and v > high:
        raise BadParameter(name, f"{_shown(v)} must be ≤ {high:g}")
    return v


def pair(name: str, value: Any, *, positive: bool = False, high: float | None = None
         ) -> tuple[float, float]:
    """Two numbers (each > 0 and ≤ ``high`` where asked), named ``name[0]``, ``name[1]``."""
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != 2:
        raise BadParameter(name, f"expected two numbers, got {_shown(value)}")
    return (number(f"{name}[0]", value[0], positive=positive, high=high),
            number(f"{name}[1]", value[1], positive=positive, high=high))


def whole(name: str, value: Any, *, low: int, high: int | None = None) -> int:
    """An integer (not a bool) within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int) and not (
            hasattr(value, "__index__") and not isinstance(value, float)):
        raise BadParameter(name, f"expected an integer, got {_shown(value)}")
    v = int(value)
    if v < low:
        raise BadParameter(name, f"{v} must be ≥ {low}")
    if high is not None and v > high:
        raise BadParameter(name, f"{v} must be ≤ {high}")
    return v


def resolution(name: str, value: Any) -> tuple[int, int]:
    """[width, height] in px, each at least 2."""
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != 2:
        raise BadParameter(name, f"expected [width, height] in px, got {_shown(value)}")
    return (whole(f"{name}[0]", value[0], low=2), whole(f"{name}[1]", value[1], low=2))
