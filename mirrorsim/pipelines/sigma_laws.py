"""The σ laws fitted: log σ regressed on an image's features by maximum likelihood
of a Student-t, gross errors apart; the robust bias fit; the shared α error of a frame's images; and
how far a fit moves with its rows.  numpy and scipy on arrays:
:mod:`mirrorsim.pipelines.errormodel` gives them a dataset's columns."""

from __future__ import annotations

import numpy as np

from mirrorsim.formats.error_model import SIGMA_DOF_RANGE, LogSigma
from solver.measurements import Tail

GROSS = 6.0  # errors beyond this many σ's are gross errors, counted apart
# a shared α error is taken as there when its mean product is this many standard
# errors above 0 (by chance: about 1 dataset in 700)
SHARED_T = 3.0


def robust_fit(X: np.ndarray, y: np.ndarray, cut: float = 1.345) -> np.ndarray:
    """A Huber-loss linear fit on standardized features, dropping directions the data do
    not determine: for one object the image height is ∝ 1/d_total, so those two features
    are nearly collinear and a plain fit would trade huge opposite coefficients.

    ``cut``: where the loss turns linear, in robust σ's of the first residuals (1.345:
    95 % efficient for Gaussian errors).
    """
    from scipy.optimize import least_squares

    mu = X[:, 1:].mean(axis=0)
    sd = X[:, 1:].std(axis=0)
    sd[sd == 0] = 1.0
    Z = (X[:, 1:] - mu) / sd
    _, sv, vt = np.linalg.svd(Z, full_matrices=False)
    basis = vt[sv > 2e-2 * sv[0]].T  # the determined directions
    A = np.column_stack([np.ones(len(X)), Z @ basis])
    w0, *_ = np.linalg.lstsq(A, y, rcond=None)
    r0 = y - A @ w0
    scale = 1.4826 * float(np.median(np.abs(r0 - np.median(r0)))) or float(np.std(r0)) or 1.0
    w = least_squares(lambda w: A @ w - y, w0, loss="huber", f_scale=cut * scale).x
    bz = basis @ w[1:]
    return np.r_[w[0] - np.sum(bz * mu / sd), bz / sd]


def fit_log_sigma(X: np.ndarray, y: np.ndarray, ridge: float = 1e-3,
                  *, shared_var: float = 0.0) -> tuple[LogSigma, float]:
    """σ = exp(w·z) and ν by maximum likelihood of y ~ σ·t_ν (z: [1, standardized X]),
    with a small ridge on the slopes so that a feature the rows barely vary in stays
    flat.  The detector's errors are heavier-tailed than a Gaussian's (ν 2-4 on the
    ideal bench's domain dataset): a Gaussian fit's σ is their RMS, wide for the most of
    them, and a 95 % factor on it wider still; σ here is the scale of their bulk, and ν
    says how far their tail reaches (errors drawn from a Gaussian give ν at its bound,
    σ the Gaussian's).  σ is the spread about the truth (a bias is part of it: a
    measurement cannot be corrected for a bias its features do not predict);
    ``shared_var``: the variance of an error every image of a frame shares, known (added
    to σ² in the scale).  Returns the law and ν."""
    from scipy.optimize import minimize
    from scipy.special import gammaln

    Z, mu, sc = standardized(X)
    y2 = np.maximum(y**2, 1e-300)
    n = len(y)
    lo, hi = np.log(SIGMA_DOF_RANGE)

    def nll(p):
        w, nu = p[:-1], float(np.exp(np.clip(p[-1], lo, hi)))
        v = np.exp(2.0 * (Z @ w)) + shared_var
        ll = (gammaln((nu + 1) / 2) - gammaln(nu / 2) - 0.5 * np.log(nu * np.pi * v)
              - (nu + 1) / 2 * np.log1p(y2 / (nu * v)))
        return -np.sum(ll) + ridge * n * np.sum(w[1:] ** 2)

    own0 = max(np.mean(y2) - shared_var, 0.01 * np.mean(y2))
    p0 = np.r_[0.5 * np.log(own0), np.zeros(X.shape[1]), np.log(5.0)]
    p = minimize(nll, p0, method="BFGS").x
    w, nu = p[:-1], float(np.exp(np.clip(p[-1], lo, hi)))
    return LogSigma(float(w[0]), tuple(w[1:].tolist()), tuple(mu.tolist()),
                    tuple(sc.tolist())), nu


