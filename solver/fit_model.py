"""What the least squares fits, declared once for the solve and its Cramér–Rao bound:
the forward model in the mirror line's (θ, ρ) with its derivatives, the self-calibrated
nuisances' effects (a pan offset, a range scale, the mirror's power), and the problem's
unknowns, weights and priors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.errors import SolverError
from solver.geometry import line_normal, unit
from solver.measurements import (
    ObjectSigmas,
)
from solver.selfcal import NUISANCES, SelfCalibration
from solver.sltr import observe


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


@dataclass(frozen=True)
class FitProblem:
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
    def of(cls, bpos: np.ndarray, nt: int, sig: ObjectSigmas, *,
           calibration: SelfCalibration, d_cm: np.ndarray) -> FitProblem:
        """The problem of ``bpos`` beacons and ``nt`` target observations with σ's
        ``sig`` (a relative σ_d taken of ``d_cm``: the measured d_totals for a solve, the
        true ones for a bound)."""
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
        _, _, da, dd = forward(x, o, bpos, nt=self.nt, nuisances=self.unknown, free=self.free)
        return np.vstack([self.w_a[:, None] * da, self.w_d[:, None] * dd, self.prior])


def forward(x: np.ndarray, o: np.ndarray, bpos: np.ndarray, *, nt: int,
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
        elif name == "power":
            ea[:, j], ed[:, j] = power
        else:
            raise SolverError(f"{name}: not a nuisance of the planar solve")
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
