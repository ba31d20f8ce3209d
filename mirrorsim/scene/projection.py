"""The camera's pinhole projection: its axes (level, or pitched and rolled by a bench)
and 3-D points to pixels, OpenCV's convention."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from mirrorsim.scene.model import Camera
from solver.geometry import unit


def camera_axes(camera: Camera, pitch: float = 0.0, roll: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward, right and down unit vectors of the camera (3-D): level unless a bench's
    ``pitch`` (deg, optical axis raised) or ``roll`` (deg, clockwise as seen from behind)
    says otherwise."""
    f = unit(camera.pan_deg)
    forward = np.array([f[0], f[1], 0.0])
    right = np.array([f[1], -f[0], 0.0])
    down = np.array([0.0, 0.0, -1.0])
    if pitch:
        p = math.radians(pitch)
        forward, down = (math.cos(p) * forward - math.sin(p) * down,
                         math.cos(p) * down + math.sin(p) * forward)
    if roll:
        q = math.radians(roll)
        right, down = (math.cos(q) * right + math.sin(q) * down,
                       math.cos(q) * down - math.sin(q) * right)
    return forward, right, down


def project(camera: Camera, points3: ArrayLike, pitch: float = 0.0, *, roll: float = 0.0
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pinhole projection of 3-D points (OpenCV pixel convention: centres at integers),
    by the level camera or one pitched and rolled (:func:`camera_axes`).

    Returns
    -------
    u, v : ndarray
        Pixel coordinates (+u right, +v down).
    depth : ndarray
        Distance along the optical axis (negative behind the camera).
    """
    p = np.asarray(points3, float) - camera.center3
    forward, right, down = camera_axes(camera, pitch, roll)
    z = p @ forward
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.cx + camera.fx * (p @ right) / z
        v = camera.cy + camera.fx * (p @ down) / z
    return u, v, z


def hfov_of(width: float, fx: float) -> float:
    """The horizontal field of view (deg) that ``width`` px see at focal length ``fx``
    px: the inverse of :func:`~mirrorsim.scene.model.fx_of`."""
    return math.degrees(2.0 * math.atan(width / 2.0 / fx))


def radial_factor(x: np.ndarray, y: np.ndarray, k: tuple[float, float]) -> np.ndarray:
    """The Brown–Conrady radial factor 1 + k1·r² + k2·r⁴ at normalized coordinates
    (x, y): a lens images the pinhole's (x, y) at (x, y) times it."""
    r2 = x * x + y * y
    return 1.0 + k[0] * r2 + k[1] * r2 * r2


def radial_slope(r2: np.ndarray, k: tuple[float, float]) -> np.ndarray:
    """d/dr of r·(1 + k1 r² + k2 r⁴) at r² = ``r2``: where it is not positive, a lens
    folds its image back (no lens does so over its frame)."""
    return 1 + 3 * k[0] * r2 + 5 * k[1] * r2 * r2


def distort_pixels(camera: Camera, u: np.ndarray, v: np.ndarray, *, k: tuple[float, float]
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Where a lens of radial distortion ``k`` images the pinhole pixels (u, v)."""
    x, y = (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fx
    f = radial_factor(x, y, k)
    return camera.cx + camera.fx * x * f, camera.cy + camera.fx * y * f
