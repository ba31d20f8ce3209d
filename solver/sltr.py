"""SLTR: the mirror and the target from beacon measurements (paper sections 2 and 6).

The mirror is an infinite line in the board plane, ``n(θ)·x = ρ`` with
``n(θ) = (−sin θ, cos θ)``; an observation of a point is its angle of arrival α and
its path length d_total = d1 + d2, i.e. the bearing and distance of its virtual image.

* :func:`observe` is the forward model (eqs 1–6); :func:`locate` its inverse.
* :func:`solve_single` is the exact one-beacon solution: the mirror line is the
  perpendicular bisector of the beacon B and its virtual image B′ (eq 6 solved in
  closed form), the target is the reflection of its virtual image across that line.
* :func:`solve_lsq` fuses several beacon (and target) observations by weighted
  nonlinear least squares, with the first-order covariance from the analytic Jacobian.

A note on the paper's eq 1: it writes the second leg as d2·(cos(α − 2θ), sin(α − 2θ)).
A ray at bearing α reflected by a line at yaw θ leaves at bearing 2θ − α, so the sine
term's sign is wrong; everything here uses the physical 2θ − α.

All functions broadcast over leading axes where they say so; angles in degrees, lengths
in the caller's unit (cm in mirrorsim).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solver.errors import SolverError
from solver.geometry import line_normal, reflect, unit, wrap_bearing, wrap_yaw
from solver.measurements import GAUSSIAN, Tail

ArrayLike = np.typing.ArrayLike
EPS = 1e-9

__all__ = ["SolverError", "MirrorLine", "Observation", "Solution", "BatchEstimate", "observe",
           "locate", "mirror_from_beacon", "ray_hits_line", "solve_single",
           "closed_form_unchecked", "error_ellipse"]


@dataclass(frozen=True)
class MirrorLine:
    """An infinite mirror line: a direction ``yaw_deg`` in [0, 180) and a ``point`` on it."""

    yaw_deg: float
    point: np.ndarray

    @property
    def rho(self) -> float:
        """Offset of the line: n(yaw)·x = rho for points x on it."""
        return float(line_normal(self.yaw_deg) @ self.point)

    @classmethod
    def from_params(cls, theta_deg: float, rho: float) -> MirrorLine:
        """The line n(θ)·x = ρ."""
        n = line_normal(theta_deg)
        return cls(float(wrap_yaw(theta_deg)), rho * n)


@dataclass(frozen=True)
class Observation:
    """What the observer measures of a point through the mirror, and where it goes."""

    alpha_deg: np.ndarray | float
    d_total: np.ndarray | float
    d1: np.ndarray | float
    d2: np.ndarray | float
    virtual: np.ndarray
    reflection_point: np.ndarray


def observe(observer: ArrayLike, mirror_point: ArrayLike, yaw_deg: ArrayLike,
            *, point: ArrayLike, strict: bool = True) -> Observation:
    """Forward model (eqs 1–6): α, d1, d2 and d_total of ``point`` seen in the mirror.

    Broadcasts over leading axes.  The observer and the point must stand on the same
    side of the line (a mirror shows only what is in front of it).

    Raises
    ------
    SolverError
        If the point or the observer lies on the line, or they are on opposite sides
        (with ``strict=False`` the formulas are applied regardless).
    """
    o = np.asarray(observer, float)
    p = np.asarray(point, float)
    n = line_normal(yaw_deg)
    so = np.sum((o - np.asarray(mirror_point, float)) * n, axis=-1)
    sp = np.sum((p - np.asarray(mirror_point, float)) * n, axis=-1)
    if strict and (np.any(np.abs(so) < EPS) or np.any(np.abs(sp) < EPS)):
        raise SolverError("the observer or the point lies on the mirror line")
    if strict and np.any(so * sp < 0):
        raise SolverError("the point is behind the mirror (on the other side from the observer)")
    v = reflect(p, mirror_point, yaw_deg)
    rel = v - o
    d_total = np.hypot(rel[..., 0], rel[..., 1])
    t = so / (so - (-sp))  # the virtual image is -sp from the line
    r = o + t[..., None] * rel
    d1 = t * d_total
    return Observation(
        alpha_deg=wrap_bearing(np.rad2deg(np.arctan2(rel[..., 1], rel[..., 0]))),
        d_total=d_total, d1=d1, d2=d_total - d1, virtual=v, reflection_point=r)


def virtual_image(observer: ArrayLike, alpha_deg: ArrayLike, d_total: ArrayLike) -> np.ndarray:
    """The virtual image a measurement points at: observer + d_total·u(α) (broadcasts)."""
    return np.asarray(observer, float) + np.asarray(d_total, float)[..., None] * unit(alpha_deg)


def locate(observer: ArrayLike, mirror_point: ArrayLike, yaw_deg: ArrayLike,
           *, alpha_deg: ArrayLike, d_total: ArrayLike) -> np.ndarray:
    """Inverse of :func:`observe`: the point whose image has this α and d_total."""
    return reflect(virtual_image(observer, alpha_deg, d_total), mirror_point, yaw_deg)


# ----------------------------------------------------------------- closed form


@dataclass(frozen=True)
class Solution:
    """Mirror and target estimated from measurements."""

    mirror: MirrorLine
    target: np.ndarray
    target_reflection_point: np.ndarray
    beacon_reflection_points: np.ndarray  # (k, 2)
    covariance: np.ndarray | None = None  # of params_order: (θ [deg], ρ, x_t, y_t, …)
    method: str = "closed form"
    downweighted: tuple[str, ...] = ()  # measurements the robust fit trusted less
    # self-calibration's estimates (pan_offset_deg, range_scale, mirror_power_per_cm),
    # after θ, ρ, x_t, y_t in the covariance
    nuisances: dict[str, float] = field(default_factory=dict)
    # the priors' σ's the bench gave some of them (solver.selfcal.SelfCalibration's)
    priors: dict[str, float] = field(default_factory=dict)
    # how far the truth lies from the estimate in the covariance's σ's (the σ's' error
    # model's): where :meth:`ellipse95` and :meth:`inside95` draw the edge
    tail: Tail = GAUSSIAN

    @property
    def target_covariance(self) -> np.ndarray | None:
        """The target's 2×2 covariance block, if σ's were given."""
        return None if self.covariance is None else self.covariance[2:4, 2:4]

    @property
    def nuisance_sd(self) -> dict[str, float]:
        """Each estimated nuisance's σ, from the covariance (empty without σ's)."""
        if self.covariance is None:
            return {}
        sd = np.sqrt(np.diag(self.covariance))[4:4 + len(self.nuisances)]
        return {name: float(e) for name, e in zip(self.nuisances, sd, strict=True)}

    @property
    def params_order(self) -> list[str]:
        """The covariance's parameters: the mirror, the target, the nuisances, then each
        beacon's offset from its believed position where those were estimated."""
        names = ["mirror_yaw_deg", "mirror_rho", "target_x", "target_y", *self.nuisances]
        extra = 0 if self.covariance is None else len(self.covariance) - len(names)
        return names + [f"beacon{i // 2}_offset_{'xy'[i % 2]}" for i in range(extra)]

    def mahalanobis(self, point: ArrayLike) -> float | None:
        """How many σ's ``point`` lies from the estimated target, by its covariance
        (√(Δᵀ C⁻¹ Δ); its median over honest Gaussian estimates is χ₂'s, 1.18)."""
        cov = self.target_covariance
        if cov is None:
            return None
        delta = np.asarray(point, float) - self.target
        return float(np.sqrt(delta @ np.linalg.solve(cov, delta)))

    def ellipse95(self) -> tuple[float, float, float] | None:
        """The target's 95 % error ellipse: semi-axes (major, minor) and the major axis's
        bearing in degrees (its edge at :attr:`tail`'s 95 % radius)."""
        cov = self.target_covariance
        return None if cov is None else error_ellipse(cov, 0.95, tail=self.tail)

    def inside95(self, point: ArrayLike) -> bool | None:
        """Whether ``point`` lies inside the target's 95 % ellipse (None without σ's)."""
        m = self.mahalanobis(point)
        return None if m is None else bool(m <= self.tail.radius(0.95))

    def to_json(self) -> dict:
        """The solution document of docs/files.md."""
        out = {
            "mirror": {"yaw_deg": self.mirror.yaw_deg, "point": self.mirror.point.tolist()},
            "target": {"position": self.target.tolist(),
                       "reflection_point": self.target_reflection_point.tolist()},
            "beacon_reflection_points": self.beacon_reflection_points.tolist(),
            "method": self.method,
        }
        if self.downweighted:
            out["downweighted"] = list(self.downweighted)
        if self.nuisances:
            out["self_calibration"] = dict(self.nuisances)
        if self.priors:
            out["self_calibration_priors"] = dict(self.priors)
        if self.covariance is not None:
            major, minor, angle = self.ellipse95()
            out["covariance"] = {
                "target": self.target_covariance.tolist(),
                "params": self.covariance.tolist(),
                "params_order": self.params_order,
                "target_ellipse95": {"major": major, "minor": minor, "angle_deg": angle},
                "tail": self.tail.to_json(),
            }
        return out

    @classmethod
    def from_json(cls, d: dict) -> Solution:
        """Inverse of :meth:`to_json`."""
        cov = d.get("covariance", {}).get("params")
        return cls(mirror=MirrorLine(d["mirror"]["yaw_deg"], np.asarray(d["mirror"]["point"])),
                   target=np.asarray(d["target"]["position"], float),
                   target_reflection_point=np.asarray(d["target"]["reflection_point"], float),
                   beacon_reflection_points=np.asarray(d["beacon_reflection_points"], float),
                   covariance=None if cov is None else np.asarray(cov, float),
                   method=d["method"], downweighted=tuple(d.get("downweighted", ())),
                   nuisances=dict(d.get("self_calibration", {})),
                   priors=dict(d.get("self_calibration_priors", {})),
                   tail=Tail.from_json(d.get("covariance", {}).get("tail")))


