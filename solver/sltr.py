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

from dataclasses import dataclass, field, replace

import numpy as np

from solver.errors import SolverError
from solver.geometry import line_normal, reflect, unit, wrap_bearing, wrap_yaw

ArrayLike = np.typing.ArrayLike
EPS = 1e-9

__all__ = ["SolverError", "MirrorLine", "Observation", "Solution", "BeaconMeasurement",
           "Sigma", "observe", "locate", "solve_single", "solve_lsq", "solve_measurements"]


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
            point: ArrayLike, *, strict: bool = True) -> Observation:
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
    v = p - 2.0 * sp[..., None] * n
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
           alpha_deg: ArrayLike, d_total: ArrayLike) -> np.ndarray:
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
    covariance: np.ndarray | None = None  # of (θ [deg], ρ, x_t, y_t)
    residuals: np.ndarray | None = None  # weighted, at the solution
    method: str = "closed form"
    extra: dict = field(default_factory=dict)

    @property
    def target_covariance(self) -> np.ndarray | None:
        """The target's 2×2 covariance block, if σ's were given."""
        return None if self.covariance is None else self.covariance[2:, 2:]

    def ellipse95(self) -> tuple[float, float, float] | None:
        """The target's 95 % error ellipse: semi-axes (major, minor) and the major axis's
        bearing in degrees."""
        cov = self.target_covariance
        return None if cov is None else error_ellipse(cov, 0.95)

    def to_json(self) -> dict:
        """The solution document of INTERFACE.md."""
        out = {
            "mirror": {"yaw_deg": self.mirror.yaw_deg, "point": self.mirror.point.tolist()},
            "target": {"position": self.target.tolist(),
                       "reflection_point": self.target_reflection_point.tolist()},
            "beacon_reflection_points": self.beacon_reflection_points.tolist(),
            "method": self.method,
        }
        if self.covariance is not None:
            major, minor, angle = self.ellipse95()
            out["covariance"] = {
                "target": self.target_covariance.tolist(),
                "params": self.covariance.tolist(),
                "params_order": ["mirror_yaw_deg", "mirror_rho", "target_x", "target_y"],
                "target_ellipse95": {"major": major, "minor": minor, "angle_deg": angle},
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
                   method=d["method"])


def error_ellipse(cov: ArrayLike, level: float = 0.95) -> tuple[float, float, float]:
    """Semi-axes (major, minor) and major-axis bearing of a 2-D Gaussian's ``level`` region."""
    vals, vecs = np.linalg.eigh(np.asarray(cov, float))
    k = -2.0 * np.log(1.0 - level)  # the χ² quantile with 2 degrees of freedom
    major, minor = np.sqrt(k * np.maximum(vals[::-1], 0.0))
    v = vecs[:, 1]
    return float(major), float(minor), float(wrap_yaw(np.degrees(np.arctan2(v[1], v[0]))))


