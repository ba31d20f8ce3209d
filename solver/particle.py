"""Particle filter for one moving beacon (paper section 4), Rao-Blackwellized.

The state is the static mirror line (θ [deg], ρ: n(θ)·x = ρ) and the beacon's position,
which moves by a commanded translation each step corrupted by Gaussian noise σ_trs
(velocity motion model).  Given the mirror, everything else is linear-Gaussian: the
observation (α, d_total) places the beacon's virtual image at o + d_total·(cos α, sin α),
and the mirror's reflection maps it affinely onto the beacon.  So each particle is a
mirror hypothesis carrying an exact Kalman filter of the beacon (mean, 2×2 covariance),
weighted by the marginal likelihood of each observation; only the mirror is sampled.

Why (``python bench/particle.py``, 20 runs on EXP1's mirror): the former filter sampled
the beacon too, in four dimensions with 4000 particles.  Each resampling kept few
distinct mirrors (its static parameters were only roughened by 0.02° / 0.02 cm), so a
run whose surviving cloud had locked onto a wrong yaw stayed there: the p90 of the yaw
error stopped at 0.77° from step 8 on, and 20000 particles lowered it to 0.51° at step 23
(``bench/particle.py --particles 20000`` at commit 6e07002): sample impoverishment, not a
wrong likelihood.  Here the beacon is integrated out, and after
resampling the mirror is regularized by Liu and West's shrinkage kernel (bandwidth h
from the cloud's own covariance), which keeps the posterior's mean and spread while
giving the duplicates new, distinct values.

:func:`pf_step` is the pure function; :class:`MovingBeaconFilter` holds the state and
calls it (tested to agree).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.geometry import line_normal, unit
from solver.sltr import Sigma, virtual_image

SHRINK = 0.98  # Liu-West's a (discount δ ≈ 0.96 in a = (3δ − 1)/(2δ)); kernel h² = 1 − a²


@dataclass(frozen=True)
class PFParams:
    """Noise levels of the filter."""

    sigma: Sigma = Sigma(0.05, 0.005)
    sigma_trs: float = 0.1  # translation noise per step (cm)


@dataclass(frozen=True)
class MirrorEstimate:
    """The filter's estimate after a step: weighted means and spreads."""

    beacon: np.ndarray  # (2,) the beacon's mean position
    yaw_deg: float  # the mirror line's mean angle (mod 180)
    rho: float  # its offset along the mean yaw's normal (cm)
    yaw_sd_deg: float  # weighted SD of the hypotheses' yaw
    rho_sd: float  # weighted SD of their offset

    @property
    def point(self) -> np.ndarray:
        """The mirror line's foot point, ρ·n(θ)."""
        return self.rho * line_normal(self.yaw_deg)


@dataclass(frozen=True)
class Particles:
    """N mirror hypotheses, each with its beacon's Gaussian (mean, covariance)."""

    mirror: np.ndarray  # (N, 2): θ (deg), ρ (cm)
    beacon: np.ndarray  # (N, 2)
    cov: np.ndarray  # (N, 2, 2)

    def take(self, idx: np.ndarray) -> Particles:
        """The particles at ``idx`` (resampling)."""
        return Particles(self.mirror[idx], self.beacon[idx], self.cov[idx])


def _virtual_image(observation, observer, sigma: Sigma) -> tuple[np.ndarray, np.ndarray]:
    """Where (α, d_total) puts the beacon's virtual image, and its covariance."""
    a, d = float(observation[0]), float(observation[1])
    u = unit(a)
    v = virtual_image(observer, a, d)
    du = np.array([-u[1], u[0]])
    s_a, s_d = np.radians(sigma.alpha_deg) * d, sigma.d_total_rel * d
    return v, s_a**2 * np.outer(du, du) + s_d**2 * np.outer(u, u)


def pf_step(particles: Particles, weights: np.ndarray, control: np.ndarray,
            observation: tuple[float, float] | None, observer: np.ndarray, params: PFParams,
            rng: np.random.Generator) -> tuple[Particles, np.ndarray]:
    """One predict–update–resample step; returns new (particles, weights).

    Parameters
    ----------
    particles : the mirror hypotheses and their beacon Gaussians
    weights : (N,) normalized
    control : (2,) commanded translation of the beacon this step
    observation : (α_deg, d_total) of the beacon's image after the move; None when the
        beacon was not seen (prediction only)
    """
    n = len(weights)
    mean = particles.beacon + np.asarray(control, float)
    cov = particles.cov + params.sigma_trs**2 * np.eye(2)
    if observation is None:
        return Particles(particles.mirror, mean, cov), weights
    v, Rv = _virtual_image(observation, observer, params.sigma)
    nn = line_normal(particles.mirror[:, 0])  # (N, 2)
    rho = particles.mirror[:, 1]
    sv = nn @ v - rho  # the virtual image must lie behind the mirror
    so = nn @ np.asarray(observer, float) - rho
    H = np.eye(2)[None] - 2.0 * nn[:, :, None] * nn[:, None, :]  # reflection (symmetric)
    z = v[None] - 2.0 * sv[:, None] * nn  # the beacon, reflected back
    S = cov + H @ Rv @ H
    Sinv = np.linalg.inv(S)
    y = z - mean
    K = cov @ Sinv
    mean = mean + np.einsum("nij,nj->ni", K, y)
    cov = cov - K @ cov
    logl = -0.5 * np.einsum("ni,nij,nj->n", y, Sinv, y) - 0.5 * np.log(np.linalg.det(S))
    logw = np.log(np.maximum(weights, 1e-300)) + logl
    logw[so * sv >= 0] = -np.inf  # image on the observer's side: no mirror shows that
    if not np.isfinite(logw).any():
        logw = np.zeros(n)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    out = Particles(particles.mirror, mean, cov)
    if 1.0 / np.sum(w**2) < n / 2:
        out, w = _resample(out, w, rng)
    return out, w


