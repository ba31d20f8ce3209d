"""Beacon placement: the paper's geometry (eqs 7–21), its Algorithm 1, the two-beacon
orientation method of its ref. [26], and the best beacon position (beyond the paper).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from solver.fit_model import predict
from solver.geometry import line_normal, point_segment_distance, reflect, unit, wrap_bearing
from solver.measurements import ObjectSigmas, Sigma, as_object_sigmas
from solver.sltr import SolverError, observe


def _intersect(p, angle_p, q, angle_q) -> np.ndarray:
    """Intersection of the line through p at angle_p with the line through q at angle_q.

    The paper writes this with slopes (eqs 12–13, 16–17); direction vectors give the
    same point without the vertical-line singularity of tan.
    """
    d1, d2 = unit(angle_p), unit(angle_q)
    a = np.column_stack([d1, -d2])
    t = np.linalg.solve(a, np.asarray(q, float) - np.asarray(p, float))
    return np.asarray(p, float) + t[0] * d1


@dataclass(frozen=True)
class PlacementGeometry:
    """The paper's beacon area for one observation (eqs 9–18)."""

    b: float  # step size Δd along the observation line (eq 14)
    half_a: float  # a/2, the triangle's other leg (eq 18)
    R: np.ndarray  # the point at d_total on the observation line
    C: np.ndarray  # the reflector's edge (eq 9)
    inter1: np.ndarray  # eq 13
    inter2: np.ndarray  # eq 17
    n_beacons: float  # eq 8: 2·d_total / b

    @property
    def area(self) -> float:
        """Area of the right triangle with legs a/2 and b."""
        return 0.5 * self.half_a * self.b

    def triangle(self, alpha_deg: float, side: int = 1) -> np.ndarray:
        """Corners of the right triangle at R (legs along the observation line, towards
        the observer, and across it), as in the paper's Figs. 5–6."""
        back = -unit(alpha_deg) * self.b
        across = unit(alpha_deg + 90.0) * self.half_a * side
        return np.array([self.R, self.R + back, self.R + across])


def paper_placement(alpha_deg: float, d_total: float, s: float, *, eps_deg: float,
                    literal: bool = True) -> PlacementGeometry:
    """Step size b and half-width a/2 of the beacon area, eqs 9–18.

    ``literal=True`` follows the paper: the reflector at world angle θ = α − ε (eq 9),
    the reflected line at α − 2ε (eq 10), and eq 15's line at angle 90° − α.
    ``literal=False`` takes eq 15's line perpendicular to the observation line, as the
    text says it is ("the reflector at angle 90 w.r.t. the line observer"): α + 90°.
    """
    if s <= 0 or d_total <= 0 or not 0 < eps_deg < 90:
        raise ValueError("need s > 0, d_total > 0 and 0 < eps < 90 degrees")
    theta = alpha_deg - eps_deg
    R = d_total * unit(alpha_deg)
    C = R - (s / 2.0) * unit(theta)  # eq 9
    beta = alpha_deg - 2.0 * eps_deg  # eq 10's slope angle
    inter1 = _intersect(C, beta, R, alpha_deg)  # eqs 12–13
    b = float(np.linalg.norm(inter1 - R))  # eq 14
    perp = (90.0 - alpha_deg) if literal else (alpha_deg + 90.0)  # eq 15
    inter2 = _intersect(C, beta, R, perp)  # eqs 16–17
    half_a = float(np.linalg.norm(inter2 - R))  # eq 18
    return PlacementGeometry(b=b, half_a=half_a, R=R, C=C, inter1=inter1, inter2=inter2,
                             n_beacons=2.0 * d_total / b)


def visible_region(observer: ArrayLike, alpha_deg: float, d_total: float, *, s: float,
                   eps_deg: float,
                   grid: np.ndarray, n_orientations: int = 21) -> np.ndarray:
    """Exact version of the paper's area: grid points (k, 2) whose image the observer
    sees through a mirror of width ``s`` centred at R = d_total·u(α), for *every*
    orientation within ±ε of facing the observer square-on.
    """
    o = np.asarray(observer, float)
    R = o + d_total * unit(alpha_deg)
    ok = np.ones(len(grid), bool)
    for dth in np.linspace(-eps_deg, eps_deg, n_orientations):
        yaw = alpha_deg + 90.0 + dth
        n = line_normal(yaw)
        so = (o - R) @ n
        sp = (grid - R) @ n
        front = sp * so > 0
        obs = observe(o, R, yaw, point=np.where(front[:, None], grid, R + so * n * 0.5),
                      strict=False)
        off = (np.asarray(obs.reflection_point) - R) @ unit(yaw)
        ok &= front & (np.abs(off) <= s / 2.0)
    return ok


