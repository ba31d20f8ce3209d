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
from solver.geometry import line_normal, wrap_yaw

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
        p = np.asarray(point, float)
        flip = bool(line_normal(yaw_deg) @ (np.asarray(toward, float)[:2] - p[:2]) < 0)
        n = cls.from_params(yaw_deg, lean_deg, 0.0, flip=flip).normal
        return cls(n, float(n @ p))

    @classmethod
    def from_params(cls, yaw_deg: float, lean_deg: float, rho: float, *,
                    flip: bool = False) -> MirrorPlane:
        """The plane of a pose's parameters: its normal the face of ``yaw_deg``'s line
        (turned +90°, or −90° with ``flip``) raised by ``lean_deg``, at offset ``rho``."""
        n2 = line_normal(yaw_deg) * (-1.0 if flip else 1.0)
        lean = np.radians(lean_deg)
        return cls(np.array([np.cos(lean) * n2[0], np.cos(lean) * n2[1], np.sin(lean)]),
                   float(rho))

    @property
    def flip(self) -> bool:
        """Whether the normal faces the −90° side of its yaw's line (:meth:`from_params`)."""
        return bool(line_normal(self.yaw_deg) @ self.normal[:2] < 0)

    @property
    def lean_deg(self) -> float:
        """How far the top leans away from the face (deg): the normal's elevation."""
        return float(np.degrees(np.arcsin(np.clip(self.normal[2], -1.0, 1.0))))

    @property
    def yaw_deg(self) -> float:
        """The bearing of the plane's line on the board, mod 180 (deg)."""
        along = np.cross(ZHAT, self.normal)
        return float(wrap_yaw(np.degrees(np.arctan2(along[1], along[0]))))

    def reflect(self, points: ArrayLike) -> np.ndarray:
        """Points (…, 3) reflected across the plane."""
        p = np.asarray(points, float)
        return p - 2.0 * (p @ self.normal - self.rho)[..., None] * self.normal

    def hit(self, o: np.ndarray, ray: np.ndarray) -> np.ndarray:
        """Where the line o + t·ray meets the plane."""
        return o + (self.rho - self.normal @ o) / (self.normal @ ray) * ray


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


def observe3(observer: ArrayLike, plane: MirrorPlane, point: ArrayLike, *,
             strict: bool = True) -> Observation3:
    """The forward model in 3-D: what ``observer`` (the camera's centre) sees of
    ``point`` in ``plane`` (``strict=False``: wherever the point stands).

    Raises
    ------
    SolverError
        ``point`` or ``observer`` behind the mirror's face (with ``strict``).
    """
    o, p = np.asarray(observer, float), np.asarray(point, float)
    if strict and (p @ plane.normal - plane.rho <= 0 or o @ plane.normal - plane.rho <= 0):
        raise SolverError("the point and the camera must stand in front of the mirror")
    v = plane.reflect(p)
    r = plane.hit(o, v - o)
    alpha, elevation, d = seen3(o, plane, p)
    return Observation3(alpha_deg=alpha, elevation_deg=elevation, d_total=d,
                        d1=float(np.linalg.norm(r - o)), d2=float(np.linalg.norm(p - r)),
                        virtual=v, reflection_point=r)


def seen3(observer: ArrayLike, plane: MirrorPlane, point: ArrayLike
          ) -> tuple[float, float, float]:
    """(α, ε, d_total) of ``point``'s image, without :func:`observe3`'s in-front check
    (a fit's step may pass through a plane a point stands behind)."""
    rel = plane.reflect(np.asarray(point, float)) - np.asarray(observer, float)
    d = float(np.linalg.norm(rel))
    return (float(np.degrees(np.arctan2(rel[1], rel[0]))),
            float(np.degrees(np.arcsin(rel[2] / d))), d)


def power_terms3(observer: ArrayLike, plane: MirrorPlane, points: ArrayLike, *,
                 vertex: ArrayLike | None = None) -> np.ndarray:
    """First-order change of each point's (α, ε, d_total) per unit of the mirror's power
    c = 1/R (1/cm, > 0 concave), the glass curved about ``vertex`` (a point on the
    plane; None: the middle of the points' reflection points, as the planar solver
    takes it): :func:`solver.fit_model.power_terms` in 3-D.

    At a reflection point w from the vertex (in the plane) the glass is turned by c·w
    and stands c·|w|²/2 nearer the camera, which moves the virtual image by
    c·(2((q·w)·n + (q·n)·w) + |w|²·n) (q: the point from the reflection point, n the
    normal on the camera's side): across the line of sight, α's and ε's change; along it,
    a shorter path.  Size constancy reads the sagittal magnification 2·c·cos i as
    nearer (−2·c·cos i·d1·d2, the mirror equation).  With the glass upright and every
    point at the lens's height it is the planar terms, ε's change 0 (tested).

    Returns
    -------
    (k, 3)
        Each point's dα (deg), dε (deg) and dd (cm) per unit c.
    """
    o = np.asarray(observer, float)
    pts = np.atleast_2d(np.asarray(points, float))
    n = plane.normal
    virtual = plane.reflect(pts)
    rel = virtual - o  # the line of sight to each image
    P = np.array([plane.hit(o, r) for r in rel])  # the reflection points
    w = P - (P.mean(axis=0) if vertex is None else np.asarray(vertex, float))
    w -= (w @ n)[:, None] * n  # in the plane
    q = pts - P
    dv = (2.0 * ((np.sum(q * w, axis=1))[:, None] * n + (q @ n)[:, None] * w)
          + np.sum(w * w, axis=1)[:, None] * n)
    dist = np.linalg.norm(rel, axis=1)
    flat2 = rel[:, 0] ** 2 + rel[:, 1] ** 2
    dalpha = np.degrees((rel[:, 0] * dv[:, 1] - rel[:, 1] * dv[:, 0]) / flat2)
    dflat = (rel[:, 0] * dv[:, 0] + rel[:, 1] * dv[:, 1]) / np.sqrt(flat2)
    delev = np.degrees((np.sqrt(flat2) * dv[:, 2] - rel[:, 2] * dflat) / dist**2)
    cos_i = np.abs(rel @ n) / dist
    d1, d2 = np.linalg.norm(P - o, axis=1), np.linalg.norm(q, axis=1)
    dd = np.sum(rel * dv, axis=1) / dist - 2.0 * cos_i * d1 * d2
    return np.column_stack([dalpha, delev, dd])


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
    return Solution3(plane, plane.reflect(v), plane.hit(o, v - o))


