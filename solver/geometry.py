"""Planar geometry of a vertical mirror seen from above: reflections, bearings, lines.

Everything is in the board plane (top view), lengths in cm, angles in degrees,
counter-clockwise from +x.  Arrays are numpy; functions broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np

ArrayLike = np.typing.ArrayLike


def unit(angle_deg: ArrayLike) -> np.ndarray:
    """Unit vector(s) at ``angle_deg`` from +x, shape ``(..., 2)``."""
    a = np.deg2rad(np.asarray(angle_deg, dtype=float))
    return np.stack([np.cos(a), np.sin(a)], axis=-1)


def wrap_bearing(angle_deg: ArrayLike) -> np.ndarray | float:
    """Wrap an angle into (-180, 180]."""
    a = np.asarray(angle_deg, dtype=float)
    w = 180.0 - np.mod(180.0 - a, 360.0)
    return float(w) if w.ndim == 0 else w


def wrap_yaw(angle_deg: ArrayLike) -> np.ndarray | float:
    """Wrap a line's direction into [0, 180): a line has no sense of direction."""
    w = np.mod(np.asarray(angle_deg, dtype=float), 180.0)
    # mod can return exactly 180.0 for tiny negative inputs through rounding
    w = np.where(w >= 180.0, 0.0, w)
    return float(w) if w.ndim == 0 else w


def bearing_deg(origin: ArrayLike, point: ArrayLike) -> np.ndarray | float:
    """Bearing from ``origin`` to ``point`` in (-180, 180]."""
    d = np.asarray(point, dtype=float) - np.asarray(origin, dtype=float)
    return wrap_bearing(np.rad2deg(np.arctan2(d[..., 1], d[..., 0])))


def line_normal(yaw_deg: ArrayLike) -> np.ndarray:
    """Unit normal of a line of direction ``yaw_deg`` (the direction turned +90°)."""
    return unit(np.asarray(yaw_deg, dtype=float) + 90.0)


def signed_distance(point: ArrayLike, line_point: ArrayLike, yaw_deg: ArrayLike) -> np.ndarray:
    """Signed distance of ``point`` from the line, positive on the side of ``line_normal``."""
    p = np.asarray(point, dtype=float) - np.asarray(line_point, dtype=float)
    return np.sum(p * line_normal(yaw_deg), axis=-1)


def reflect(point: ArrayLike, line_point: ArrayLike, yaw_deg: ArrayLike) -> np.ndarray:
    """Mirror image of ``point`` across the line through ``line_point`` at ``yaw_deg``."""
    p = np.asarray(point, dtype=float)
    n = line_normal(yaw_deg)
    s = signed_distance(p, line_point, yaw_deg)
    return p - 2.0 * s[..., None] * n


def segment_distance(p0: ArrayLike, p1: ArrayLike, q0: ArrayLike, *, q1: ArrayLike) -> float:
    """Shortest distance between the segments p0–p1 and q0–q1 (either may be a point)."""
    p0, p1, q0, q1 = (np.asarray(v, dtype=float) for v in (p0, p1, q0, q1))
    if _segments_cross(p0, p1, q0, q1):
        return 0.0
    return float(min(point_segment_distance(p0, q0, q1), point_segment_distance(p1, q0, q1),
                     point_segment_distance(q0, p0, p1), point_segment_distance(q1, p0, p1)))


def point_segment_distance(p: ArrayLike, a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Distance of each point ``p`` (..., 2) from the segment a–b (a point if a = b)."""
    p, a, b = (np.asarray(v, dtype=float) for v in (p, a, b))
    ab = b - a
    L2 = float(ab @ ab)
    t = np.zeros(p.shape[:-1]) if L2 == 0.0 else np.clip((p - a) @ ab / L2, 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _segments_cross(p0, p1, q0, q1) -> bool:
    d1 = _cross2(q1 - q0, p0 - q0)
    d2 = _cross2(q1 - q0, p1 - q0)
    d3 = _cross2(p1 - p0, q0 - p0)
    d4 = _cross2(p1 - p0, q1 - p0)
    return (d1 * d2 < 0.0) and (d3 * d4 < 0.0)


def segment_crossing(
    p0: ArrayLike, p1: ArrayLike, q0: ArrayLike, *, q1: ArrayLike
) -> float | None:
    """Parameter u in [0, 1] along p0→p1 where it crosses segment q0–q1, or None."""
    p0, p1, q0, q1 = (np.asarray(v, dtype=float) for v in (p0, p1, q0, q1))
    r, s = p1 - p0, q1 - q0
    denom = _cross2(r, s)
    if denom == 0.0:
        return None
    u = _cross2(q0 - p0, s) / denom
    w = _cross2(q0 - p0, r) / denom
    if 0.0 <= u <= 1.0 and 0.0 <= w <= 1.0:
        return u
    return None


def yaw_difference(a_deg: ArrayLike, b_deg: ArrayLike) -> np.ndarray | float:
    """|a − b| between two line directions, in [0, 90]: lines have no sense of direction."""
    d = np.abs((np.asarray(a_deg, float) - np.asarray(b_deg, float) + 90.0) % 180.0 - 90.0)
    return float(d) if d.ndim == 0 else d