def region_area(observer: ArrayLike, alpha_deg: float, d_total: float, *, s: float, eps_deg: float,
                cell: float = 0.5, n_orientations: int = 11) -> float:
    """Area of :func:`visible_region`, counting grid cells.

    The reflected fields of view of the extreme orientations cross about
    (s/2)/tan(2ε) from the mirror, so the grid reaches 1.5 times that beyond R.
    """
    R = np.asarray(observer, float) + d_total * unit(alpha_deg)
    half = 1.5 * (s / 2) / math.tan(math.radians(2 * eps_deg)) + s
    xs = np.arange(-half, half, cell) + cell / 2
    gx, gy = np.meshgrid(xs, xs)
    grid = np.column_stack([gx.ravel(), gy.ravel()]) + R
    seen = visible_region(observer, alpha_deg, d_total, s=s, eps_deg=eps_deg, grid=grid,
                          n_orientations=n_orientations)
    return float(seen.sum()) * cell**2


# ---------------------------------------------------------------------- paths


def path_lengths(a: float, b: float, n: int) -> dict[str, float]:
    """Lengths of the moving beacon's three paths over n steps (eqs 19–21)."""
    if n < 1 or a < 0 or b < 0:
        raise ValueError("need n ≥ 1 and non-negative a, b")
    return {
        "linear": a + 2.0 * (n - 1) * b,  # eq 19
        "rectangular": a + (n - 1) * (a + b),  # eq 20
        "sawtooth": a + (n - 1) * (a + math.hypot(a, b)),  # eq 21
    }


def path_points(kind: str, origin: ArrayLike, alpha_deg: float, *, a: float, b: float, n: int
                ) -> np.ndarray:
    """Vertices of a path (for plots and the particle filter's simulated runs).

    Steps of b run along the observation line (towards the observer), a across it.
    """
    o = np.asarray(origin, float)
    along, across = -unit(alpha_deg), unit(alpha_deg + 90.0)
    pts = []
    if kind == "linear":
        pts = [o + across * a / 2 + along * b * i for i in range(n)]
        pts += [o - across * a / 2 + along * b * i for i in reversed(range(n))]
    elif kind == "rectangular":
        for i in range(n):
            side = 1 if i % 2 == 0 else -1
            pts += [o + along * b * i - across * a / 2 * side,
                    o + along * b * i + across * a / 2 * side]
    elif kind == "sawtooth":
        for i in range(n):
            pts += [o + along * b * i - across * a / 2, o + along * b * i + across * a / 2]
    else:
        raise ValueError(f"unknown path {kind!r}: linear, rectangular or sawtooth")
    return np.array(pts)


def polyline_length(points: np.ndarray) -> float:
    """Length of the path through ``points`` in order."""
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


# ------------------------------------------------------------------ Algorithm 1


def algorithm1(observer: ArrayLike, alpha_deg: float, d_total: float, *, s: float, eps_deg: float
               ) -> list[dict]:
    """The paper's Algorithm 1: reflector positions stepped along the observation line by
    Δd = b, two beacons per step, below the reflector on both sides of the line."""
    geo = paper_placement(alpha_deg, d_total, s, eps_deg=eps_deg)
    o = np.asarray(observer, float)
    steps = []
    d = geo.b
    while d <= d_total + 1e-9:  # eq 7: d = 0 … d_total in steps of Δd
        R = o + d * unit(alpha_deg)
        below = R - unit(alpha_deg) * geo.b / 2.0
        beacons = [below + side * unit(alpha_deg + 90.0) * geo.half_a / 2.0 for side in (1, -1)]
        steps.append({"d": d, "reflector": R, "beacons": np.array(beacons)})
        d += geo.b
    return steps


