"""Weighted nonlinear least squares for the mirror line and the target from several
beacon (and target) observations, with the first-order covariance from the analytic
Jacobian; :func:`solve_measurements` is the solver's front door.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from solver.errors import SolverError
from solver.geometry import line_normal, unit, wrap_bearing
from solver.measurements import (
    BeaconMeasurement,
    ObjectSigmas,
    Sigma,
    as_object_sigmas,
    check_measurements,
)
from solver.selfcal import NUISANCES, PLAIN, SelfCalibration, as_calibration, check_nuisances
from solver.sltr import MirrorLine, Solution, observe, ray_hits_line, solve_single

ArrayLike = np.typing.ArrayLike
# residuals beyond this many σ's weigh less (a Huber loss): a gross error in one image
HUBER_K = 3.0


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
    # the reflection written out in (θ, ρ): its derivatives below need s, n and dn
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
              targets: list[tuple[float, float]], *, sigma: Sigma | ObjectSigmas | None = None,
              initial: Solution | None = None,
              calibration: SelfCalibration = PLAIN) -> Solution:
    """Weighted nonlinear least squares for the mirror line and the target.

    Parameters
    ----------
    observer : (2,)
    beacons : list of BeaconMeasurement
        One or more beacons, or several observations of one moving beacon.
    targets : list of (alpha_deg, d_total)
        One or more observations of the (static) target.
    sigma : Sigma or ObjectSigmas, optional
        Weights and covariance (one pair for all, or per observation); without it,
        unit weights in (0.01°, 0.2 %) are assumed and no covariance is reported.
    initial : Solution, optional
        Start point (default: the closed form of the first beacon; with nuisances or a
        position σ, the plain fit's).
    calibration : SelfCalibration, optional
        What to self-calibrate: the nuisances estimated jointly with the mirror (the
        target comes out corrected for them), how well the beacons' positions are known
        (each beacon's offset from its believed position then estimated with that
        prior: a misplaced beacon moves its own image's fit, not the nuisances), and
        the nuisances' priors, as a bench whose pan reading is good to ±0.5° knows (a
        pan prior adds to the σ's shared α offset: their variances add).  Where the
        beacons barely separate the nuisances from the mirror, a prior keeps the
        estimate from trading a large nuisance for the measurements' noise.

    Raises
    ------
    SolverError
        Too few measurements for the unknowns, or a geometry that does not determine
        them (saying which).
    """
    if not beacons or not targets:
        raise SolverError("least squares needs at least one beacon and one target observation")
    nuisances, priors = calibration.nuisances, calibration.priors
    check_nuisances(nuisances, len(beacons), len(targets), priors=priors)
    o = np.asarray(observer, float)
    sig = as_object_sigmas(sigma or Sigma())
    bpos, meas_a, meas_d = _measurement_arrays(beacons, targets)
    shared = sig.shared_alpha_deg
    if initial is None and (nuisances or calibration.position_sigma or shared):
        # start from the plain fit: from the one-beacon closed form, a pan offset and a
        # range scale let the fit wander to a mirror on the far side of a beacon
        initial = solve_lsq(observer, beacons, targets,
                            sigma=replace(sig, shared_alpha_deg=0.0) if shared else sigma)
    init = initial or solve_single(o, bpos[0], beacons[0].alpha_deg,
                                   beacon_d_total=beacons[0].d_total,
                                   target_alpha_deg=targets[0][0], target_d_total=targets[0][1])
    p = _Problem.of(o, bpos, len(targets), sig, calibration, meas_d)
    unknown, free, known, nb, nt = p.unknown, p.free, p.known, len(beacons), len(targets)
    x0 = np.concatenate([[init.mirror.yaw_deg, init.mirror.rho, *init.target], p.neutral[4:]])
    implicit = unknown != nuisances

    def fun(x):
        a, d, _, _ = _forward(x, o, bpos, nt, unknown, free)
        return np.concatenate([p.w_a * wrap_bearing(a - meas_a), p.w_d * (d - meas_d),
                               p.prior @ (x - p.neutral)])

    def jac(x):
        return p.jacobian(x, o, bpos)

    from scipy.optimize import least_squares  # scipy is slow to import: only when used

    # more measurements than unknowns: a Huber loss, so that one bad image (a residual
    # beyond HUBER_K σ's) does not drag the estimate; it is named in the solution
    robust = len(meas_a) * 2 + len(p.prior) > len(x0)
    res = least_squares(fun, x0, jac=jac, method="trf" if robust else "lm",
                        loss="huber" if robust else "linear", f_scale=HUBER_K,
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    r = fun(res.x)
    w = np.where(np.abs(r) > HUBER_K, HUBER_K / np.maximum(np.abs(r), 1e-300), 1.0)
    J = jac(res.x)
    jtj = J.T @ (w[:, None] * J)
    if np.linalg.cond(jtj) > 1e14:
        raise SolverError(_undetermined(nuisances))
    cov = np.linalg.inv(jtj) if sigma is not None else None
    if cov is not None and implicit:  # the shared α's own unknown: marginalized out
        keep = [i for i in range(len(x0)) if i != 4 + len(nuisances)]
        cov = cov[np.ix_(keep, keep)]
    names = (_residual_names(nb, nt)
             + [f"the {n} prior" if n in priors else "the shared α offset's prior"
                for n in unknown if n in known]
             + [f"beacon {i} believed {c}" for i in range(nb) for c in "xy"])
    down = tuple(f"{names[i]} ({abs(r[i]):.1f} σ off)" for i in np.flatnonzero(w < 1.0))
    sol = _solution(o, res.x[:4], bpos, targets, cov)
    return replace(sol, downweighted=down, priors=dict(priors),
                   nuisances={NUISANCES[n][0]: float(v)
                              for n, v in zip(nuisances, res.x[4:4 + len(nuisances)],
                                              strict=True)},
                   method=sol.method + (f", self-calibrated ({', '.join(nuisances)})"
                                        if nuisances else "")
                   + (f", with priors ({calibration.describe_priors()})"
                      if priors else "")
                   + (f", a shared α offset of prior σ {shared:.3g}° estimated" if implicit
                      else ""))


@dataclass(frozen=True)
class _Problem:
    """What a weighted fit of the mirror and the target weighs, declared once for the
    solve and for its Cramér–Rao bound: the unknowns (the mirror, the target, the
    nuisances, each beacon's offset where positions are uncertain), the measurements'
    weights and each prior's row (x − neutral)/σ."""

    unknown: tuple[str, ...]  # the nuisances estimated, "pan" added for a shared α offset
    free: bool  # each beacon's offset from its believed position estimated
    known: dict[str, float]  # each nuisance's prior σ, the shared α offset's included
    nt: int
    w_a: np.ndarray  # 1/σ of each α (beacons, then targets)
    w_d: np.ndarray  # 1/σ (cm) of each d_total
    prior: np.ndarray  # the prior rows
    neutral: np.ndarray  # every unknown's neutral value (mirror and target: 0)

    @classmethod
    def of(cls, o: np.ndarray, bpos: np.ndarray, nt: int, sig: ObjectSigmas,
           calibration: SelfCalibration, d_cm: np.ndarray) -> _Problem:
        """The problem of ``bpos`` beacons and ``nt`` target observations with σ's
        ``sig`` (a relative σ_d taken of ``d_cm``: the measured d_totals for a solve, the
        true ones for a bound)."""
        del o  # the weights do not depend on the camera: kept for symmetry of callers
        nuisances, position_sigma = calibration.nuisances, calibration.position_sigma
        sa, sd = sig.arrays(len(bpos), nt)
        shared = sig.shared_alpha_deg
        free = position_sigma > 0
        # a shared α offset (a bench's pan reading) is an unknown δ on every α with the
        # prior N(0, shared²): for Gaussian errors the same estimate and covariance as
        # correlated α's, while each image keeps its own residual row for the Huber loss
        # to weigh and name (whitened rows would mix a bad image into every later one)
        implicit = bool(shared) and "pan" not in nuisances
        unknown = nuisances + (("pan",) if implicit else ())
        k, nb = len(unknown), len(bpos)
        n_x = 4 + k + (2 * nb if free else 0)
        eye = np.eye(n_x)
        # a pan prior and the σ's shared α offset are independent errors of one reading
        # (the bench's tolerance, the mount's scatter): their variances add
        known = {"pan": shared} if shared else {}
        known |= {n: float(np.hypot(v, known.get(n, 0.0)))
                  for n, v in calibration.priors.items()}
        prior = np.vstack([*(eye[[4 + unknown.index(n)]] / known[n] for n in unknown
                             if n in known),
                           eye[4 + k:] / position_sigma if free else eye[:0]])
        neutral = np.concatenate([np.zeros(4), [NUISANCES[n][1] for n in unknown],
                                  np.zeros(n_x - 4 - k)])
        return cls(unknown, free, known, nt, 1.0 / sa, 1.0 / (sd * np.asarray(d_cm, float)),
                   prior, neutral)

    def jacobian(self, x: np.ndarray, o: np.ndarray, bpos: np.ndarray) -> np.ndarray:
        """The weighted residuals' Jacobian at ``x``: the measurements', then the priors'."""
        _, _, da, dd = _forward(x, o, bpos, self.nt, self.unknown, self.free)
        return np.vstack([self.w_a[:, None] * da, self.w_d[:, None] * dd, self.prior])


def _forward(x: np.ndarray, o: np.ndarray, bpos: np.ndarray, nt: int,
             nuisances: tuple[str, ...], free: bool = False) -> tuple[np.ndarray, ...]:
    """α and d_total of every observation (beacons, then nt of the target) for the
    parameters x = (θ, ρ, x_t, y_t, *nuisances[, each beacon's offset from its believed
    position, with ``free``]), and their derivatives (k, len(x))."""
    nb, k = len(bpos), len(nuisances)
    offsets = x[4 + k:].reshape(nb, 2) if free else np.zeros((nb, 2))
    pts = np.vstack([bpos + offsets, np.broadcast_to(x[2:4], (nt, 2))])
    a, d, da, dd = predict(x[:4], o, pts)
    oa, od = np.zeros((len(a), 2 * nb if free else 0)), np.zeros((len(a), 2 * nb if free else 0))
    if free:  # a beacon's image moves with its own position
        for i in range(nb):
            oa[i, 2 * i:2 * i + 2], od[i, 2 * i:2 * i + 2] = da[i, 2:], dd[i, 2:]
    da[:nb, 2:] = 0.0  # a beacon's image does not move with the target
    dd[:nb, 2:] = 0.0
    where = {name: 4 + j for j, name in enumerate(nuisances)}
    power = None
    if "power" in where:  # the mirror's curvature first: the pan and the scale act after it
        # the vertex: the middle of the images' reflection points (the target's once)
        seen = observe(o, x[1] * line_normal(x[0]), x[0], point=pts, strict=False)
        power = _power_of(seen, x[0], x[1], o, pts,
                          vertex=seen.reflection_point[:nb + 1].mean(axis=0))
        a, d = a + x[where["power"]] * power[0], d + x[where["power"]] * power[1]
    ea, ed = nuisance_columns(nuisances, d, power)
    if "pan" in where:
        a = a + x[where["pan"]]
    if "scale" in where:  # every d_total, and its derivatives, times s
        j, v = where["scale"], x[where["scale"]]
        dd, od, ed = dd * v, od * v, ed * v
        ed[:, j - 4] = d
        d = d * v
    return a, d, np.hstack([da, ea, oa]), np.hstack([dd, ed, od])


def nuisance_columns(nuisances: tuple[str, ...], d: np.ndarray,
                     power: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """How each observation's α and d_total move per unit of each nuisance (at s = 1):
    the pan moves every α by 1, the scale every d_total by itself, the power each image
    by :func:`power_terms`' (A, D), given as ``power`` (derivatives with respect to the
    mirror and the target that the power's terms carry are second order, left out)."""
    ea, ed = np.zeros((len(d), len(nuisances))), np.zeros((len(d), len(nuisances)))
    for j, name in enumerate(nuisances):
        if name == "pan":
            ea[:, j] = 1.0
        elif name == "scale":
            ed[:, j] = d
        else:
            ea[:, j], ed[:, j] = power
    return ea, ed


def power_terms(mirror: tuple[float, float], observer: np.ndarray, points: np.ndarray,
                *, vertex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First-order change of each point's image per unit of the mirror's power c = 1/R
    (1/cm, > 0 concave), the mirror (θ, ρ) curved about ``vertex`` (a point on its
    line).

    At a reflection point u cm along the line from the vertex the glass is turned by
    c·u and stands c·u²/2 nearer the camera, which moves the virtual image by
    c·(2u·((q·a)·n + (q·n)·a) + u²·n) (q: the point from the reflection point, a along
    the line, n its normal toward the camera): across the line of sight that is its
    α's change, along it a shorter path (c·u²·cos i).  The image is also magnified by
    the mirror's sagittal power 2·c·cos i, which size constancy reads as nearer
    (−2·c·cos i·d1·d2, the mirror equation).  To first order a vertex elsewhere on the
    line is a turn and a shift of the line: it changes (θ, ρ), not the target.

    Returns
    -------
    dalpha_deg, dd : (k,)
        α's change (deg) and d_total's change (cm) per unit c.
    """
    theta, rho = mirror
    obs = observe(observer, rho * line_normal(theta), theta, point=points, strict=False)
    return _power_of(obs, theta, rho, observer, points, vertex)


def _power_of(obs, theta: float, rho: float, observer: np.ndarray, points: np.ndarray,
              vertex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`power_terms` from the points' images in the flat mirror, already
    observed (the solver's forward model has them)."""
    a, n = unit(theta), line_normal(theta)
    P = obs.reflection_point
    rel = obs.virtual - observer  # the line of sight to each image
    dist = np.asarray(obs.d_total)
    nc = n if observer @ n > rho else -n  # the normal on the camera's side
    q = points - P
    u = ((P - vertex) @ a)[:, None]
    dv = 2.0 * u * ((q @ a)[:, None] * nc + (q @ nc)[:, None] * a) + u**2 * nc
    dalpha = np.degrees((rel[:, 0] * dv[:, 1] - rel[:, 1] * dv[:, 0]) / dist**2)
    cos_i = np.abs(rel @ n) / dist
    return dalpha, np.sum(rel * dv, axis=1) / dist - 2.0 * cos_i * obs.d1 * obs.d2


def _undetermined(nuisances: tuple[str, ...]) -> str:
    if not nuisances:
        return "the measurements do not determine the mirror and the target (singular Jacobian)"
    return (f"the beacons do not separate {' and '.join(nuisances)} from the mirror (singular "
            "Jacobian): their virtual images are too close together or in line with the "
            "camera" + (", or their reflection points too close together along the mirror"
                        if "power" in nuisances else "") + "; spread the beacons along the mirror")


def _residual_names(nb: int, nt: int) -> list[str]:
    """The residuals' measurements, in their order: every α (beacons, then targets),
    then every d_total."""
    who = [f"beacon {i}" for i in range(nb)] + (
        ["target"] if nt == 1 else [f"target {k}" for k in range(nt)])
    return [f"{w} α" for w in who] + [f"{w} d_total" for w in who]


def _measurement_arrays(beacons: list[BeaconMeasurement], targets: list[tuple[float, float]]
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beacon positions, then every α and every d_total (beacons first), checked."""
    bpos = np.array([b.position for b in beacons], float)
    meas_a = np.array([b.alpha_deg for b in beacons] + [t[0] for t in targets], float)
    meas_d = np.array([b.d_total for b in beacons] + [t[1] for t in targets], float)
    if np.any(meas_d <= 0) or not np.all(np.isfinite(meas_d)) or not np.all(np.isfinite(meas_a)):
        raise SolverError("distances must be positive and all measurements finite")
    return bpos, meas_a, meas_d


def _solution(o: np.ndarray, x: np.ndarray, bpos: np.ndarray,
              targets: list[tuple[float, float]], cov: np.ndarray | None) -> Solution:
    """The least-squares parameters (θ, ρ, x_t, y_t) as a :class:`Solution`."""
    line = MirrorLine.from_params(x[0], x[1])
    # report the foot of the first beacon on the line (the closed form's midpoint of B, B′)
    foot = bpos[0] - (line_normal(x[0]) @ bpos[0] - x[1]) * line_normal(x[0])
    mirror = MirrorLine(line.yaw_deg, foot)
    a_t = np.mean([t[0] for t in targets])
    rt = ray_hits_line(o, a_t, mirror.point, yaw_deg=mirror.yaw_deg)
    rb = np.array([observe(o, mirror.point, mirror.yaw_deg,
                           point=p).reflection_point for p in bpos])
    return Solution(mirror=mirror, target=x[2:].copy(), target_reflection_point=rt,
                    beacon_reflection_points=rb, covariance=cov,
                    method=f"least squares ({len(bpos)} beacon obs, {len(targets)} target obs)")


def crlb(observer: ArrayLike, beacons: ArrayLike, mirror_yaw_deg: float, *, mirror_rho: float,
         target: ArrayLike, sigma: Sigma | ObjectSigmas, n_targets: int = 1,
         nuisances: tuple[str, ...] = (), calibration: SelfCalibration | None = None
         ) -> np.ndarray:
    """The Cramér–Rao bound of (θ [deg], ρ, x_t, y_t, *nuisances, …): the inverse of the
    Fisher information at the true mirror and target (nuisances at their neutral values,
    beacons where believed), for Gaussian measurement errors of these σ's, of the
    estimator :func:`solve_lsq` runs with ``calibration`` (its nuisances, their priors,
    the beacons' position σ; default: ``nuisances`` without priors, positions exact).

    The bound is the same information the solve's covariance inverts, taken at the
    truth instead of the estimate: the two differ only by the linearization's point (and
    by the robust fit's down-weighting, which widens the covariance).  No unbiased
    estimator's covariance is smaller; for one beacon and one target the four
    measurements fix the four unknowns and the bound is J⁻¹ Σ J⁻ᵀ.

    Raises
    ------
    SolverError
        When the geometry does not determine the unknowns (singular information).
    """
    o = np.asarray(observer, float)
    B = np.atleast_2d(np.asarray(beacons, float))
    calibration = SelfCalibration(tuple(nuisances)) if calibration is None else calibration
    check_nuisances(calibration.nuisances, len(B), n_targets, priors=calibration.priors)
    sig = as_object_sigmas(sigma)
    t = np.asarray(target, float)
    x4 = np.array([mirror_yaw_deg, mirror_rho, *t])
    _, d, _, _ = predict(x4, o, np.vstack([B, np.broadcast_to(t, (n_targets, 2))]))
    p = _Problem.of(o, B, n_targets, sig, calibration, d)
    x = np.concatenate([x4, p.neutral[4:]])
    J = p.jacobian(x, o, B)
    info = J.T @ J
    if np.linalg.cond(info) > 1e14:
        raise SolverError("the geometry does not determine the mirror and the target "
                          "(singular Fisher information)")
    bound = np.linalg.inv(info)
    if len(p.unknown) > len(calibration.nuisances):  # the shared α's implicit pan: not asked
        keep = [i for i in range(len(x)) if i != 4 + len(calibration.nuisances)]
        bound = bound[np.ix_(keep, keep)]
    return bound


def solve_measurements(observer: ArrayLike, beacons: list[BeaconMeasurement],
                       targets: list[tuple[float, float]],
                       *, sigma: Sigma | ObjectSigmas | None = None,
                       calibration: SelfCalibration = PLAIN) -> Solution:
    """The solver's front door: the closed form for one beacon and one target without
    σ's and without self-calibration, weighted least squares (with covariance when σ's
    are given) otherwise.

    Parameters
    ----------
    observer : (x, y)
        The camera's position (cm).
    beacons : list of BeaconMeasurement
        Each beacon's known position and its image's α (deg) and d_total (cm).
    targets : list of (alpha_deg, d_total)
        The target's image, once or once per frame.
    sigma : Sigma or ObjectSigmas, optional
        The measurements' σ's: they weigh the fit and give the covariance.
    calibration : SelfCalibration
        What to self-calibrate (default: nothing).

    Raises
    ------
    SolverError
        Measurements that are not finite, or a d_total outside
        :data:`~solver.measurements.D_TOTAL_RANGE_CM`; σ's out of their range; geometry
        that does not determine the unknowns.
    """
    check_measurements(observer, beacons, targets)
    calibration = as_calibration(calibration)
    if sigma is not None:
        as_object_sigmas(sigma)  # its type, before the closed form or a fit uses it
    if (len(beacons) == 1 and len(targets) == 1 and not calibration.nuisances
            and not calibration.position_sigma):
        b = beacons[0]
        sol = solve_single(observer, b.position, b.alpha_deg, beacon_d_total=b.d_total,
                           target_alpha_deg=targets[0][0], target_d_total=targets[0][1])
        if sigma is None:
            return sol
        # four measurements, four unknowns: least squares is the closed form, and the
        # covariance is J⁻¹ Σ J⁻ᵀ (no iterations, and no scipy to import)
        params = np.array([sol.mirror.yaw_deg, sol.mirror.rho, *sol.target])
        o = np.asarray(observer, float)
        pts = np.vstack([np.asarray(b.position, float), sol.target])
        _, d, da, dd = predict(params, o, pts)
        J = np.array([[*da[0, :2], 0, 0], [*dd[0, :2], 0, 0], da[1], dd[1]])
        sig = as_object_sigmas(sigma)
        sa, sr = sig.arrays(1, 1)
        sd = np.array([sa[0], sr[0] * b.d_total, sa[1], sr[1] * targets[0][1]])
        if abs(np.linalg.det(J)) < 1e-12:
            raise SolverError("the measurements do not determine the mirror and the target "
                              "(singular Jacobian)")
        Jinv = np.linalg.inv(J)
        S = np.diag(sd**2)
        S[np.ix_([0, 2], [0, 2])] = sig.alpha_covariance(sa)  # rows (α_b, d_b, α_t, d_t)
        cov = Jinv @ S @ Jinv.T
        return replace(sol, covariance=cov, method="closed form with covariance")
    return solve_lsq(observer, beacons, targets, sigma=sigma, calibration=calibration)
