"""Where to put N beacons: a greedy choice over the board's grid that minimises the
expected target error with the chosen nuisances estimated alongside the mirror
(self-calibration; the paper's "number of needed beacons and their locations", for a
bench with a pan and a calibration error, and a curved mirror).

The expected error of a set is the Cramér–Rao bound's target block (√trace), from the
Fisher information of every beacon's and the target's α and d_total, averaged over the
mirror poses of a prior.  Information adds over measurements, so each candidate's
information is computed once per pose and the greedy step inverts one small matrix per
candidate and pose.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.errors import SolverError
from solver.fit_model import nuisance_columns, power_terms, predict
from solver.geometry import point_segment_distance
from solver.measurements import ObjectSigmas, Sigma, as_object_sigmas
from solver.placement import implied_target, seen_in_mirror
from solver.selfcal import PLAIN, SelfCalibration

# an expected variance beyond this (cm²) is no estimate: the set cannot determine it
UNDETERMINED_CM2 = 1e6


@dataclass(frozen=True)
class BeaconSet:
    """:func:`best_beacon_set`'s answer: the positions in the order chosen, and after
    each, the expected target RMSE with the nuisances estimated (inf: not yet
    observable) and without nuisances (a bench without those errors)."""

    positions: np.ndarray  # (n, 2)
    rmse: tuple[float, ...]
    rmse_plain: tuple[float, ...]
    calibration: SelfCalibration  # the nuisances estimated, the priors and position σ


def _information(o: np.ndarray, B: np.ndarray, t_alpha: float, t_d: float, point, yaw: float,
                 sig: ObjectSigmas, nuisances: tuple[str, ...], position_sigma: float = 0.0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At one mirror pose: each candidate beacon's Fisher information (K, P, P), the
    target's (P, P), and the candidates' beacon d_total (K,); P = 4 + len(nuisances).

    A beacon known to ``position_sigma`` (cm per axis) has its measurements' covariance
    grown by σ_p²·J_p J_pᵀ (J_p: its image's α and d_total against its position): the
    position offset marginalized, exactly to first order."""
    params, tgt = implied_target(o, t_alpha, t_d, point=point, yaw=yaw)
    _, d_b, da_b, dd_b = predict(np.r_[params, 0, 0], o, B)
    _, d_t, da_t, dd_t = predict(np.r_[params, tgt], o, tgt[None])
    P = 4 + len(nuisances)
    ra, rd = np.zeros((len(B), P)), np.zeros((len(B), P))
    ra[:, :2], rd[:, :2] = da_b[:, :2], dd_b[:, :2]
    ta, td = np.zeros(P), np.zeros(P)
    ta[:4], td[:4] = da_t[0], dd_t[0]
    # the power's mirror curved about the pose's point (its centre; to first order the
    # vertex changes the mirror, not the target)
    power = (power_terms((params[0], params[1]), o, np.vstack([B, tgt[None]]),
                         vertex=np.asarray(point, float)) if "power" in nuisances else None)
    ea, ed = nuisance_columns(nuisances, np.r_[d_b, d_t[0]], power)
    ra[:, 4:], rd[:, 4:], ta[4:], td[4:] = ea[:-1], ed[:-1], ea[-1], ed[-1]
    sb, st = sig.beacons[0], sig.target
    R = np.stack([ra, rd], axis=1)  # (K, 2, P): each candidate's α and d rows
    C = np.zeros((len(B), 2, 2))
    C[:, 0, 0], C[:, 1, 1] = sb.alpha_deg**2, (sb.d_total_rel * d_b) ** 2
    if position_sigma > 0:
        Jp = np.stack([da_b[:, 2:], dd_b[:, 2:]], axis=1)  # (K, 2, 2)
        C = C + position_sigma**2 * Jp @ np.swapaxes(Jp, 1, 2)
    info_b = np.swapaxes(R, 1, 2) @ np.linalg.solve(C, R)
    ta, td = ta / st.alpha_deg, td / (st.d_total_rel * d_t[0])
    return info_b, np.outer(ta, ta) + np.outer(td, td), d_b


def _target_variance(info: np.ndarray, keep: int) -> np.ndarray:
    """Trace of the target block of the inverse of info's first ``keep`` parameters
    (batched over leading axes); UNDETERMINED where singular."""
    m = info[..., :keep, :keep]
    scale = np.maximum(np.abs(np.diagonal(m, axis1=-2, axis2=-1)).max(axis=-1), 1e-300)
    ridge = 1e-12 * scale[..., None, None] * np.eye(keep)
    with np.errstate(all="ignore"):
        inv = np.linalg.inv(m + ridge)
    v = inv[..., 2, 2] + inv[..., 3, 3]
    return np.where(np.isfinite(v) & (v > 0) & (v < UNDETERMINED_CM2), v, np.inf)


