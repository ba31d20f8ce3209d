"""SLTR in three dimensions: a mirror plane that may lean, objects raised off the board.

The paper solves in the board's plane; its conclusion names 3-D as the next step.  The
same two ideas carry over.
- **Size constancy.** The camera sees each object's virtual image at ``d_total`` along
  its line of sight: azimuth α (the bearing in the board's plane, as in 2-D) and
  elevation ε (above the horizontal).  The image stands at O + d_total·(cos ε cos α,
  cos ε sin α, sin ε).
- **The mirror bisects.** The mirror's plane is the perpendicular-bisector plane of a
  beacon B and its virtual image B′.

With the plane n·x = ρ (n a unit normal, on the camera's side), the target is its
virtual image reflected across it: T = T′ − 2(n·T′ − ρ) n.

A plane's pose: ``yaw`` is the bearing (deg) of its line on the board, as the planar
solver's.  ``lean`` (deg) is the turn about that line that tips the top away from the
reflective face; an upright mirror has lean 0.  With ε = 0 and lean 0 everything here
is :mod:`solver.sltr` (tested to 1e-9 cm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.errors import SolverError
from solver.geometry import line_normal

ZHAT = np.array([0.0, 0.0, 1.0])


def direction(alpha_deg: ArrayLike, elevation_deg: ArrayLike) -> np.ndarray:
    """Unit vector(s) of azimuth α and elevation ε (deg), shape (…, 3)."""
    a, e = np.radians(alpha_deg), np.radians(elevation_deg)
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)


@dataclass(frozen=True)
class MirrorPlane:
    """The mirror's plane n·x = ρ: ``normal`` a unit vector on the camera's side."""

    normal: np.ndarray
    rho: float

    @classmethod
    def from_pose(cls, point: ArrayLike, yaw_deg: float, lean_deg: float, *,
                  toward: ArrayLike) -> MirrorPlane:
        """The plane through ``point`` whose line on the board runs along ``yaw_deg``,
        leaning by ``lean_deg`` (its top away from its face), facing ``toward`` (the
        camera: the side its normal points to)."""
        n2 = line_normal(yaw_deg)
        face = np.array([n2[0], n2[1], 0.0])
        p = np.asarray(point, float)
        if face[:2] @ (np.asarray(toward, float)[:2] - p[:2]) < 0:
            face = -face
        lean = np.radians(lean_deg)
        n = np.cos(lean) * face + np.sin(lean) * ZHAT
        return cls(n, float(n @ p))

    @property
    def lean_deg(self) -> float:
        """How far the top leans away from the face (deg): the normal's elevation."""
        return float(np.degrees(np.arcsin(np.clip(self.normal[2], -1.0, 1.0))))

    @property
    def yaw_deg(self) -> float:
        """The bearing of the plane's line on the board, mod 180 (deg)."""
        along = np.cross(ZHAT, self.normal)
        yaw = float(np.degrees(np.arctan2(along[1], along[0])) % 180.0)
        return 0.0 if yaw > 180.0 - 1e-9 else yaw  # a rounding below 0 folds to ~180

    def reflect(self, points: ArrayLike) -> np.ndarray:
        """Points (…, 3) reflected across the plane."""
        p = np.asarray(points, float)
        return p - 2.0 * (p @ self.normal - self.rho)[..., None] * self.normal


@dataclass(frozen=True)
class Observation3:
    """What the camera sees of a point in the mirror: azimuth, elevation, d_total (and
    its legs d1 camera → mirror, d2 mirror → point), the virtual image and the
    reflection point."""

    alpha_deg: float
    elevation_deg: float
    d_total: float
    d1: float
    d2: float
    virtual: np.ndarray
    reflection_point: np.ndarray


def observe3(observer: ArrayLike, plane: MirrorPlane, point: ArrayLike) -> Observation3:
    """The forward model in 3-D: what ``observer`` (the camera's centre) sees of
    ``point`` in ``plane``.

    Raises
    ------
    SolverError
        ``point`` or ``observer`` behind the mirror's face.
    """
    o, p = np.asarray(observer, float), np.asarray(point, float)
    if p @ plane.normal - plane.rho <= 0 or o @ plane.normal - plane.rho <= 0:
        raise SolverError("the point and the camera must stand in front of the mirror")
    v = plane.reflect(p)
    rel = v - o
    d = float(np.linalg.norm(rel))
    t = (plane.rho - plane.normal @ o) / (plane.normal @ rel)
    r = o + t * rel
    return Observation3(alpha_deg=float(np.degrees(np.arctan2(rel[1], rel[0]))),
                        elevation_deg=float(np.degrees(np.arcsin(rel[2] / d))), d_total=d,
                        d1=float(np.linalg.norm(r - o)), d2=float(np.linalg.norm(p - r)),
                        virtual=v, reflection_point=r)


def virtual_image3(observer: ArrayLike, seen: tuple[float, float, float]) -> np.ndarray:
    """Where ``seen`` (α, ε, d_total) puts the virtual image: O + d_total·direction(α, ε)."""
    alpha_deg, elevation_deg, d_total = seen
    return np.asarray(observer, float) + d_total * direction(alpha_deg, elevation_deg)


def locate3(observer: ArrayLike, plane: MirrorPlane, seen: tuple[float, float, float]
            ) -> np.ndarray:
    """The point whose image ``plane`` shows at ``seen`` (α, ε, d_total): its virtual
    image reflected back."""
    return plane.reflect(virtual_image3(observer, seen))


