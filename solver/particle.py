"""Particle filter for one moving beacon (paper section 4), Rao-Blackwellized.

The state is the static mirror line (θ [deg], ρ: n(θ)·x = ρ) and the beacon's position,
which moves by a commanded translation each step corrupted by Gaussian noise σ_trs
(velocity motion model).  Given the mirror, everything else is linear-Gaussian: the
observation (α, d_total) places the beacon's virtual image at o + d_total·(cos α, sin α),
and the mirror's reflection maps it affinely onto the beacon.  So each particle is a
mirror hypothesis carrying an exact Kalman filter of the beacon (mean, 2×2 covariance),
weighted by the marginal likelihood of each observation; only the mirror is sampled.

Why this design: a static mirror sampled with the beacon in four dimensions keeps few
distinct mirrors after each resampling, so a cloud that locks onto a wrong yaw stays
there (sample impoverishment, not a wrong likelihood).  Here the beacon is integrated
out, and after resampling the mirror hypotheses are moved by Metropolis–Hastings
(resample-move, Gilks and Berzuini 2001): each proposes a random-walk step scaled by the
cloud's own covariance, or a draw from the Laplace approximation at the posterior's
mode, and accepts it by the marginal likelihood of the whole history so far (its Kalman
filter replayed from the start), so the duplicates become distinct draws of the exact
posterior.  A kernel that works from the cloud alone (Liu and West's shrinkage) keeps no
spread to move by where the likelihood is much narrower than the cloud (the detector's
0.005° in α, a beacon that does not drift); a random walk alone strands some runs far
from the mode, which the Laplace proposal reaches at once.  ``tests/test_particle.py``
holds the filter to the batch smoother (:mod:`solver.smoother`) on such runs.

:func:`pf_step` is the pure function; :class:`MovingBeaconFilter` holds the state and
calls it (tested to agree).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.beacon_kalman import Particles, PFParams, Prior, advance, replay
from solver.geometry import line_normal
from solver.measurements import BeaconMeasurement

SPREAD_FLOOR = (0.002, 0.001)  # the proposal's least spread: yaw (deg), offset (cm)
MOVE_SWEEPS = 4  # Metropolis–Hastings moves after each resampling
MOVE_SCALE = 2.38 / np.sqrt(2.0)  # random-walk scale for a 2-D target (Roberts et al.)
DEFAULT_PARTICLES = 4000  # the filter's particles where a caller gives no number


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


def pf_step(particles: Particles, weights: np.ndarray, control: np.ndarray,
            *, observation: tuple[float, float] | None, observer: np.ndarray, params: PFParams,
            rng: np.random.Generator, prior: Prior,
            history: Sequence[tuple[np.ndarray, tuple[float, float] | None]] = ()
            ) -> tuple[Particles, np.ndarray]:
    """One predict–update–resample–move step; returns new (particles, weights).

    Parameters
    ----------
    particles : the mirror hypotheses and their beacon Gaussians
    weights : (N,) normalized
    control : (2,) commanded translation of the beacon this step
    observation : (α_deg, d_total) of the beacon's image after the move; None when the
        beacon was not seen (prediction only)
    prior : the start and the box the hypotheses were drawn from
    history : the steps before this one, ((control, observation), …), which the move
        step replays
    """
    mean, cov, logl = advance(particles.mirror, particles.beacon, particles.cov,
                              control=control, observation=observation, observer=observer,
                              params=params)
    if logl is None:
        return Particles(particles.mirror, mean, cov, particles.loglik), weights
    return _reweigh(Particles(particles.mirror, mean, cov, particles.loglik + logl),
                    np.log(np.maximum(weights, 1e-300)) + logl, prior,
                    (*history, (control, observation)), observer, params, rng)


def _reweigh(p: Particles, logw: np.ndarray, prior: Prior, history, observer,
             params: PFParams, rng: np.random.Generator) -> tuple[Particles, np.ndarray]:
    """The hypotheses weighted by ``logw``, resampled and moved (by the likelihood of
    ``history``) when their effective size falls below half."""
    n = len(logw)
    if not np.isfinite(logw).any():
        logw = np.zeros(n)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    ess = 1.0 / np.sum(w**2)
    if ess < n / 2:
        p = _move(_resample(p, w, rng), prior, history, observer, params, rng, ess)
        w = np.full(n, 1.0 / n)
    return p, w


def _resample(p: Particles, w: np.ndarray, rng: np.random.Generator,
              n: int | None = None) -> Particles:
    """Systematic resampling to ``n`` particles (default: as many), of equal weight."""
    n = len(w) if n is None else n
    positions = (rng.random() + np.arange(n)) / n
    return p.take(np.minimum(np.searchsorted(np.cumsum(w), positions), len(w) - 1))


def _laplace(p: Particles, prior: Prior, history, observer, params: PFParams
             ) -> tuple[np.ndarray, np.ndarray] | None:
    """The posterior's mode (from the best hypothesis, by Nelder–Mead) and the inverse of
    the negative Hessian of its log likelihood there (central differences): a Gaussian
    that reaches the mode however far the cloud lies from it.  None where the Hessian is
    not negative definite."""
    from scipy.optimize import minimize

    def nll(m):
        ll = replay(np.asarray(m, float)[None], prior, history, observer=observer,
                    params=params).loglik[0]
        return -ll if np.isfinite(ll) else 1e300

    best = p.mirror[int(np.argmax(p.loglik))]
    mode = minimize(nll, best, method="Nelder-Mead",
                    options={"xatol": 1e-5, "fatol": 1e-6, "initial_simplex": [
                        best, best + (0.5, 0.0), best + (0.0, 0.2)]}).x
    h = np.array(SPREAD_FLOOR)
    pts = [mode + np.array([i * h[0], j * h[1]]) for i in (-1, 0, 1) for j in (-1, 0, 1)]
    f = replay(np.array(pts), prior, history, observer=observer, params=params).loglik.reshape(3, 3)
    H = np.array([[(f[2, 1] - 2 * f[1, 1] + f[0, 1]) / h[0] ** 2,
                   (f[2, 2] - f[2, 0] - f[0, 2] + f[0, 0]) / (4 * h[0] * h[1])],
                  [0.0, (f[1, 2] - 2 * f[1, 1] + f[1, 0]) / h[1] ** 2]])
    H[1, 0] = H[0, 1]
    if not np.all(np.isfinite(H)) or np.any(np.linalg.eigvalsh(-H) <= 0):
        return None
    return mode, np.linalg.inv(-H)


def _log_gauss(x: np.ndarray, mean: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """An unnormalized Gaussian log density at the rows of ``x``."""
    d = x - mean
    return -0.5 * np.einsum("ni,ij,nj->n", d, inv, d)


def _mix_in_laplace(p: Particles, ess: float, mode: np.ndarray, cov: np.ndarray,
                    inv: np.ndarray, prior: Prior, history, observer, params: PFParams,
                    rng: np.random.Generator) -> Particles:
    """The cloud pooled with an importance sample of the posterior drawn from the Laplace
    Gaussian (``cov``, its inverse ``inv``), each share weighted by its effective size,
    resampled to the cloud's size.

    Where the likelihood is a thin curved ridge (one fixed beacon: a ±3° banana a few
    thousandths wide), the uniform first cloud leaves one or two hypotheses on it, at
    random places; the independence moves cannot leave such a place (the Gaussian gives
    it no density, so no move is accepted), and the cloud stayed there, 5° from the mode,
    reporting a spread of 0.004°.  A second sample of the same posterior, drawn where
    the Gaussian fits it, and pooled by effective size, corrects that; where the cloud
    is healthy (ESS ≥ the draws'), it keeps at least half the weight."""
    n = len(p.mirror)
    x = rng.multivariate_normal(mode, cov, n)
    q = replay(x, prior, history, observer=observer, params=params)
    logw = np.where(prior.contains(x), q.loglik - _log_gauss(x, mode, inv), -np.inf)
    if not np.isfinite(logw).any():
        return p
    w = np.exp(logw - logw[np.isfinite(logw)].max())
    w /= w.sum()
    share = ess / (ess + 1.0 / np.sum(w**2))
    pool = Particles(*(np.concatenate([a, b]) for a, b in
                       ((p.mirror, q.mirror), (p.beacon, q.beacon), (p.cov, q.cov),
                        (p.loglik, q.loglik))))
    return _resample(pool, np.concatenate([np.full(n, share / n), (1 - share) * w]), rng, n)


def _move(p: Particles, prior: Prior, history, observer, params: PFParams,
          rng: np.random.Generator, ess: float) -> Particles:
    """Metropolis–Hastings moves of the equally weighted mirror hypotheses (first pooled
    with a Laplace sample by ``ess``, the effective size they had before resampling:
    :func:`_mix_in_laplace`), each accepted
    by the likelihood of the whole history (uniform prior: none leaves the box).  Each
    hypothesis, each sweep, proposes either a random-walk step scaled by the cloud's
    covariance, or an independent draw from the Laplace approximation at the mode
    (twice as wide; its density enters the acceptance ratio)."""
    n = len(p.mirror)
    laplace = _laplace(p, prior, history, observer, params)
    if laplace is not None:
        mode, cov = laplace[0], 4.0 * laplace[1]
        inv = np.linalg.inv(cov)
        p = _mix_in_laplace(p, ess, mode, cov, inv, prior, history, observer, params, rng)
    for _ in range(MOVE_SWEEPS):
        dev = p.mirror - p.mirror.mean(axis=0)
        # the cloud's covariance, floored: a collapsed cloud still proposes moves
        spread = dev.T @ dev / n + np.diag(SPREAD_FLOOR) ** 2
        proposal = p.mirror + MOVE_SCALE * rng.multivariate_normal(np.zeros(2), spread, n)
        log_q = np.zeros(n)  # log q(x) − log q(x′): 0 for the symmetric random walk
        if laplace is not None:
            jump = rng.random(n) < 0.5
            drawn = rng.multivariate_normal(mode, cov, n)
            proposal[jump] = drawn[jump]
            log_q[jump] = (_log_gauss(p.mirror, mode, inv) - _log_gauss(proposal, mode, inv)
                           )[jump]
        q = replay(proposal, prior, history, observer=observer, params=params)
        log_ratio = np.where(prior.contains(proposal), q.loglik - p.loglik + log_q, -np.inf)
        with np.errstate(invalid="ignore"):  # −inf − (−inf): both impossible, stay
            accept = np.log(rng.random(n)) < np.nan_to_num(log_ratio, nan=-np.inf)
        p = Particles(np.where(accept[:, None], q.mirror, p.mirror),
                      np.where(accept[:, None], q.beacon, p.beacon),
                      np.where(accept[:, None, None], q.cov, p.cov),
                      np.where(accept, q.loglik, p.loglik))
    return p


def initial_particles(prior: Prior, n: int, params: PFParams, *, rng: np.random.Generator,
                      observer: ArrayLike | None = None) -> Particles:
    """The mirror drawn from the prior's uniform box; the beacon at its known start (to
    σ_trs); each hypothesis' log likelihood of the fixed beacons (they need the
    ``observer``), which :class:`MovingBeaconFilter` then weighs the draws by."""
    mirror = np.column_stack([rng.uniform(*prior.yaw_range, n),
                              rng.uniform(*prior.rho_range, n)])
    return replay(mirror, prior, (), observer=observer, params=params)


class MovingBeaconFilter:
    """Stateful wrapper of :func:`pf_step`: it keeps the particles, the weights and the
    history that the move step replays."""

    def __init__(self, observer, beacon_start, yaw_range, rho_range, n: int = DEFAULT_PARTICLES,
                 params: PFParams | None = None, rng: int | np.random.Generator | None = 0,
                 fixed: tuple[BeaconMeasurement, ...] = (), fixed_sigma: float = 0.0):
        self.observer = np.asarray(observer, float)
        self.params = params or PFParams()
        self.rng = np.random.default_rng(rng)
        self.prior = Prior(np.asarray(beacon_start, float), tuple(yaw_range), tuple(rho_range),
                           tuple(fixed), fixed_sigma)
        self.particles = initial_particles(self.prior, n, self.params, rng=self.rng,
                                           observer=observer)
        self.weights = np.full(n, 1.0 / n)
        self.history: tuple = ()
        if fixed:  # the uniform draws weighed by the fixed beacons, as any observation
            self.particles, self.weights = _reweigh(
                self.particles, self.particles.loglik.copy(), self.prior, (), self.observer,
                self.params, self.rng)

    def step(self, control: ArrayLike, observation: tuple[float, float] | None) -> None:
        """Move by ``control`` and weigh by ``observation`` (α, d_total; None: unseen)."""
        self.particles, self.weights = pf_step(self.particles, self.weights, control,
                                               observation=observation, observer=self.observer,
                                               params=self.params,
                                               rng=self.rng, prior=self.prior, history=self.history)
        self.history = (*self.history, (np.asarray(control, float), observation))

    def _spread(self) -> tuple[float, float, np.ndarray]:
        """The hypotheses' weighted mean yaw (a line angle, in [0, 180)) and offset along
        its normal, and each hypothesis' (yaw, offset) deviation from them."""
        w, m = self.weights, self.particles.mirror
        th = np.radians(m[:, 0])
        # line angles are modulo 180°: average the doubled angle
        # (in [0, 180) before ρ is taken along its normal: a mean yaw of −0.005° returned
        # as 179.995° turned the normal round, and the line stood 2ρ away)
        yaw = float(np.degrees(0.5 * np.arctan2(w @ np.sin(2 * th), w @ np.cos(2 * th)))
                    % 180.0)
        # express ρ in the mean yaw's normal
        rhos = (m[:, 1, None] * line_normal(m[:, 0])) @ line_normal(yaw)
        rho = float(w @ rhos)
        dev = np.column_stack([(m[:, 0] - yaw + 90.0) % 180.0 - 90.0, rhos - rho])
        return yaw, rho, dev

    def estimate(self) -> MirrorEstimate:
        """Weighted means of the beacon and the mirror (yaw averaged as a line angle), and
        the spread of the mirror hypotheses (weighted SD of yaw and offset)."""
        w = self.weights
        yaw, rho, dev = self._spread()
        yaw_sd, rho_sd = np.sqrt(w @ dev**2)
        return MirrorEstimate(beacon=w @ self.particles.beacon, yaw_deg=yaw, rho=rho,
                              yaw_sd_deg=float(yaw_sd), rho_sd=float(rho_sd))

    def nees(self, mirror_point: ArrayLike, mirror_yaw_deg: float) -> float:
        """eᵀ C⁻¹ e: the true mirror line's squared Mahalanobis distance from the
        hypotheses' weighted mean, in their weighted covariance of (yaw, offset) (the
        offsets along the mean yaw's normal, as :meth:`estimate` takes them).  χ²₂ for
        a consistent filter: 2 on average, ≤ 5.99 95 % of the time."""
        w = self.weights
        yaw, rho, dev = self._spread()
        cov = (w[:, None] * dev).T @ dev
        n_true = line_normal(mirror_yaw_deg)
        rho_true = float(n_true @ np.asarray(mirror_point, float)) * float(
            n_true @ line_normal(yaw))
        e = np.array([(mirror_yaw_deg - yaw + 90.0) % 180.0 - 90.0, rho_true - rho])
        try:
            return float(e @ np.linalg.solve(cov, e))
        except np.linalg.LinAlgError:  # the hypotheses collapsed onto one line
            return float("nan")


__all__ = ["PFParams", "Prior", "MirrorEstimate", "pf_step", "replay",
           "MovingBeaconFilter", "initial_particles", "DEFAULT_PARTICLES"]