def _resample(p: Particles, w: np.ndarray, rng: np.random.Generator
              ) -> tuple[Particles, np.ndarray]:
    """Systematic resampling, then Liu-West regularization of the static mirror."""
    n = len(w)
    positions = (rng.random() + np.arange(n)) / n
    idx = np.minimum(np.searchsorted(np.cumsum(w), positions), n - 1)
    m = p.mirror
    centre = w @ m
    spread = np.cov(m.T, aweights=w) + 1e-12 * np.eye(2)
    h2 = 1.0 - SHRINK**2
    moved = (SHRINK * m[idx] + (1 - SHRINK) * centre
             + rng.multivariate_normal(np.zeros(2), h2 * spread, n))
    return Particles(moved, p.beacon[idx], p.cov[idx]), np.full(n, 1.0 / n)


def initial_particles(beacon_start, yaw_range: tuple[float, float], rho_range: tuple[float, float],
                      n: int, params: PFParams, rng: np.random.Generator) -> Particles:
    """The mirror drawn from a broad uniform prior; the beacon at its known start (to
    σ_trs)."""
    mirror = np.column_stack([rng.uniform(*yaw_range, n), rng.uniform(*rho_range, n)])
    beacon = np.tile(np.asarray(beacon_start, float), (n, 1))
    cov = np.tile(params.sigma_trs**2 * np.eye(2), (n, 1, 1))
    return Particles(mirror, beacon, cov)


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
        """Move by ``control`` and weigh by ``observation`` (α, d_total; None: unseen)."""
        self.particles, self.weights = pf_step(self.particles, self.weights, control,
                                               observation, self.observer, self.params,
                                               self.rng)

    def estimate(self) -> MirrorEstimate:
        """Weighted means of the beacon and the mirror (yaw averaged as a line angle), and
        the spread of the mirror hypotheses (weighted SD of yaw and offset)."""
        w = self.weights
        th = np.radians(self.particles.mirror[:, 0])
        # line angles are modulo 180°: average the doubled angle
        yaw = np.degrees(0.5 * np.arctan2(w @ np.sin(2 * th), w @ np.cos(2 * th)))
        # express ρ in the mean yaw's normal
        n_mean = line_normal(yaw)
        foot = self.particles.mirror[:, 1, None] * line_normal(self.particles.mirror[:, 0])
        rhos = foot @ n_mean
        rho = float(w @ rhos)
        dyaw = (self.particles.mirror[:, 0] - yaw + 90.0) % 180.0 - 90.0
        return MirrorEstimate(beacon=w @ self.particles.beacon, yaw_deg=float(yaw % 180.0),
                              rho=rho, yaw_sd_deg=float(np.sqrt(w @ dyaw**2)),
                              rho_sd=float(np.sqrt(w @ (rhos - rho) ** 2)))


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
          n: int = 4000, params: PFParams | None = None, rng=0) -> list[MirrorEstimate]:
    """Run the filter over a whole run; the estimate after each step."""
    f = MovingBeaconFilter(observer, beacon_start, yaw_range, rho_range, n, params, rng)
    out = []
    for c, z in zip(controls, observations, strict=True):
        f.step(c, z)
        out.append(f.estimate())
    return out


def mirror_errors(estimates: list[MirrorEstimate], mirror_point, mirror_yaw_deg: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Yaw error (deg) and offset error (distance of the true mirror point from each
    estimated line) per step."""
    p = np.asarray(mirror_point, float)
    yaw_err = np.array([(e.yaw_deg - mirror_yaw_deg + 90.0) % 180.0 - 90.0 for e in estimates])
    off = np.array([abs(line_normal(e.yaw_deg) @ p - e.rho) for e in estimates])
    return yaw_err, off


__all__ = ["PFParams", "MirrorEstimate", "pf_step", "MovingBeaconFilter", "simulate_run", "track",
           "mirror_errors", "initial_particles"]
