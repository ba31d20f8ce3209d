"""The batch smoother beside the particle filter: every pose of a moving-beacon run, the
mirror and the motion estimated at once by least squares.  The best any estimator can do
with these data, so the reference the filter (:mod:`solver.particle`) is measured against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.beacon_kalman import PFParams
from solver.geometry import line_normal, wrap_bearing
from solver.measurements import BeaconMeasurement
from solver.sltr import observe


@dataclass(frozen=True)
class SmoothedRun:
    """The smoother's estimate: the mirror line n(θ)·x = ρ and the beacon at every pose."""

    yaw_deg: float
    rho: float
    beacons: np.ndarray  # (k + 1, 2): the start pose, then one per control


def smooth_run(observer: ArrayLike, start: ArrayLike, controls: np.ndarray,
               *, observations: np.ndarray, params: PFParams, yaw_deg: float, rho: float,
               beacons: np.ndarray, fixed: tuple[BeaconMeasurement, ...] = (),
               fixed_sigma: float = 0.0) -> SmoothedRun:
    """Least squares over the odometry (σ_trs per move, the start as believed) and every
    observation (α, d_total with ``params.sigma``) of the moving beacon and of the
    ``fixed`` ones (their believed positions known to ``fixed_sigma``), from the start
    point (``yaw_deg``, ``rho``, ``beacons``): it finds the optimum nearest that point."""
    from scipy.optimize import least_squares  # scipy is slow to import: only when used

    k, s = len(controls), params.sigma
    obs = np.asarray(observations, float)
    o = np.asarray(observer, float)
    known = np.array([f.position for f in fixed], float).reshape(-1, 2)
    obs_fixed = np.array([(f.alpha_deg, f.d_total) for f in fixed], float).reshape(-1, 2)
    # fixed beacons known to a σ are parameters with that prior, as in the filter
    free = fixed_sigma > 0
    z = np.vstack([obs, obs_fixed])

    def residuals(x):
        b = x[2:2 + 2 * (k + 1)].reshape(k + 1, 2)
        at = x[2 + 2 * (k + 1):].reshape(-1, 2) if free else known
        seen = observe(o, x[1] * line_normal(x[0]), x[0], point=np.vstack([b[1:], at]),
                       strict=False)
        alpha, d = np.asarray(seen.alpha_deg), np.asarray(seen.d_total)
        return np.concatenate([
            (b[0] - start) / params.sigma_trs,
            ((b[1:] - b[:-1] - controls) / params.sigma_trs).ravel(),
            ((at - known) / fixed_sigma).ravel() if free else [],
            wrap_bearing(alpha - z[:, 0]) / s.alpha_deg,
            (d - z[:, 1]) / (s.d_total_rel * z[:, 1])])

    x = least_squares(residuals, np.r_[yaw_deg, rho, np.asarray(beacons, float).ravel(),
                                       known.ravel() if free else []]).x
    return SmoothedRun(float(x[0]), float(x[1]), x[2:2 + 2 * (k + 1)].reshape(k + 1, 2))