def error_ellipse(cov: ArrayLike, level: float = 0.95, *, tail: Tail = GAUSSIAN
                  ) -> tuple[float, float, float]:
    """Semi-axes (major, minor) and major-axis bearing of the ``level`` region of an
    estimate of covariance ``cov`` whose errors spread as ``tail`` says (default: a
    Gaussian's)."""
    vals, vecs = np.linalg.eigh(np.asarray(cov, float))
    major, minor = tail.radius(level) * np.sqrt(np.maximum(vals[::-1], 0.0))
    v = vecs[:, 1]
    return float(major), float(minor), float(wrap_yaw(np.degrees(np.arctan2(v[1], v[0]))))


def mirror_from_beacon(observer: ArrayLike, beacon: ArrayLike, alpha_deg: ArrayLike,
                       *, d_total: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mirror line from one beacon: the perpendicular bisector of B and its image B′.

    Broadcasts.  Returns ``(yaw_deg, midpoint, beacon_reflection_point)``.

    Raises
    ------
    SolverError
        Negative or zero distance; B′ coinciding with B (the beacon on the mirror line);
        an image closer than the beacon itself (no mirror can produce it).
    """
    o, b = np.asarray(observer, float), np.asarray(beacon, float)
    d = np.asarray(d_total, float)
    if np.any(~np.isfinite(d)) or np.any(d <= 0):
        raise SolverError(f"beacon d_total must be positive, got {d}")
    yaw, mid, bv, sep = _bisector(o, b, alpha_deg, d)
    dist = np.hypot(sep[..., 0], sep[..., 1])
    if np.any(dist < 1e-6 * np.maximum(1.0, d)):
        raise SolverError("the beacon's image coincides with the beacon: it stands on the "
                          "mirror line, which is then undetermined")
    # B and B′ are at equal distances from every point of the mirror; the observer sees
    # B′ at d_total ≥ |O B| (the path via the mirror is never shorter than the direct one)
    direct = np.linalg.norm(b - o, axis=-1)
    if np.any(d < direct - 1e-9 * np.maximum(1.0, d)):
        raise SolverError(f"beacon d_total {_show(d)} is shorter than the beacon's direct "
                          f"distance {_show(direct)}: no mirror can produce this image")
    r = ray_hits_line(o, alpha_deg, mid, yaw_deg=yaw)
    return np.asarray(yaw), mid, r


def _show(x) -> str:
    """Numbers in messages: 3 decimals, scalars or arrays."""
    a = np.round(np.asarray(x, float), 3)
    return f"{float(a):g}" if a.ndim == 0 else np.array2string(a, separator=", ")


def _bisector(o: np.ndarray, b: np.ndarray, alpha_deg: ArrayLike, d_total: ArrayLike
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The perpendicular bisector of the beacon B and its virtual image B′ (broadcasts):
    ``(yaw_deg, midpoint, B′, B′ − B)``, unchecked."""
    bv = virtual_image(o, alpha_deg, d_total)
    sep = bv - b
    # B and B′ are at equal distances from every point of the mirror: the line is
    # perpendicular to B′ − B through their midpoint
    yaw = wrap_yaw(np.degrees(np.arctan2(sep[..., 1], sep[..., 0])) + 90.0)
    return yaw, (b + bv) / 2.0, bv, sep


def _ray_parameter(o, alpha_deg, point, yaw_deg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ray from o at bearing α against the line: its direction u, u·n and the
    parameter t where it meets the line (inf or nan where parallel), unchecked."""
    u = unit(alpha_deg)
    n = line_normal(yaw_deg)
    denom = np.sum(u * n, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.sum((np.asarray(point, float) - o) * n, axis=-1) / denom
    return u, denom, t


def ray_hits_line(o: ArrayLike, alpha_deg: float, point: ArrayLike, *,
                  yaw_deg: float) -> np.ndarray:
    """Where the ray from o at bearing α meets the line (raises if parallel or behind)."""
    u, denom, t = _ray_parameter(o, alpha_deg, point, yaw_deg)
    if np.any(np.abs(denom) < 1e-9):
        raise SolverError("the observation ray runs parallel to the mirror line")
    if np.any(t <= 0):
        raise SolverError("the mirror line lies behind the observer along this ray")
    return o + t[..., None] * u


def solve_single(observer: ArrayLike, beacon: ArrayLike, beacon_alpha_deg: ArrayLike,
                 *, beacon_d_total: ArrayLike, target_alpha_deg: ArrayLike,
                 target_d_total: ArrayLike) -> Solution:
    """Exact solution from one beacon and one target measurement (broadcasts).

    The mirror is the perpendicular bisector of the beacon and its virtual image; the
    target is the reflection of its virtual image across it; the target's reflection
    point is where its observation ray meets the mirror.
    """
    o = np.asarray(observer, float)
    dt = np.asarray(target_d_total, float)
    if np.any(~np.isfinite(dt)) or np.any(dt <= 0):
        raise SolverError(f"target d_total must be positive, got {dt}")
    yaw, mid, rb = mirror_from_beacon(o, beacon, beacon_alpha_deg, d_total=beacon_d_total)
    rt = ray_hits_line(o, target_alpha_deg, mid, yaw_deg=yaw)
    d1 = np.linalg.norm(rt - o, axis=-1)
    if np.any(dt <= d1):
        raise SolverError(f"target d_total {_show(dt)} does not reach past the mirror "
                          f"(the mirror is {_show(d1)} away along the target's ray)")
    target = locate(o, mid, yaw, alpha_deg=target_alpha_deg, d_total=dt)
    mirror = MirrorLine(float(yaw), mid) if np.ndim(yaw) == 0 else MirrorLine(yaw, mid)
    return Solution(mirror=mirror, target=target, target_reflection_point=rt,
                    beacon_reflection_points=np.atleast_2d(rb) if np.ndim(yaw) == 0 else rb)


@dataclass(frozen=True)
class BatchEstimate:
    """:func:`closed_form_unchecked`'s estimates, one per draw (arrays over draws)."""

    yaw_deg: np.ndarray
    mirror_point: np.ndarray
    target: np.ndarray
    target_reflection_point: np.ndarray


def closed_form_unchecked(observer: ArrayLike, beacon: ArrayLike, beacon_alpha_deg: ArrayLike,
                          *, beacon_d_total: ArrayLike, target_alpha_deg: ArrayLike,
                          target_d_total: ArrayLike) -> BatchEstimate:
    """:func:`solve_single`'s arithmetic without its checks, for Monte Carlo batches
    where a few noisy draws may be physically impossible (they still give a line)."""
    o, b = np.asarray(observer, float), np.asarray(beacon, float)
    yaw, mid, _, _ = _bisector(o, b, beacon_alpha_deg, beacon_d_total)
    u, _, t = _ray_parameter(o, target_alpha_deg, mid, yaw)
    return BatchEstimate(np.asarray(yaw), mid, locate(o, mid, yaw, alpha_deg=target_alpha_deg,
                                                       d_total=target_d_total),
                                                       o + t[..., None] * u)