def plane_from_beacon3(observer: ArrayLike, beacon: ArrayLike,
                       seen: tuple[float, float, float]) -> MirrorPlane:
    """The mirror's plane from one beacon at ``beacon`` seen at (α, ε, d_total): the
    perpendicular-bisector plane of the beacon and its virtual image, its normal
    towards the beacon (the camera's side).

    Raises
    ------
    SolverError
        The image coincides with the beacon (no plane bisects them).
    """
    b = np.asarray(beacon, float)
    v = virtual_image3(observer, seen)
    gap = b - v
    length = float(np.linalg.norm(gap))
    if length < 1e-9:
        raise SolverError("the beacon's image coincides with the beacon: no mirror bisects them")
    n = gap / length
    return MirrorPlane(n, float(n @ (b + v) / 2.0))


@dataclass(frozen=True)
class Solution3:
    """One beacon's closed-form 3-D solution: the mirror's plane and the target."""

    plane: MirrorPlane
    target: np.ndarray
    target_reflection_point: np.ndarray


def solve_single3(observer: ArrayLike, beacon: ArrayLike, beacon_seen: tuple[float, float, float],
                  *, target_seen: tuple[float, float, float]) -> Solution3:
    """The closed form from one beacon: the plane from the beacon and its image, then
    the target's image reflected across it.

    Raises
    ------
    SolverError
        No plane from the beacon, or a target whose image lies on the camera's side of it.
    """
    plane = plane_from_beacon3(observer, beacon, beacon_seen)
    o = np.asarray(observer, float)
    v = virtual_image3(o, target_seen)
    if v @ plane.normal - plane.rho >= 0:
        raise SolverError("the target's image lies in front of the mirror the beacon gives")
    rel = v - o
    t = (plane.rho - plane.normal @ o) / (plane.normal @ rel)
    return Solution3(plane, plane.reflect(v), o + t * rel)


def plane_of(yaw_deg: float, lean_deg: float, rho: float, *, flip: bool = False) -> MirrorPlane:
    """The plane of a pose's parameters: its normal the face of ``yaw_deg``'s line
    (turned +90°, or −90° with ``flip``) raised by ``lean_deg``, at offset ``rho``."""
    n2 = line_normal(yaw_deg) * (-1.0 if flip else 1.0)
    lean = np.radians(lean_deg)
    return MirrorPlane(np.array([np.cos(lean) * n2[0], np.cos(lean) * n2[1], np.sin(lean)]),
                       float(rho))


@dataclass(frozen=True)
class Fit3:
    """A weighted least-squares solution in 3-D: the plane, the target, and the
    covariance of (yaw [deg], lean [deg], ρ [cm], x, y, z [cm]) where σ's were given."""

    plane: MirrorPlane
    target: np.ndarray
    covariance: np.ndarray | None

    @property
    def target_covariance(self) -> np.ndarray | None:
        """The target's 3×3 covariance (cm²)."""
        return None if self.covariance is None else self.covariance[3:, 3:]


def solve_lsq3(observer: ArrayLike, beacons: list[tuple[ArrayLike, tuple[float, float, float]]],
               targets: list[tuple[float, float, float]], *,
               sigma: tuple[float, float, float] | None = None) -> Fit3:
    """The mirror's plane and the target from every beacon (its position, and what the
    camera saw of it: α, ε, d_total) and every view of the target, by weighted least
    squares from the first beacon's closed form.  ``sigma``: (σ_α deg, σ_ε deg, σ_d as a
    fraction of d_total) of every measurement; without it, unit weights of (0.01°,
    0.01°, 0.2 %) and no covariance.

    Raises
    ------
    SolverError
        No beacon or target, or a geometry that does not determine the unknowns.
    """
    from scipy.optimize import least_squares  # scipy is slow to import: only when used

    if not beacons or not targets:
        raise SolverError("least squares needs at least one beacon and one target observation")
    o = np.asarray(observer, float)
    start = solve_single3(o, beacons[0][0], beacons[0][1], target_seen=targets[0])
    yaw0 = start.plane.yaw_deg
    # the normal's side: the face of yaw0's line, or its opposite
    flip = bool(line_normal(yaw0) @ start.plane.normal[:2] < 0)
    sa, se, sd = sigma or (0.01, 0.01, 0.002)
    positions = [np.asarray(b, float) for b, _ in beacons]
    seen = np.array([s for _, s in beacons] + list(targets), float)

    def residuals(x: np.ndarray) -> np.ndarray:
        plane = plane_of(x[0], x[1], x[2], flip=flip)
        predicted = [_seen_of(o, plane, p) for p in positions]
        predicted += [_seen_of(o, plane, x[3:])] * len(targets)
        pr = np.array(predicted)
        da = (pr[:, 0] - seen[:, 0] + 180.0) % 360.0 - 180.0
        return np.concatenate([da / sa, (pr[:, 1] - seen[:, 1]) / se,
                               (pr[:, 2] - seen[:, 2]) / (sd * seen[:, 2])])

    x0 = np.array([yaw0, start.plane.lean_deg, start.plane.rho, *start.target])
    res = least_squares(residuals, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    jtj = res.jac.T @ res.jac
    if np.linalg.cond(jtj) > 1e14:
        raise SolverError("the beacons and the target do not determine the mirror's plane")
    return Fit3(plane_of(res.x[0], res.x[1], res.x[2], flip=flip), res.x[3:].copy(),
                np.linalg.inv(jtj) if sigma is not None else None)


def _seen_of(o: np.ndarray, plane: MirrorPlane, point: np.ndarray) -> tuple[float, float, float]:
    """(α, ε, d_total) of ``point``'s image, without the in-front check (a fit's step may
    pass through a plane that a point stands behind)."""
    rel = plane.reflect(point) - o
    d = float(np.linalg.norm(rel))
    return (float(np.degrees(np.arctan2(rel[1], rel[0]))),
            float(np.degrees(np.arcsin(rel[2] / d))), d)
