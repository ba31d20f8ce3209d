"""Particle filter for one moving beacon (paper section 4).

State of a particle: the beacon's position (x, y) and the mirror line (θ [deg], ρ).
The beacon moves by a commanded translation each step (velocity motion model: the
true motion is the command corrupted by Gaussian translation noise σ_trs); the mirror
is static.  Each step the observer measures the beacon's image in the mirror
(α, d_total), which weights the particles; systematic resampling follows when the
effective sample size falls under half the particles.

:func:`pf_step` is the pure function; :class:`MovingBeaconFilter` holds the state and
calls it (tested to agree).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.geometry import line_normal, wrap_bearing
from solver.sltr import Sigma, observe

ROUGHEN = (0.02, 0.02)  # jitter of the static mirror (deg, cm) so resampling keeps diversity


@dataclass(frozen=True)
class PFParams:
    """Noise levels of the filter."""

    sigma: Sigma = Sigma(0.05, 0.005)
    sigma_trs: float = 0.1  # translation noise per step (cm)


def _predict_obs(particles: np.ndarray, observer: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """α and d of each particle's beacon in each particle's mirror (the solver's
    forward model, :func:`solver.sltr.observe`, on the particles' lines n·x = ρ)."""
    th, rho = particles[:, 2], particles[:, 3]
    obs = observe(observer, rho[:, None] * line_normal(th), th, particles[:, :2], strict=False)
    return np.asarray(obs.alpha_deg), np.asarray(obs.d_total)


def pf_step(particles: np.ndarray, weights: np.ndarray, control: np.ndarray,
            observation: tuple[float, float], observer: np.ndarray, params: PFParams,
            rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One predict–update–resample step; returns new (particles, weights).

    Parameters
    ----------
    particles : (N, 4) beacon x, y, mirror θ (deg), ρ
    weights : (N,) normalized
    control : (2,) commanded translation of the beacon this step
    observation : (α_deg, d_total) of the beacon's image, measured after the move
    """
    n = len(particles)
    p = particles.copy()
    p[:, :2] += np.asarray(control, float) + rng.normal(0.0, params.sigma_trs, (n, 2))
    p[:, 2] += rng.normal(0.0, ROUGHEN[0], n)
    p[:, 3] += rng.normal(0.0, ROUGHEN[1], n)
    a, d = _predict_obs(p, np.asarray(observer, float))
    ra = wrap_bearing(a - observation[0]) / params.sigma.alpha_deg
    rd = (d - observation[1]) / (params.sigma.d_total_rel * observation[1])
    # in front of the mirror only: behind it the particle's beacon could not be seen
    th, rho = p[:, 2], p[:, 3]
    nn = line_normal(th)
    same_side = (np.sum(p[:, :2] * nn, 1) - rho) * (np.asarray(observer) @ nn.T - rho) > 0
    logw = np.log(np.maximum(weights, 1e-300)) - 0.5 * (ra**2 + rd**2)
    logw[~same_side] = -np.inf
    if not np.isfinite(logw).any():
        logw = np.zeros(n)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    if 1.0 / np.sum(w**2) < n / 2:
        # systematic resampling
        positions = (rng.random() + np.arange(n)) / n
        idx = np.minimum(np.searchsorted(np.cumsum(w), positions), n - 1)
        p, w = p[idx], np.full(n, 1.0 / n)
    return p, w


def initial_particles(beacon_start, yaw_range: tuple[float, float], rho_range: tuple[float, float],
                      n: int, params: PFParams, rng: np.random.Generator) -> np.ndarray:
    """Particles at the known start of the beacon; the mirror drawn from a broad prior."""
    p = np.empty((n, 4))
    p[:, :2] = np.asarray(beacon_start, float) + rng.normal(0.0, params.sigma_trs, (n, 2))
    p[:, 2] = rng.uniform(*yaw_range, n)
    p[:, 3] = rng.uniform(*rho_range, n)
    return p


class MovingBeaconFilter:
    """Stateful wrapper of :func:`pf_step`."""

    def __init__(self, observer, beacon_start, yaw_range, rho_range, n: int = 4000,
                 params: PFParams | None = None, rng: int | np.random.Generator | None = 0):
        self.observer = np.asarray(observer, float)
        self.params = params or PFParams()
        self.rng = np.random.default_rng(rng)
        self.particles = initial_particles(beacon_start, yaw_range, rho_range, n,
                                           self.params, self.rng)
        self.weights = np.full(n, 1.0 / n)

    def step(self, control, observation) -> None:
        """Move by ``control`` and weigh by ``observation`` (α, d_total)."""
        self.particles, self.weights = pf_step(self.particles, self.weights, control,
                                               observation, self.observer, self.params,
                                               self.rng)

    def estimate(self) -> dict[str, np.ndarray | float]:
        """Weighted mean of the beacon, and of the mirror (yaw averaged as a line angle)."""
        w = self.weights
        th = np.radians(self.particles[:, 2])
        # line angles are modulo 180°: average the doubled angle
        yaw = np.degrees(0.5 * np.arctan2(w @ np.sin(2 * th), w @ np.cos(2 * th)))
        # express ρ in the mean yaw's normal
        n_mean = line_normal(yaw)
        foot = self.particles[:, 3, None] * line_normal(self.particles[:, 2])
        rho = float(w @ (foot @ n_mean))
        return {"beacon": w @ self.particles[:, :2], "yaw_deg": float(yaw % 180.0), "rho": rho}


def simulate_run(observer, mirror_point, mirror_yaw_deg: float, path: np.ndarray,
                 params: PFParams, rng: int | np.random.Generator | None = 0):
    """Noisy commands and observations for a beacon following ``path`` (k, 2).

    Returns (controls (k-1, 2), observations (k-1, 2), true positions (k, 2)); the true
    motion is the command plus N(0, σ_trs) per axis.
    """
    from solver.sltr import observe

    rng = np.random.default_rng(rng)
    path = np.asarray(path, float)
    controls = np.diff(path, axis=0)
    true = [path[0]]
    for c in controls:
        true.append(true[-1] + c + rng.normal(0.0, params.sigma_trs, 2))
    true = np.array(true)
    obs = observe(observer, mirror_point, mirror_yaw_deg, true[1:], strict=False)
    a = np.asarray(obs.alpha_deg) + rng.normal(0.0, params.sigma.alpha_deg, len(controls))
    d = np.asarray(obs.d_total) * (1 + rng.normal(0.0, params.sigma.d_total_rel, len(controls)))
    return controls, np.column_stack([a, d]), true


def track(observer, beacon_start, controls, observations, yaw_range, rho_range,
          n: int = 4000, params: PFParams | None = None, rng=0) -> list[dict]:
    """Run the filter over a whole run; the estimate after each step."""
    f = MovingBeaconFilter(observer, beacon_start, yaw_range, rho_range, n, params, rng)
    out = []
    for c, z in zip(controls, observations, strict=True):
        f.step(c, z)
        out.append(f.estimate())
    return out


def mirror_errors(estimates: list[dict], mirror_point, mirror_yaw_deg: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Yaw error (deg) and offset error (distance of the true mirror point from each
    estimated line) per step."""
    p = np.asarray(mirror_point, float)
    yaw_err = np.array([(e["yaw_deg"] - mirror_yaw_deg + 90.0) % 180.0 - 90.0 for e in estimates])
    off = np.array([abs(line_normal(e["yaw_deg"]) @ p - e["rho"]) for e in estimates])
    return yaw_err, off


__all__ = ["PFParams", "pf_step", "MovingBeaconFilter", "simulate_run", "track",
           "mirror_errors", "initial_particles"]