def orientation_from_beacons(observer: ArrayLike, reflector_point: ArrayLike, beacons: ArrayLike,
                             *, alphas_deg: ArrayLike, initial_yaw_deg: float) -> float:
    """Ref. [26]: the yaw of a reflector of known position from the angles of arrival
    of beacons seen in it (two or more; least squares in the one unknown)."""
    o = np.asarray(observer, float)
    bs = np.asarray(beacons, float)
    al = np.asarray(alphas_deg, float)

    def residual(x):
        v = reflect(bs, reflector_point, x[0])
        pred = np.degrees(np.arctan2(v[:, 1] - o[1], v[:, 0] - o[0]))
        return wrap_bearing(pred - al)

    res = least_squares(residual, [initial_yaw_deg], xtol=1e-14, ftol=1e-14)
    return float(res.x[0] % 180.0)


# ------------------------------------------------------------ best placement


@dataclass(frozen=True)
class MirrorPrior:
    """Mirror poses consistent with the target's measurement: the reflection point along
    the target's ray at ``d1`` ± ``d1_spread``, the yaw ± ``yaw_spread_deg``."""

    d1: float
    yaw_deg: float
    d1_spread: float = 5.0
    yaw_spread_deg: float = 5.0
    n: int = 5

    def poses(self, observer: ArrayLike, target_alpha_deg: float) -> list[tuple[np.ndarray, float]]:
        """Mirror poses (a point on the line, yaw) spread around the prior's centre."""
        out = []
        for dd in np.linspace(-self.d1_spread, self.d1_spread, self.n):
            for dy in np.linspace(-self.yaw_spread_deg, self.yaw_spread_deg, self.n):
                p = np.asarray(observer, float) + (self.d1 + dd) * unit(target_alpha_deg)
                out.append((p, self.yaw_deg + dy))
        return out


