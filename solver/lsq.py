"""Weighted nonlinear least squares for the mirror line and the target from several
beacon (and target) observations, with the first-order covariance from the analytic
Jacobian; :func:`solve_measurements` is the solver's front door.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from solver.errors import SolverError
from solver.fit_model import FitProblem, forward, predict
from solver.geometry import line_normal, wrap_bearing
from solver.measurements import (
    BeaconMeasurement,
    ObjectSigmas,
    Sigma,
    as_object_sigmas,
    check_measurements,
)
from solver.selfcal import (
    NUISANCES,
    PLAIN,
    SelfCalibration,
    as_calibration,
    check_nuisances,
    check_planar,
)
from solver.sltr import MirrorLine, Solution, observe, ray_hits_line, solve_single

ArrayLike = np.typing.ArrayLike
# residuals beyond this many σ's weigh less (a Huber loss): a gross error in one image
HUBER_K = 3.0


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
    nuisances, priors = check_planar(calibration).nuisances, calibration.priors
    check_nuisances(nuisances, len(beacons), len(targets), priors=priors)
    o = np.asarray(observer, float)
    sig = as_object_sigmas(sigma or Sigma())
    bpos, meas_a, meas_d = _measurement_arrays(beacons, targets)
    shared = sig.shared_alpha_deg
    init = initial or _start(o, beacons, targets, sigma=sigma, calibration=calibration)
    p = FitProblem.of(bpos, len(targets), sig, calibration=calibration, d_cm=meas_d)
    x0 = np.concatenate([[init.mirror.yaw_deg, init.mirror.rho, *init.target], p.neutral[4:]])
    fit = _robust_fit(p, x0, o, bpos, meas_a=meas_a, meas_d=meas_d)
    if np.linalg.cond(fit.jtj) > 1e14:
        raise SolverError(_undetermined(nuisances))
    implicit = p.unknown != nuisances
    cov = np.linalg.inv(fit.jtj) if sigma is not None else None
    if cov is not None and implicit:  # the shared α's own unknown: marginalized out
        cov = np.delete(np.delete(cov, 4 + len(nuisances), 0), 4 + len(nuisances), 1)
    sol = _solution(o, fit.x[:4], bpos, targets, cov)
    return replace(sol, downweighted=_downweighted(p, fit, len(beacons), priors),
                   priors=dict(priors),
                   nuisances={NUISANCES[n][0]: float(v)
                              for n, v in zip(nuisances, fit.x[4:4 + len(nuisances)],
                                              strict=True)},
                   method=sol.method + _method_notes(calibration, shared, implicit=implicit))


def _start(o: np.ndarray, beacons: list[BeaconMeasurement], targets: list[tuple[float, float]],
           *, sigma: Sigma | ObjectSigmas | None, calibration: SelfCalibration) -> Solution:
    """Where the fit starts: the one-beacon closed form; with nuisances, a position σ or a
    shared α offset, the plain fit from it (from the closed form, a pan offset and a
    range scale let the fit wander to a mirror on the far side of a beacon)."""
    sig = as_object_sigmas(sigma or Sigma())
    shared = sig.shared_alpha_deg
    if calibration.nuisances or calibration.position_sigma or shared:
        return solve_lsq(o, beacons, targets,
                         sigma=replace(sig, shared_alpha_deg=0.0) if shared else sigma)
    b = beacons[0]
    return solve_single(o, b.position, b.alpha_deg, beacon_d_total=b.d_total,
                        target_alpha_deg=targets[0][0], target_d_total=targets[0][1])


@dataclass(frozen=True)
class _Fit:
    """A robust fit's end: the parameters, the weighted residuals, each residual's Huber
    weight (1 inside HUBER_K σ's) and the weighted information JᵀWJ."""

    x: np.ndarray
    r: np.ndarray
    w: np.ndarray
    jtj: np.ndarray


def _robust_fit(p: FitProblem, x0: np.ndarray, o: np.ndarray, bpos: np.ndarray, *,
                meas_a: np.ndarray, meas_d: np.ndarray) -> _Fit:
    """The least-squares fit of ``p`` from ``x0``: with more measurements than unknowns a
    Huber loss, so that one bad image (a residual beyond HUBER_K σ's) does not drag the
    estimate; it is named in the solution."""
    from scipy.optimize import least_squares  # scipy is slow to import: only when used

    def fun(x):
        a, d, _, _ = forward(x, o, bpos, nt=p.nt, nuisances=p.unknown, free=p.free)
        return np.concatenate([p.w_a * wrap_bearing(a - meas_a), p.w_d * (d - meas_d),
                               p.prior @ (x - p.neutral)])

    def jac(x):
        return p.jacobian(x, o, bpos)

    robust = len(meas_a) * 2 + len(p.prior) > len(x0)
    res = least_squares(fun, x0, jac=jac, method="trf" if robust else "lm",
                        loss="huber" if robust else "linear", f_scale=HUBER_K,
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    r = fun(res.x)
    w = np.where(np.abs(r) > HUBER_K, HUBER_K / np.maximum(np.abs(r), 1e-300), 1.0)
    J = jac(res.x)
    return _Fit(res.x, r, w, J.T @ (w[:, None] * J))


def _downweighted(p: FitProblem, fit: _Fit, nb: int, priors: dict[str, float]
                  ) -> tuple[str, ...]:
    """The residuals the Huber loss weighed down, each named with how many σ's off."""
    names = (_residual_names(nb, p.nt)
             + [f"the {n} prior" if n in priors else "the shared α offset's prior"
                for n in p.unknown if n in p.known]
             + [f"beacon {i} believed {c}" for i in range(nb) for c in "xy"])
    return tuple(f"{names[i]} ({abs(fit.r[i]):.1f} σ off)" for i in np.flatnonzero(fit.w < 1.0))


def _method_notes(calibration: SelfCalibration, shared: float, *, implicit: bool) -> str:
    """What the solution's method adds to the plain fit's: the nuisances, their priors,
    a shared α offset estimated."""
    nuisances, priors = calibration.nuisances, calibration.priors
    return ((f", self-calibrated ({', '.join(nuisances)})" if nuisances else "")
            + (f", with priors ({calibration.describe_priors()})" if priors else "")
            + (f", a shared α offset of prior σ {shared:.3g}° estimated" if implicit else ""))


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
    calibration = check_planar(SelfCalibration(tuple(nuisances)) if calibration is None
                               else calibration)
    check_nuisances(calibration.nuisances, len(B), n_targets, priors=calibration.priors)
    sig = as_object_sigmas(sigma)
    t = np.asarray(target, float)
    x4 = np.array([mirror_yaw_deg, mirror_rho, *t])
    _, d, _, _ = predict(x4, o, np.vstack([B, np.broadcast_to(t, (n_targets, 2))]))
    p = FitProblem.of(B, n_targets, sig, calibration=calibration, d_cm=d)
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
    calibration = as_calibration(calibration)  # (a pitch: solve_lsq refuses it)
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
        return replace(sol, covariance=cov, method="closed form with covariance",
                       tail=sig.tail)
    sol = solve_lsq(observer, beacons, targets, sigma=sigma, calibration=calibration)
    return sol if sigma is None else replace(sol, tail=as_object_sigmas(sigma).tail)
