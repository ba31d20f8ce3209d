"""Whole runs of the moving-beacon filter (:mod:`solver.particle`): a simulated run's
commands and observations, the filter over a run, and its mirror errors per step."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from solver.beacon_kalman import PFParams
from solver.geometry import line_normal
from solver.measurements import BeaconMeasurement
from solver.particle import DEFAULT_PARTICLES, MirrorEstimate, MovingBeaconFilter
from solver.sltr import observe


def simulate_run(observer: ArrayLike, mirror_point: ArrayLike, mirror_yaw_deg: float,
                 *, path: np.ndarray, params: PFParams, rng: int | np.random.Generator | None = 0
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noisy commands and observations for a beacon following ``path`` (k, 2).

    Returns (controls (k-1, 2), observations (k-1, 2), true positions (k, 2)); the true
    motion is the command plus N(0, σ_trs) per axis.
    """
    rng = np.random.default_rng(rng)
    path = np.asarray(path, float)
    controls = np.diff(path, axis=0)
    true = [path[0]]
    for c in controls:
        true.append(true[-1] + c + rng.normal(0.0, params.sigma_trs, 2))
    true = np.array(true)
    obs = observe(observer, mirror_point, mirror_yaw_deg, point=true[1:], strict=False)
    a = np.asarray(obs.alpha_deg) + rng.normal(0.0, params.sigma.alpha_deg, len(controls))
    d = np.asarray(obs.d_total) * (1 + rng.normal(0.0, params.sigma.d_total_rel, len(controls)))
    return controls, np.column_stack([a, d]), true


def track(observer: ArrayLike, beacon_start: ArrayLike, controls: ArrayLike,
          *, observations: Sequence[tuple[float, float] | None], yaw_range: tuple[float, float],
          rho_range: tuple[float, float], n: int = DEFAULT_PARTICLES,
          params: PFParams | None = None, rng: int | np.random.Generator | None = 0,
          fixed: tuple[BeaconMeasurement, ...] = (), fixed_sigma: float = 0.0
          ) -> list[MirrorEstimate]:
    """Run the filter over a whole run (beside the ``fixed`` beacons, known to
    ``fixed_sigma``); the estimate after each step."""
    f = MovingBeaconFilter(observer, beacon_start, yaw_range, rho_range, n, params, rng, fixed,
                           fixed_sigma)
    out = []
    for c, z in zip(controls, observations, strict=True):
        f.step(c, z)
        out.append(f.estimate())
    return out


def mirror_errors(estimates: list[MirrorEstimate], mirror_point: ArrayLike, mirror_yaw_deg: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Yaw error (deg) and offset error (distance of the true mirror point from each
    estimated line) per step."""
    p = np.asarray(mirror_point, float)
    yaw_err = np.array([(e.yaw_deg - mirror_yaw_deg + 90.0) % 180.0 - 90.0 for e in estimates])
    off = np.array([abs(line_normal(e.yaw_deg) @ p - e.rho) for e in estimates])
    return yaw_err, off