def apparent_height_ratio(observer: ArrayLike, plane: MirrorPlane, base: ArrayLike, *,
                          height: float) -> float:
    """How tall an upright object of ``height`` standing on ``base`` looks in the mirror
    (rows of a level pinhole camera at ``observer`` facing its image), against an
    upright object at its image's foot: 1 in an upright mirror.

    A leaning mirror leans the image by twice its lean, so the image looks shorter (to
    first order by cos 2λ) and its top nearer or farther.  Size constancy (d_total =
    K / pixels) then reads d_total too long by 1/ratio − 1: what a 3-D detector must
    correct for once it knows the lean.
    """
    o = np.asarray(observer, float)
    foot = plane.reflect(np.asarray(base, float))
    top = plane.reflect(np.asarray(base, float) + height * ZHAT)
    forward = np.array([*(foot[:2] - o[:2]), 0.0])
    forward /= np.linalg.norm(forward)

    def rows(p: np.ndarray) -> float:  # −v·f: the height on the film over the depth
        return (p[2] - o[2]) / ((p - o) @ forward)

    return float((rows(top) - rows(foot)) / (rows(foot + height * ZHAT) - rows(foot)))


def measured3(observer: ArrayLike, plane: MirrorPlane, base: ArrayLike, *, height: float,
              front: float = 0.0, pan_deg: float | None = None
              ) -> tuple[float, float, float]:
    """(α, ε, d_total) as a detector reads them off the image of an upright object of
    ``height`` standing on ``base``, by a level pinhole camera at ``observer`` panned to
    ``pan_deg`` (None: turned to the image).  On the film (tangents of the camera's
    angles) the image runs from its foot to its top; the detector takes
    - α at the column of their midpoint, φ off the optical axis: pan − φ;
    - the horizontal distance by size constancy, height over the image's length along
      its axis, over cos φ;
    - the foot's row: its elevation's tangent is the row's times cos φ, and it stands
      that far above the lens at the distance less ``front`` (how far before the axis
      the measured face stands: the foot it sees is that face's, which drops or rises
      with the image's lean towards the camera); ε is that rise at the distance.

    In an upright mirror this is :func:`seen3` of ``base`` exactly, at any pan (tested
    to 1e-9).  In a leaning one the image leans by twice the lean: shorter, its top
    nearer or farther, slanted across the line of sight, so each reading is biased; a
    fit that predicts the readings with this model removes the bias (docs/method.md).
    """
    o = np.asarray(observer, float)
    b = np.asarray(base, float)
    foot, top = plane.reflect(np.array([b, b + height * ZHAT]))
    if pan_deg is None:
        mid = (foot + top) / 2.0 - o
        pan = float(np.arctan2(mid[1], mid[0]))
    else:
        pan = float(np.radians(pan_deg))
    ahead = np.array([np.cos(pan), np.sin(pan), 0.0])
    right = np.array([np.sin(pan), -np.cos(pan), 0.0])

    def film(p: np.ndarray) -> np.ndarray:  # (right, up) over the depth along the axis
        q = p - o
        return np.array([q @ right, q[2]]) / (q @ ahead)

    f_foot, f_top = film(foot), film(top)
    phi = float(np.arctan((f_foot[0] + f_top[0]) / 2.0))
    horizontal = height / float(np.linalg.norm(f_top - f_foot)) / np.cos(phi)
    seen = foot
    if front:  # the near face's foot: towards the camera, across the image's axis
        axis = (top - foot) / height
        toward = (o - foot) - ((o - foot) @ axis) * axis
        seen = foot + front * toward / np.linalg.norm(toward)
    rise = float(film(seen)[1] * np.cos(phi)) * (horizontal - front)
    alpha = float(np.degrees(pan - phi))
    alpha = (alpha + 180.0) % 360.0 - 180.0
    return alpha, float(np.degrees(np.arctan2(rise, horizontal))), float(np.hypot(horizontal, rise))