def best_beacon_set(observer: ArrayLike, target_alpha_deg: float, target_d_total: float,
                    *, poses: list[tuple[np.ndarray, float]], sigma: Sigma | ObjectSigmas,
                    mirror_size: float, board: tuple[float, float], n: int,
                    calibration: SelfCalibration = PLAIN, step: float = 1.0,
                    keep_out: Sequence[tuple[np.ndarray, np.ndarray, float]] = (),
                    clearance: float = 1.0,
                    accept: Callable[[np.ndarray], bool] | None = None,
                    min_depth: float = 0.5) -> BeaconSet:
    """Choose ``n`` beacon positions on the board's grid one at a time, each the one that
    lowers the expected target error most (with ``calibration``'s nuisances estimated,
    and its priors on them known), among
    positions every pose shows, clear of ``keep_out`` segments (start, end, clearance)
    and ``clearance`` from the beacons already chosen, vetted by ``accept(position)``.
    While the set cannot yet carry the nuisances (one beacon for pan and scale, two for
    pan, scale and power), the choice is by the error without them.  ``calibration``'s
    position σ: how well a placed beacon's position is known (cm per axis): clustered
    beacons then buy less.

    Raises
    ------
    SolverError
        No position is seen under every pose, or none passes ``accept``.
    """
    nuisances = calibration.nuisances
    o = np.asarray(observer, float)
    xs = np.arange(step / 2, board[0], step)
    ys = np.arange(step / 2, board[1], step)
    gx, gy = np.meshgrid(xs, ys)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    allowed, per_pose = _candidates(o, grid, (target_alpha_deg, target_d_total), poses=poses,
                                    sigma=as_object_sigmas(sigma), calibration=calibration,
                                    keep_out=keep_out, mirror_size=mirror_size,
                                    min_depth=min_depth)
    if not allowed.any():
        raise SolverError("no beacon position on the board is seen under every mirror pose")
    P = 4 + len(nuisances)
    # a prior N(neutral, σ²) on a nuisance is information 1/σ² on its own parameter
    prior = np.diag([0.0] * 4 + [calibration.priors.get(x, np.inf) ** -2.0 for x in nuisances])
    base = [info_t + prior for _, info_t in per_pose]
    chosen, rmse, plain = [], [], []
    for _ in range(n):
        full, only = _rms_errors(per_pose, base, P)
        if 2 * (len(chosen) + 2) < P:  # the set and the target cannot carry the nuisances
            full[:] = np.inf
        ok = allowed.copy()
        for c in chosen:
            ok &= np.hypot(*(grid - grid[c]).T) >= clearance
        score = np.where(ok, full if np.isfinite(full[ok]).any() else only, np.inf)
        order = np.argsort(score)
        pick = next((int(i) for i in order if np.isfinite(score[i])
                     and (accept is None or accept(grid[i]))), -1)
        if pick < 0:
            raise SolverError(f"no acceptable position for beacon {len(chosen) + 1}")
        chosen.append(pick)
        rmse.append(float(full[pick]))
        plain.append(float(only[pick]))
        for k, (info_b, _) in enumerate(per_pose):
            base[k] = base[k] + info_b[pick]
    return BeaconSet(grid[chosen], tuple(rmse), tuple(plain), calibration)


def _rms_errors(per_pose: list[tuple[np.ndarray, np.ndarray]], base: list[np.ndarray],
                P: int) -> tuple[np.ndarray, np.ndarray]:
    """The expected target error (RMS over the poses) with a beacon added at each
    candidate to the information ``base`` holds: with the nuisances estimated (the first
    ``P`` parameters), and without them."""
    full, only = 0.0, 0.0
    for (info_b, _), b0 in zip(per_pose, base, strict=True):
        m = b0[None] + info_b
        full = full + _target_variance(m, P)
        only = only + _target_variance(m, 4)
    return np.sqrt(full / len(per_pose)), np.sqrt(only / len(per_pose))


def _candidates(o: np.ndarray, grid: np.ndarray, target: tuple[float, float], *,
                poses: list[tuple[np.ndarray, float]], sigma: ObjectSigmas,
                calibration: SelfCalibration,
                keep_out: Sequence[tuple[np.ndarray, np.ndarray, float]],
                mirror_size: float, min_depth: float
                ) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Which ``grid`` positions every pose shows, clear of ``keep_out``; and under each
    pose the information a beacon at each position adds, and the target's own."""
    allowed = np.ones(len(grid), bool)
    for a, b, clear in keep_out:
        allowed &= point_segment_distance(grid, a, b) >= clear
    per_pose = []
    for point, yaw in poses:
        allowed &= seen_in_mirror(o, grid, point, yaw=yaw, mirror_size=mirror_size,
                                  min_depth=min_depth)
        info_b, info_t, _ = _information(o, grid, target[0], target[1], point, yaw, sigma,
                                         calibration.nuisances, calibration.position_sigma)
        per_pose.append((info_b, info_t))
    return allowed, per_pose