def standardized(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The design z = [1, (X − mean)/SD] (an SD of 0 taken as 1), the means and SDs."""
    mu, sc = X.mean(axis=0), X.std(axis=0)
    # a feature the rows do not vary in (to rounding: a constant's SD comes out 1e-16)
    # is left unscaled, its slope then held near 0 by the ridge
    sc[sc <= 1e-9 * (1.0 + np.abs(mu))] = 1.0
    return np.column_stack([np.ones(len(X)), (X - mu) / sc]), mu, sc


def gross_free_fit(X: np.ndarray, y: np.ndarray, shared_var: float = 0.0
                   ) -> tuple[LogSigma, float, np.ndarray]:
    """The σ law and its ν fitted on the rows that are not gross errors, and which rows
    are (more than GROSS predicted σ's off, and beyond the 99.9th percentile of its
    t_ν: a gross error is a detector fault, counted apart, not the law's tail)."""
    from scipy.stats import t as student

    scale = 1.4826 * float(np.median(np.abs(y))) or float(np.std(y)) or 1.0
    keep = np.abs(y) <= GROSS * scale
    for _ in range(4):  # the gross rows by the fitted σ's, until they settle
        law, nu = fit_log_sigma(X[keep], y[keep], shared_var=shared_var)
        reach = max(GROSS, float(student.ppf(0.9995, nu)))
        now = np.abs(y) <= reach * np.sqrt(law(X) ** 2 + shared_var)
        if np.array_equal(now, keep):
            break
        keep = now
    return law, nu, ~keep


STABILITY_DRAWS = 20


def stability(S: np.ndarray, y: np.ndarray, draws: int = STABILITY_DRAWS) -> float:
    """How far a σ law's fit moves with the rows drawn: refitted on ``draws`` resamples of
    (S, y) with replacement (a fixed seed: the same rows, the same answer), the factor
    between the largest and the smallest σ each row gets, at the 90th percentile of the
    rows."""
    rng = np.random.default_rng(0)
    sig = np.empty((draws, len(y)))
    for k in range(draws):
        pick = rng.integers(0, len(y), len(y))
        sig[k] = gross_free_fit(S[pick], y[pick])[0](S)  # as fitted: gross errors apart
    return float(np.quantile(sig.max(axis=0) / sig.min(axis=0), 0.9))


def fit_alpha_pair(St: np.ndarray, yt: np.ndarray, Sb: np.ndarray, *, yb: np.ndarray,
                   shared0: float, ridge: float = 1e-3) -> tuple[LogSigma, LogSigma, float]:
    """The target's and the beacon's own α laws and the shared σ, by maximum likelihood
    of each frame's pair of α errors ~ N(0, [[σt² + s², s²], [s², σb² + s²]]) (z's
    standardized as :func:`fit_log_sigma`'s, a small ridge on the slopes); ``shared0``
    starts s."""
    from scipy.optimize import minimize

    Zt, mt, ct = standardized(St)
    Zb, mb, cb = standardized(Sb)
    k = Zt.shape[1]
    n = len(yt)

    def nll(w):
        a, b, c = np.exp(2 * (Zt @ w[:k])), np.exp(2 * (Zb @ w[k:2 * k])), np.exp(2 * w[-1])
        det = a * b + c * (a + b)
        q = ((b + c) * yt**2 - 2 * c * yt * yb + (a + c) * yb**2) / det
        return (0.5 * np.sum(np.log(det) + q)
                + ridge * n * (np.sum(w[1:k] ** 2) + np.sum(w[k + 1:2 * k] ** 2)))

    def own(y):
        return 0.5 * np.log(max(np.mean(y**2) - shared0**2, 0.01 * np.mean(y**2)))

    w0 = np.r_[own(yt), np.zeros(k - 1), own(yb), np.zeros(k - 1), np.log(shared0)]
    w = minimize(nll, w0, method="BFGS").x
    law = lambda v, mu, sc: LogSigma(float(v[0]), tuple(v[1:].tolist()),  # noqa: E731
                                     tuple(mu.tolist()), tuple(sc.tolist()))
    return law(w[:k], mt, ct), law(w[k:2 * k], mb, cb), float(np.exp(w[-1]))


def shared_of(et: np.ndarray, eb: np.ndarray, m: np.ndarray) -> float:
    """σ (deg) of the α error every image of a frame shares (beyond what the pan's
    tolerance holds): √ of the mean product of each frame's target and beacon α errors
    (``et``, ``eb``: their own errors; independent errors average to 0), gross pairs
    left out; 0 unless the mean is positive by more than SHARED_T of its standard errors
    (an ideal bench's errors are independent)."""
    m = m & np.isfinite(et) & np.isfinite(eb)
    p = et[m] * eb[m]
    if p.size < 3:
        return 0.0
    med = float(np.median(np.abs(p)))
    p = p[np.abs(p) <= GROSS**2 * 1.4826**2 * med] if med > 0 else p  # gross pairs out
    if p.size < 3 or np.std(p) == 0:
        return 0.0
    t = np.mean(p) / (np.std(p, ddof=1) / np.sqrt(p.size))
    return float(np.sqrt(np.mean(p))) if t > SHARED_T else 0.0


# the fewest solved rows a tail is fitted on; fewer leave the σ's at their word
TAIL_MIN_ROWS = 30
TAIL_DOF_RANGE = (0.5, 1e4)


def fit_tail(distances: np.ndarray) -> Tail:
    """The :class:`~solver.measurements.Tail` of truths' Mahalanobis distances m from
    their estimates: (scale c ≥ 1, dof ν) by maximum likelihood of m/c ~ the radius of a
    2-D Student-t (:meth:`~solver.measurements.Tail.density`).
    With fewer than TAIL_MIN_ROWS finite distances: the σ's at their word.

    A tail widens the ellipses, never narrows them (c ≥ 1): rows whose covariance was
    wider than their errors (a bench's priors holding what one beacon cannot measure)
    say nothing of a solve where more beacons measure it, and a bench model fitted on
    one-beacon rows, its scale let fall to 0.39, held 25 of 60 self-calibrated
    three-beacon benches inside its 95 % ellipse."""
    from scipy.optimize import minimize

    m = np.asarray(distances, float)
    m = m[np.isfinite(m) & (m > 0)]
    if m.size < TAIL_MIN_ROWS:
        return Tail()
    lo, hi = np.log(TAIL_DOF_RANGE)

    def nll(p):
        tail = Tail(float(np.exp(max(p[0], 0.0))), float(np.exp(np.clip(p[1], lo, hi))))
        return -np.sum(np.log(tail.density(m)))

    start = [max(np.log(np.median(m) / 1.1774), 0.0), np.log(10.0)]
    p = minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9}).x
    return Tail(float(np.exp(max(p[0], 0.0))), float(np.exp(np.clip(p[1], lo, hi))))
