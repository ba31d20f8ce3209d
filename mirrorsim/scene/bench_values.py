"""Each bench value held to its bounds, once, whatever made the scene: the scene reader
parses a value's type, and the composer (:mod:`mirrorsim.truth.compose`) runs
:func:`bench_failures` on every scene, since some bounds relate a value to the mirror
(a curvature) or the camera (a lens)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mirrorsim.scene.imperfections import REGISTRY, Imperfection
from mirrorsim.scene.model import (
    MAX_CURVATURE_RADIUS,
    MAX_FULL_WELL,
    MAX_READ_NOISE,
    Bench,
    Scene,
)
from mirrorsim.scene.projection import radial_slope


def check_bounds(imp: Imperfection, value: float) -> str | None:
    """Why ``value`` is out of ``imp``'s bounds (beyond them a value is a typo, not a
    bench), or None."""
    if imp.form == "angle" and abs(value) >= imp.bound:
        return f"{value:g}: |{imp.leaf}| must stay below {imp.bound:g}°"
    if imp.form == "number" and not imp.low < value < imp.high:
        return (f"{value:g}: {imp.why or 'out of range'} (error in ({imp.low:g}, "
                f"{imp.high:g}) {imp.units})")
    return None


def radius_bound(size: tuple[float, float]) -> float:
    """The smallest |curvature radius| of a mirror of this size: its diagonal."""
    return math.hypot(*size)


def distortion_monotonic(k: tuple[float, float], r_max: float) -> bool:
    """Whether r·(1 + k1 r² + k2 r⁴) grows on [0, r_max] (normalized radius): a lens
    that folds its image over is no lens."""
    r = np.linspace(0.0, r_max, 512)
    return bool((radial_slope(r**2, k) > 0).all())


def value_failure(imp: Imperfection, value: Any, scene: Scene) -> str | None:
    """Why ``value`` (as :class:`Bench` holds it) is refused for ``imp`` in ``scene`` (its
    mirror's size bounds a curvature, its camera's frame a lens), or None: the one
    statement of each imperfection's bounds, for a scene file's value and an edited
    scene's alike."""
    if imp.form in ("angle", "number"):
        return check_bounds(imp, value)
    if imp.form == "quality" and not imp.low <= value <= imp.high:
        return f"{value} must be {'≥' if value < imp.low else '≤'} " \
               f"{imp.low if value < imp.low else imp.high:g}"
    if imp.form == "lens":
        if not all(imp.low <= k <= imp.high for k in value):
            return f"{list(value)}: each coefficient must be within {imp.low:g}..{imp.high:g}"
        cam = scene.camera
        corner = math.hypot(*cam.resolution) / 2 / cam.fx
        if not distortion_monotonic(value, corner):
            return (f"{list(value)}: the lens folds the image over before the frame's corner "
                    "(r·(1 + k1 r² + k2 r⁴) must grow)")
    if imp.form == "radius":
        diagonal = radius_bound(scene.mirror.size)
        if not diagonal <= abs(value) <= MAX_CURVATURE_RADIUS:
            return (f"{value:g}: |radius| must be at least the mirror's diagonal "
                    f"({diagonal:.1f} cm) and at most {MAX_CURVATURE_RADIUS:g} cm (flatter: "
                    "leave the key out)")
    return None


_TYPES = {"angle": float, "number": float, "quality": int, "flag": bool, "radius": float}


def _type_failure(want: type | None, value: Any) -> str | None:
    """What ``value`` is not, of the type a form holds (None: it is)."""
    if want is bool:
        return None if isinstance(value, bool) else "true or false"
    if want in (int, float):
        if isinstance(value, bool) or not isinstance(value, int | float):
            return "a number"
        if want is int and not isinstance(value, int):
            return "an integer"
        return None if math.isfinite(value) else "a finite number"
    return None


def bench_failures(scene: Scene) -> list[tuple[str, str]]:
    """Each of ``scene``'s bench values a scene file would refuse, as (key path, why):
    of the wrong type, or out of its bounds (:func:`value_failure`).  The composer runs
    it on every scene, however made."""
    out = []
    for imp in REGISTRY:
        if not hasattr(scene.bench, imp.field):
            continue  # (a beacon's believed position is the beacon's own)
        value = getattr(scene.bench, imp.field)
        if value is None or value == getattr(Bench(), imp.field):
            continue
        why = _type_failure(_TYPES.get(imp.form), value)
        if why:
            out.append((imp.key, f"{value!r} is not {why}"))
            continue
        if imp.form == "noise":  # each of its two values under its own key
            out += [(f"{imp.key}.{name}", f"{v:g} must be ≤ {most:g}") for name, v, most in (
                ("full_well", value.full_well, MAX_FULL_WELL),
                ("read_noise", value.read_noise, MAX_READ_NOISE)) if v > most]
            continue
        why = value_failure(imp, value, scene)
        if why:
            out.append((imp.key, why))
    return out