def mirror_from_beacon(observer: ArrayLike, beacon: ArrayLike, alpha_deg: ArrayLike,
                       d_total: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    bv = virtual_image(o, alpha_deg, d)
    sep = bv - b
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
    mid = (b + bv) / 2.0
    # the line is perpendicular to B′ − B
    yaw = wrap_yaw(np.degrees(np.arctan2(sep[..., 1], sep[..., 0])) + 90.0)
    r = _ray_hits_line(o, alpha_deg, mid, yaw)
    return np.asarray(yaw), mid, r


def _show(x) -> str:
    """Numbers in messages: 3 decimals, scalars or arrays."""
    a = np.round(np.asarray(x, float), 3)
    return f"{float(a):g}" if a.ndim == 0 else np.array2string(a, separator=", ")


def _ray_hits_line(o, alpha_deg, point, yaw_deg) -> np.ndarray:
    """Where the ray from o at bearing α meets the line (raises if parallel or behind)."""
    u = unit(alpha_deg)
    n = line_normal(yaw_deg)
    denom = np.sum(u * n, axis=-1)
    if np.any(np.abs(denom) < 1e-9):
        raise SolverError("the observation ray runs parallel to the mirror line")
    t = np.sum((np.asarray(point, float) - o) * n, axis=-1) / denom
    if np.any(t <= 0):
        raise SolverError("the mirror line lies behind the observer along this ray")
    return o + t[..., None] * u


def solve_single(observer: ArrayLike, beacon: ArrayLike, beacon_alpha_deg: ArrayLike,
                 beacon_d_total: ArrayLike, target_alpha_deg: ArrayLike,
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
    yaw, mid, rb = mirror_from_beacon(o, beacon, beacon_alpha_deg, beacon_d_total)
    rt = _ray_hits_line(o, target_alpha_deg, mid, yaw)
    d1 = np.linalg.norm(rt - o, axis=-1)
    if np.any(dt <= d1):
        raise SolverError(f"target d_total {_show(dt)} does not reach past the mirror "
                          f"(the mirror is {_show(d1)} away along the target's ray)")
    target = locate(o, mid, yaw, target_alpha_deg, dt)
    mirror = MirrorLine(float(yaw), mid) if np.ndim(yaw) == 0 else MirrorLine(yaw, mid)
    return Solution(mirror=mirror, target=target, target_reflection_point=rt,
                    beacon_reflection_points=np.atleast_2d(rb) if np.ndim(yaw) == 0 else rb)


def closed_form_unchecked(observer, beacon, beacon_alpha_deg, beacon_d_total,
                          target_alpha_deg, target_d_total) -> dict[str, np.ndarray]:
    """:func:`solve_single`'s arithmetic without its checks, for Monte Carlo batches
    where a few noisy draws may be physically impossible (they still give a line).

    Returns arrays ``yaw_deg``, ``mirror_point``, ``target``, ``target_reflection_point``.
    """
    o, b = np.asarray(observer, float), np.asarray(beacon, float)
    bv = virtual_image(o, beacon_alpha_deg, beacon_d_total)
    sep = bv - b
    yaw = wrap_yaw(np.degrees(np.arctan2(sep[..., 1], sep[..., 0])) + 90.0)
    mid = (b + bv) / 2.0
    u, n = unit(target_alpha_deg), line_normal(yaw)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.sum((mid - o) * n, axis=-1) / np.sum(u * n, axis=-1)
    return {"yaw_deg": np.asarray(yaw), "mirror_point": mid,
            "target": locate(o, mid, yaw, target_alpha_deg, target_d_total),
            "target_reflection_point": o + t[..., None] * u}


# --------------------------------------------------------------- least squares


@dataclass(frozen=True)
class BeaconMeasurement:
    """A beacon's known position and its image's measured α and d_total."""

    position: tuple[float, float]
    alpha_deg: float
    d_total: float


@dataclass(frozen=True)
class Sigma:
    """Measurement standard deviations: α in degrees, d_total relative (0.002 = 0.2 %)."""

    alpha_deg: float = 0.01
    d_total_rel: float = 0.002


def predict(params: np.ndarray, observer: np.ndarray, points: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """α, d of ``points`` (k, 2) seen in the mirror (θ, ρ) = params[:2], with derivatives.

    Returns
    -------
    alpha_deg, d : (k,)
    dalpha, dd : (k, 4)
        Derivatives with respect to (θ [deg], ρ, x, y) of the point.
    """
    theta, rho = params[0], params[1]
    th = np.radians(theta)
    n = np.array([-np.sin(th), np.cos(th)])
    dn = np.array([-np.cos(th), -np.sin(th)])  # dn/dθ (per radian)
    s = points @ n - rho
    v = points - 2.0 * s[:, None] * n
    rel = v - observer
    d = np.hypot(rel[:, 0], rel[:, 1])
    alpha = np.degrees(np.arctan2(rel[:, 1], rel[:, 0]))
    # dv/dθ = −2 (dn·p) n − 2 s dn ; dv/dρ = 2 n ; dv/dp = I − 2 n nᵀ
    dv_dth = (-2.0 * (points @ dn)[:, None] * n - 2.0 * s[:, None] * dn) * np.pi / 180.0
    dv_drho = np.broadcast_to(2.0 * n, v.shape)
    R = np.eye(2) - 2.0 * np.outer(n, n)
    # dα/dv = (−rel_y, rel_x)/d² (radians) ; dd/dv = rel/d
    ga = np.stack([-rel[:, 1], rel[:, 0]], axis=1) / d[:, None] ** 2 * (180.0 / np.pi)
    gd = rel / d[:, None]
    dalpha = np.column_stack([np.sum(ga * dv_dth, 1), np.sum(ga * dv_drho, 1), ga @ R])
    dd = np.column_stack([np.sum(gd * dv_dth, 1), np.sum(gd * dv_drho, 1), gd @ R])
    return alpha, d, dalpha, dd


def solve_lsq(observer: ArrayLike, beacons: list[BeaconMeasurement],
              targets: list[tuple[float, float]], sigma: Sigma | None = None,
              initial: Solution | None = None) -> Solution:
    """Weighted nonlinear least squares for the mirror line and the target.

    Parameters
    ----------
    observer : (2,)
    beacons : list of BeaconMeasurement
        One or more beacons, or several observations of one moving beacon.
    targets : list of (alpha_deg, d_total)
        One or more observations of the (static) target.
    sigma : Sigma, optional
        Weights and covariance; without it, unit weights in (0.01°, 0.2 %) are assumed
        and no covariance is reported.
    initial : Solution, optional
        Start point (default: the closed form of the first beacon).
    """
    if not beacons or not targets:
        raise SolverError("least squares needs at least one beacon and one target observation")
    o = np.asarray(observer, float)
    s = sigma or Sigma()
    if s.alpha_deg <= 0 or s.d_total_rel <= 0:
        raise SolverError(f"sigmas must be positive, got {s}")
    bpos = np.array([b.position for b in beacons], float)
    meas_a = np.array([b.alpha_deg for b in beacons] + [t[0] for t in targets], float)
    meas_d = np.array([b.d_total for b in beacons] + [t[1] for t in targets], float)
    if np.any(meas_d <= 0) or not np.all(np.isfinite(meas_d)) or not np.all(np.isfinite(meas_a)):
        raise SolverError("distances must be positive and all measurements finite")
    init = initial or solve_single(o, bpos[0], beacons[0].alpha_deg, beacons[0].d_total,
                                   targets[0][0], targets[0][1])
    x0 = np.array([init.mirror.yaw_deg, init.mirror.rho, *init.target])
    nb = len(beacons)
    w_a = np.full(len(meas_a), 1.0 / s.alpha_deg)
    w_d = 1.0 / (s.d_total_rel * meas_d)

    def points_of(x):
        return np.vstack([bpos, np.broadcast_to(x[2:], (len(targets), 2))])

    def fun(x):
        a, d, _, _ = predict(x, o, points_of(x))
        return np.concatenate([w_a * wrap_bearing(a - meas_a), w_d * (d - meas_d)])

    def jac(x):
        _, _, da, dd = predict(x, o, points_of(x))
        # beacons do not depend on the target's coordinates
        da[:nb, 2:] = 0.0
        dd[:nb, 2:] = 0.0
        return np.vstack([w_a[:, None] * da, w_d[:, None] * dd])

    from scipy.optimize import least_squares  # scipy is slow to import: only when used

    res = least_squares(fun, x0, jac=jac, method="lm" if len(meas_a) * 2 >= 4 else "trf",
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    x = res.x
    J = jac(x)
    jtj = J.T @ J
    if np.linalg.cond(jtj) > 1e14:
        raise SolverError("the measurements do not determine the mirror and the target "
                          "(singular Jacobian)")
    cov = np.linalg.inv(jtj) if sigma is not None else None
    line = MirrorLine.from_params(x[0], x[1])
    # report the foot of the first beacon on the line (the closed form's midpoint of B, B′)
    foot = bpos[0] - (line_normal(x[0]) @ bpos[0] - x[1]) * line_normal(x[0])
    mirror = MirrorLine(line.yaw_deg, foot)
    target = x[2:].copy()
    a_t = np.mean([t[0] for t in targets])
    rt = _ray_hits_line(o, a_t, mirror.point, mirror.yaw_deg)
    rb = np.array([observe(o, mirror.point, mirror.yaw_deg, p).reflection_point for p in bpos])
    return Solution(mirror=mirror, target=target, target_reflection_point=rt,
                    beacon_reflection_points=rb, covariance=cov, residuals=res.fun,
                    method=f"least squares ({nb} beacon obs, {len(targets)} target obs)")


def solve_measurements(observer, beacons: list[BeaconMeasurement],
                       targets: list[tuple[float, float]], sigma: Sigma | None = None
                       ) -> Solution:
    """The solver's front door: the closed form for one beacon and one target without
    σ's, weighted least squares (with covariance when σ's are given) otherwise."""
    if len(beacons) == 1 and len(targets) == 1:
        b = beacons[0]
        sol = solve_single(observer, b.position, b.alpha_deg, b.d_total, *targets[0])
        if sigma is None:
            return sol
        # four measurements, four unknowns: least squares is the closed form, and the
        # covariance is J⁻¹ Σ J⁻ᵀ (no iterations, and no scipy to import)
        params = np.array([sol.mirror.yaw_deg, sol.mirror.rho, *sol.target])
        o = np.asarray(observer, float)
        pts = np.vstack([np.asarray(b.position, float), sol.target])
        _, d, da, dd = predict(params, o, pts)
        J = np.array([[*da[0, :2], 0, 0], [*dd[0, :2], 0, 0], da[1], dd[1]])
        sd = np.array([sigma.alpha_deg, sigma.d_total_rel * b.d_total,
                       sigma.alpha_deg, sigma.d_total_rel * targets[0][1]])
        if abs(np.linalg.det(J)) < 1e-12:
            raise SolverError("the measurements do not determine the mirror and the target "
                              "(singular Jacobian)")
        Jinv = np.linalg.inv(J)
        cov = Jinv @ np.diag(sd**2) @ Jinv.T
        return replace(sol, covariance=cov, method="closed form with covariance")
    return solve_lsq(observer, beacons, targets, sigma)
