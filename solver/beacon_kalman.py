"""Given a mirror hypothesis the moving beacon is linear-Gaussian: the observation
(α, d_total) places its virtual image, and the mirror's reflection maps that affinely
onto the beacon.  Here is that exact Kalman filter, run for N hypotheses at once (each
observation's marginal likelihood, the fixed beacons' once, a history replayed), and
the values it works on: the filter's noise levels, its prior and the particles.
:mod:`solver.particle` samples the mirror."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.geometry import line_normal, unit
from solver.measurements import BeaconMeasurement, Sigma
from solver.sltr import virtual_image


@dataclass(frozen=True)
class PFParams:
    """Noise levels of the filter."""

    sigma: Sigma = Sigma(0.05, 0.005)
    sigma_trs: float = 0.1  # translation noise per step (cm)


@dataclass(frozen=True)
class Prior:
    """What the filter starts from: the beacon's known start, the uniform box of mirror
    hypotheses, and the fixed beacons: each stands still beside the moving one, its
    image observed once, and weighs every hypothesis once by its likelihood (a prior on
    the mirror before the moving beacon's first step), its believed position known to
    ``fixed_sigma`` cm per axis (0: exactly; a position off by more than that pins the
    mirror wrong: a virtual image's σ across the line of sight is ~0.01 cm at the
    detector's σ's)."""

    beacon_start: np.ndarray
    yaw_range: tuple[float, float]
    rho_range: tuple[float, float]
    fixed: tuple[BeaconMeasurement, ...] = ()
    fixed_sigma: float = 0.0

    def contains(self, mirror: np.ndarray) -> np.ndarray:
        """Which of the (N, 2) hypotheses lie inside the box."""
        return ((mirror[:, 0] >= self.yaw_range[0]) & (mirror[:, 0] <= self.yaw_range[1])
                & (mirror[:, 1] >= self.rho_range[0]) & (mirror[:, 1] <= self.rho_range[1]))


@dataclass(frozen=True)
class Particles:
    """N mirror hypotheses, each with its beacon's Gaussian (mean, covariance) and the
    log marginal likelihood of every observation so far."""

    mirror: np.ndarray  # (N, 2): θ (deg), ρ (cm)
    beacon: np.ndarray  # (N, 2)
    cov: np.ndarray  # (N, 2, 2)
    loglik: np.ndarray  # (N,)

    def take(self, idx: np.ndarray) -> Particles:
        """The particles at ``idx`` (resampling)."""
        return Particles(self.mirror[idx], self.beacon[idx], self.cov[idx], self.loglik[idx])


def _virtual_image(observation, observer, sigma: Sigma) -> tuple[np.ndarray, np.ndarray]:
    """Where (α, d_total) puts the beacon's virtual image, and its covariance."""
    a, d = float(observation[0]), float(observation[1])
    u = unit(a)
    v = virtual_image(observer, a, d)
    du = np.array([-u[1], u[0]])
    s_a, s_d = np.radians(sigma.alpha_deg) * d, sigma.d_total_rel * d
    return v, s_a**2 * np.outer(du, du) + s_d**2 * np.outer(u, u)


def _update(mirror: np.ndarray, mean: np.ndarray, cov: np.ndarray, observation,
            observer: np.ndarray, sigma: Sigma) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Kalman update of each hypothesis' beacon by one observation: new (mean, cov)
    and the observation's log marginal likelihood (−inf where the image would stand on
    the observer's side of that mirror: no mirror shows that)."""
    v, Rv = _virtual_image(observation, observer, sigma)
    nn = line_normal(mirror[:, 0])  # (N, 2)
    rho = mirror[:, 1]
    sv = nn @ v - rho  # the virtual image must lie behind the mirror
    so = nn @ np.asarray(observer, float) - rho
    H = np.eye(2)[None] - 2.0 * nn[:, :, None] * nn[:, None, :]  # reflection (symmetric)
    z = v[None] - 2.0 * sv[:, None] * nn  # the beacon, reflected back
    S = cov + H @ Rv @ H
    Sinv = np.linalg.inv(S)
    y = z - mean
    K = cov @ Sinv
    logl = -0.5 * np.einsum("ni,nij,nj->n", y, Sinv, y) - 0.5 * np.log(np.linalg.det(S))
    logl[so * sv >= 0] = -np.inf
    return mean + np.einsum("nij,nj->ni", K, y), cov - K @ cov, logl


def advance(mirror: np.ndarray, mean: np.ndarray, cov: np.ndarray, *, control: ArrayLike,
            observation: tuple[float, float] | None, observer: ArrayLike, params: PFParams
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """One step of each hypothesis' Kalman filter: predict by the command, then update by
    the observation; the observation's log likelihood, or None where it was unseen."""
    mean = mean + np.asarray(control, float)
    cov = cov + params.sigma_trs**2 * np.eye(2)
    if observation is None:
        return mean, cov, None
    return _update(mirror, mean, cov, observation, observer, params.sigma)


def _fixed_loglik(mirror: np.ndarray, prior: Prior, observer, sigma: Sigma) -> np.ndarray:
    """The fixed beacons' log likelihood of each hypothesis: each believed position,
    reflected in that mirror, against its observed virtual image (a Kalman update of a
    beacon known to its position σ)."""
    n = len(mirror)
    loglik = np.zeros(n)
    if prior.fixed and observer is None:
        raise ValueError("fixed beacons need the observer: their images are seen from it")
    cov = np.tile(prior.fixed_sigma**2 * np.eye(2), (n, 1, 1))
    for f in prior.fixed:
        known = np.tile(np.asarray(f.position, float), (n, 1))
        loglik += _update(mirror, known, cov, (f.alpha_deg, f.d_total),
                          np.asarray(observer, float), sigma)[2]
    return loglik


def replay(mirror: np.ndarray, prior: Prior,
           history: Sequence[tuple[np.ndarray, tuple[float, float] | None]], *, observer: ArrayLike,
           params: PFParams) -> Particles:
    """The hypotheses ``mirror`` (N, 2) run through ``history`` ((control, observation or
    None), …) from the prior's start: their beacons' Gaussians and log likelihoods (the
    fixed beacons' included)."""
    n = len(mirror)
    mean = np.tile(np.asarray(prior.beacon_start, float), (n, 1))
    cov = np.tile(params.sigma_trs**2 * np.eye(2), (n, 1, 1))
    loglik = _fixed_loglik(mirror, prior, observer, params.sigma)
    for control, observation in history:
        mean, cov, logl = advance(mirror, mean, cov, control=control, observation=observation,
                                  observer=observer, params=params)
        if logl is not None:
            loglik = loglik + logl
    return Particles(mirror, mean, cov, loglik)