def implied_target(observer: np.ndarray, target_alpha_deg: float, target_d_total: float,
                   *, point: ArrayLike, yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """A mirror pose's (θ, ρ) and the target it implies for this target measurement: its
    virtual image reflected in the line (the (θ, ρ) form :func:`predict` differentiates)."""
    n = line_normal(yaw)
    params = np.array([yaw, n @ point])
    vt = observer + target_d_total * unit(target_alpha_deg)
    return params, vt - 2.0 * (n @ vt - params[1]) * n


def seen_in_mirror(observer: np.ndarray, points: np.ndarray, point: ArrayLike, *, yaw: float,
                   mirror_size: float, min_depth: float) -> np.ndarray:
    """Which points a mirror pose (a point on the line, its yaw) shows the observer: in
    front of it by ``min_depth``, their image on the glass of width ``mirror_size``."""
    n = line_normal(yaw)
    so, sp = (observer - point) @ n, (points - point) @ n
    obs = observe(observer, point, yaw, point=points, strict=False)
    off = (np.asarray(obs.reflection_point) - point) @ unit(yaw)
    return (sp * so > 0) & (np.abs(sp) >= min_depth) & (np.abs(off) <= mirror_size / 2)


def expected_target_error(observer: ArrayLike, target_alpha_deg: float, target_d_total: float,
                          *, beacons: np.ndarray, poses: list[tuple[np.ndarray, float]],
                          sigma: Sigma | ObjectSigmas, mirror_size: float, min_depth: float = 0.5
                          ) -> tuple[np.ndarray, np.ndarray]:
    """First-order RMS target error for each candidate beacon position over the mirror
    poses where it is seen, and the fraction of poses where it is seen.

    A beacon counts as seen when its image reaches the observer through the mirror of
    width ``mirror_size`` and it stands at least ``min_depth`` in front of it.  For one
    beacon and one target the four measurements determine the four unknowns (mirror θ,
    ρ and the target's x, y), so cov = J⁻¹ Σ J⁻ᵀ with J from :func:`predict`.

    Returns
    -------
    rmse : (k,) ``inf`` where never seen
    seen_fraction : (k,)
    """
    o = np.asarray(observer, float)
    B = np.asarray(beacons, float)
    sig = as_object_sigmas(sigma)
    st, sb = sig.target, sig.beacons[0]  # every candidate is one beacon, with its σ's
    total = np.zeros(len(B))
    count = np.zeros(len(B))
    for point, yaw in poses:
        params, tgt = implied_target(o, target_alpha_deg, target_d_total, point=point, yaw=yaw)
        _, d_b, da_b, dd_b = predict(np.r_[params, 0, 0], o, B)
        _, d_t, da_t, dd_t = predict(np.r_[params, tgt], o, tgt[None])
        J = np.zeros((len(B), 4, 4))
        J[:, 0, :2], J[:, 1, :2] = da_b[:, :2], dd_b[:, :2]
        J[:, 2, :], J[:, 3, :] = da_t[0], dd_t[0]
        sd = np.stack([np.full(len(B), sb.alpha_deg), sb.d_total_rel * d_b,
                       np.full(len(B), st.alpha_deg),
                       np.full(len(B), st.d_total_rel * d_t[0])], axis=1)
        with np.errstate(all="ignore"):
            Jinv = np.linalg.pinv(J)
            cov_t = np.einsum("kij,kj,klj->kil", Jinv[:, 2:, :], sd**2, Jinv[:, 2:, :])
            err2 = cov_t[:, 0, 0] + cov_t[:, 1, 1]
        seen = seen_in_mirror(o, B, point, yaw=yaw, mirror_size=mirror_size,
                              min_depth=min_depth) & np.isfinite(err2)
        total += np.where(seen, err2, 0.0)
        count += seen
    with np.errstate(divide="ignore", invalid="ignore"):
        rmse = np.where(count > 0, np.sqrt(total / np.maximum(count, 1)), np.inf)
    return rmse, count / len(poses)


@dataclass(frozen=True)
class BeaconSearch:
    """:func:`best_beacon`'s answer: the position, its expected target RMSE and the share
    of mirror poses that see it; and the whole grid's maps (``xs`` × ``ys``)."""

    position: np.ndarray
    rmse: float
    seen_fraction: float
    xs: np.ndarray
    ys: np.ndarray
    map: np.ndarray  # expected target RMSE (cm), inf where refused
    seen: np.ndarray


def best_beacon(observer: ArrayLike, target_alpha_deg: float, target_d_total: float,
                *, poses: list[tuple[np.ndarray, float]], sigma: Sigma | ObjectSigmas,
                mirror_size: float, board: tuple[float, float], step: float = 0.5,
                keep_out: list[tuple[np.ndarray, np.ndarray, float]] = (), min_seen: float = 1.0,
                accept: Callable[[np.ndarray], bool] | None = None) -> BeaconSearch:
    """Grid search over the board for the beacon position with the least expected
    target error among those seen under at least ``min_seen`` of the mirror poses (or,
    where none is, under as many as any position is).  ``keep_out`` holds segments
    (start, end, clearance) the beacon must avoid (walls, the mirror, the target);
    ``accept(position) -> bool``, if given, vets candidates in order of merit (e.g.
    that no wall blocks the path through the mirror)."""
    xs = np.arange(step / 2, board[0], step)
    ys = np.arange(step / 2, board[1], step)
    gx, gy = np.meshgrid(xs, ys)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    err, seen = expected_target_error(observer, target_alpha_deg, target_d_total, beacons=grid,
                                      poses=poses, sigma=sigma, mirror_size=mirror_size)
    for a, b, clear in keep_out:
        blocked = point_segment_distance(grid, a, b) < clear
        err[blocked], seen[blocked] = np.inf, 0.0
    if not (seen > 0).any():
        raise SolverError("no beacon position on the board is seen through the mirror")
    k, refused = -1, set()
    # the best position seen under ``min_seen`` of the poses; where ``accept`` refuses
    # every such one (a wide prior leaves a handful), the best under fewer poses
    for need in np.unique(seen[seen > 0])[::-1]:
        score = np.where(seen >= min(min_seen, need) - 1e-12, err, np.inf)
        for i in np.argsort(score):
            if not np.isfinite(score[i]):
                break
            if i not in refused:
                if accept is None or accept(grid[i]):
                    k = int(i)
                    break
                refused.add(i)
        if k >= 0:
            break
    if k < 0:
        raise SolverError("no beacon position on the board passes the placement's test "
                          "(its image unobstructed through the mirror)")
    return BeaconSearch(grid[k], float(err[k]), float(seen[k]), xs, ys,
                        err.reshape(gx.shape), seen.reshape(gx.shape))
