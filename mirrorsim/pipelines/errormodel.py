"""The error model: each measurement's σ from what the experimenter knows, fitted on a
dataset's rows; and, to explain the errors, their bias against geometry and the bench.

For each object kind (target, beacon) and quantity (α error in degrees, relative d_total
error):

* **σ** (:mod:`mirrorsim.formats.error_model`): log σ linear in the measured features
  (log d_total, |off-axis bearing|), fitted by maximum likelihood on the errors about
  the truth, gross errors (beyond GROSS predicted σ's) left out and counted.  What the
  solver weights with, and what its error ellipse is made of.
* **bias** (diagnostic): a robust linear fit (Huber loss, scipy's ``least_squares``) in
  the geometry [1, d_total, signed off-axis bearing, mirror incidence, 1/image height]
  and, for a dataset drawn with bench imperfections, each imperfection that varies in it
  (:data:`BENCH_FEATURES`: the pan error, the calibration error, the mirror's
  curvature…).  These features come from the truth and from values an experimenter
  does not know, so the bias says what drives the errors; it never sets a σ.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.error_model import (
    KINDS,
    SIGMA_FEATURES,
    ErrorModel,
    LogSigma,
    QuantityFit,
    measured_features,
    sealed,
)
from mirrorsim.formats.files import save_figure, write_json
from mirrorsim.scene import imperfections

FEATURES = ("1", "d_total_cm", "off_axis_deg", "incidence_deg", "inv_height_px")
# A bench's imperfections (a dataset's bench_* columns) as bias features, each in the form
# its first-order effect is linear in (declared with its imperfection in the registry).
# A feature enters the bias fit only where its column varies.
BENCH_FEATURES = {f.name: f for f in imperfections.FEATURES}
QUANTITY_COLUMNS = {"alpha": "alpha_err", "d_rel": "d_rel_err"}
GROSS = 6.0  # errors beyond this many σ's are gross errors, counted apart
# a shared α error is taken as there when its mean product is this many standard
# errors above 0 (by chance: about 1 dataset in 700)
SHARED_T = 3.0


def _feature(cols: dict, kind: str, name: str) -> np.ndarray:
    """One feature column for ``kind`` (target or beacon)."""
    col = lambda k: np.asarray(cols[k], float)  # noqa: E731
    if name == "1":
        return np.ones(len(cols[table.object_column(kind, "d_true")]))
    if name in ("d_total_cm", "off_axis_deg", "incidence_deg"):
        return col(table.object_column(kind, {"d_total_cm": "d_true"}.get(name, name)))
    if name == "inv_height_px":
        return 1.0 / col(table.object_column(kind, "height_px_true"))
    if name in BENCH_FEATURES:
        return BENCH_FEATURES[name].of(col, lambda k: col(table.object_column(kind, k)))
    raise KeyError(name)


def features_of(cols: dict) -> list[str]:
    """The model's features for these columns: FEATURES, then each bench feature whose
    column varies (for either object)."""
    names = list(FEATURES)
    if imperfections.ROW_COLUMNS[0] not in cols:  # a dataset from before the bench
        return names
    ok = table.usable_rows(cols)
    for name in BENCH_FEATURES:
        for kind in ("target", "beacon"):
            v = _feature(cols, kind, name)[ok]
            v = v[np.isfinite(v)]
            if v.size and np.ptp(v) > 0:
                names.append(name)
                break
    return names


def _design(cols: dict, kind: str, names: list[str] | tuple[str, ...] = FEATURES
            ) -> np.ndarray:
    return np.column_stack([_feature(cols, kind, n) for n in names])


def _robust_fit(X: np.ndarray, y: np.ndarray, cut: float = 1.345) -> np.ndarray:
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
                  shared_var: float = 0.0) -> LogSigma:
    """σ = exp(w·z) by maximum likelihood of y ~ N(0, σ² + shared_var) (z: [1,
    standardized X]), with a small ridge on the slopes so that a feature the rows barely
    vary in stays flat.  σ is the spread about the truth (a bias is part of it: a
    measurement cannot be corrected for a bias its features do not predict);
    ``shared_var``: the variance of an error every image of a frame shares, known."""
    from scipy.optimize import minimize

    Z, mu, sc = _standardized(X)
    y2 = np.maximum(y**2, 1e-300)
    n = len(y)

    def nll(w):
        eta = Z @ w
        if shared_var == 0.0:
            e = y2 * np.exp(-2.0 * eta)
            value = np.sum(eta + 0.5 * e)
            g = 1.0 - e
        else:  # v = σ² + shared: d/dη of ½ log v + ½ y²/v is (σ²/v)(1 − y²/v)
            own = np.exp(2.0 * eta)
            v = own + shared_var
            value = np.sum(0.5 * np.log(v) + 0.5 * y2 / v)
            g = own / v * (1.0 - y2 / v)
        value += ridge * n * np.sum(w[1:] ** 2)
        grad = Z.T @ g + np.r_[0.0, 2.0 * ridge * n * w[1:]]
        return value, grad

    own0 = max(np.mean(y2) - shared_var, 0.01 * np.mean(y2))
    w0 = np.r_[0.5 * np.log(own0), np.zeros(X.shape[1])]
    w = minimize(nll, w0, jac=True, method="BFGS").x
    return LogSigma(float(w[0]), tuple(w[1:].tolist()), tuple(mu.tolist()), tuple(sc.tolist()))


def _standardized(X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The design z = [1, (X − mean)/SD] (an SD of 0 taken as 1), the means and SDs."""
    mu, sc = X.mean(axis=0), X.std(axis=0)
    sc[sc == 0] = 1.0
    return np.column_stack([np.ones(len(X)), (X - mu) / sc]), mu, sc


def _sigma_fit(X: np.ndarray, y: np.ndarray, shared_var: float = 0.0
               ) -> tuple[LogSigma, np.ndarray]:
    """The σ law fitted on the rows that are not gross errors, and which rows are (more
    than GROSS predicted σ's off): a gross error is a detector fault, counted apart."""
    scale = 1.4826 * float(np.median(np.abs(y))) or float(np.std(y)) or 1.0
    keep = np.abs(y) <= GROSS * scale
    for _ in range(4):  # the gross rows by the fitted σ's, until they settle
        law = fit_log_sigma(X[keep], y[keep], shared_var=shared_var)
        now = np.abs(y) <= GROSS * np.sqrt(law(X) ** 2 + shared_var)
        if np.array_equal(now, keep):
            break
        keep = now
    return law, ~keep


def sigma_features_of(cols: dict, kind: str) -> np.ndarray:
    """The σ law's features (SIGMA_FEATURES) of ``kind``'s measurements in dataset
    columns: from the measurement and the pan the capture record gives, as at
    measurement time."""
    col = lambda k: np.asarray(cols[k], float)  # noqa: E731
    for k in (table.object_column(kind, "d_meas"), "observer_pan_deg"):
        if k not in cols:
            raise ValueError(f"the dataset has no column {k!r}: it was made by an older "
                             "mirrorsim; make it again")
    return measured_features(col(table.object_column(kind, "d_meas")),
                             col(table.object_column(kind, "alpha_meas")),
                             col("observer_pan_deg"))


def min_rows(names: tuple[str, ...] | list[str]) -> int:
    """The fewest usable rows a fit takes: five per coefficient of the σ law, and two
    more than the bias fit's coefficients."""
    return max(5 * (len(SIGMA_FEATURES) + 1), len(names) + 2)


def fit(cols: dict, provenance: dict | None = None) -> ErrorModel:
    """Fit the model to dataset columns (name → sequence); rows with errors or missing
    values are left out.

    Raises
    ------
    ValueError
        When too few rows are usable (the message says how many are needed).
    """
    names = features_of(cols)
    fits: dict[str, dict[str, QuantityFit]] = {}
    # a row per beacon image: every beacon of a scene is fitted, its target once (the
    # pair fit and the shared α take the target beside each of its beacons)
    cols, beacon_of, scene_of = table.image_rows(cols)
    ok = table.usable_rows(cols)
    once = table.counted_once(beacon_of)
    need = min_rows(names)
    # pixel errors scale as 1/fx: each row's errors as at the rows' median focal length
    fx = table.focal_lengths(cols)
    fx_px = float(np.median(fx[ok & np.isfinite(fx)])) if np.any(ok & np.isfinite(fx)) else None
    at_fx = np.where(np.isfinite(fx), fx / (fx_px or 1.0), 1.0)
    shared = shared_alpha(cols, ok)
    alpha_rows = {}  # per kind: the α rows used and which were gross, for the pair fit
    for kind in KINDS:
        X_all = _design(cols, kind, names)
        S_all = sigma_features_of(cols, kind)
        fits[kind] = {}
        for q, col in QUANTITY_COLUMNS.items():
            y = np.asarray(cols[table.object_column(kind, col)], float)
            m = (ok & once[kind] & np.isfinite(y) & np.isfinite(X_all).all(axis=1)
                 & np.isfinite(S_all).all(1))
            if m.sum() < need:
                raise ValueError(f"too few usable rows ({int(m.sum())}) to fit {kind} {q}: "
                                 f"{need} needed")
            law, gross = _sigma_fit(S_all[m], (y * at_fx)[m],
                                    shared**2 if q == "alpha" else 0.0)
            bias = _robust_fit(X_all[m][~gross], y[m][~gross])
            if q == "alpha":
                keep = m.copy()
                keep[np.flatnonzero(m)[gross]] = False
                # the target's rows as its scene's first (the target fitted once)
                alpha_rows[kind] = (keep[scene_of] if kind == "target" else keep, S_all,
                                    y * at_fx)
            fits[kind][q] = QuantityFit(
                log_sigma=law, n=int(m.sum()), gross_errors=int(gross.sum()),
                rms=float(np.sqrt(np.mean((y * at_fx)[m] ** 2))),
                typical_sigma=float(np.sqrt(np.mean(law(S_all[m][~gross]) ** 2))),
                bias=tuple(bias.tolist()))
    if shared:
        # each kind's own α law is nearly free in its own likelihood when the shared
        # part dominates (a bench's pan): both laws and the shared σ from the pair's
        # likelihood, where the difference of the two errors holds the own parts
        (kt, St, yt), (kb, Sb, yb) = (alpha_rows[k] for k in KINDS)
        both = kt & kb
        law_t, law_b, shared = fit_alpha_pair(St[both], yt[both], Sb[both], yb[both], shared)
        for kind, law, S in (("target", law_t, St), ("beacon", law_b, Sb)):
            keep = alpha_rows[kind][0] & once[kind]
            fits[kind]["alpha"] = replace(
                fits[kind]["alpha"], log_sigma=law,
                typical_sigma=float(np.sqrt(np.mean(law(S[keep]) ** 2))))
    return ErrorModel(fits, tuple(names), provenance, fx_px, shared)


def fit_alpha_pair(St: np.ndarray, yt: np.ndarray, Sb: np.ndarray, yb: np.ndarray,
                   shared0: float, ridge: float = 1e-3) -> tuple[LogSigma, LogSigma, float]:
    """The target's and the beacon's own α laws and the shared σ, by maximum likelihood
    of each frame's pair of α errors ~ N(0, [[σt² + s², s²], [s², σb² + s²]]) (z's
    standardized as :func:`fit_log_sigma`'s, a small ridge on the slopes); ``shared0``
    starts s."""
    from scipy.optimize import minimize

    Zt, mt, ct = _standardized(St)
    Zb, mb, cb = _standardized(Sb)
    k = Zt.shape[1]
    n = len(yt)

    def nll(w):
        a, b, c = np.exp(2 * (Zt @ w[:k])), np.exp(2 * (Zb @ w[k:2 * k])), np.exp(2 * w[-1])
        det = a * b + c * (a + b)
        q = ((b + c) * yt**2 - 2 * c * yt * yb + (a + c) * yb**2) / det
        return (0.5 * np.sum(np.log(det) + q)
                + ridge * n * (np.sum(w[1:k] ** 2) + np.sum(w[k + 1:2 * k] ** 2)))

    own = lambda y: 0.5 * np.log(max(np.mean(y**2) - shared0**2, 0.01 * np.mean(y**2)))  # noqa: E731
    w0 = np.r_[own(yt), np.zeros(k - 1), own(yb), np.zeros(k - 1), np.log(shared0)]
    w = minimize(nll, w0, method="BFGS").x
    law = lambda v, mu, sc: LogSigma(float(v[0]), tuple(v[1:].tolist()),  # noqa: E731
                                     tuple(mu.tolist()), tuple(sc.tolist()))
    return law(w[:k], mt, ct), law(w[k:2 * k], mb, cb), float(np.exp(w[-1]))


def shared_alpha(cols: dict, ok: np.ndarray) -> float:
    """σ (deg) of the α error every image of a frame shares (a bench's pan reading):
    √ of the mean product of each frame's target and beacon α errors (independent errors
    average to 0), gross pairs left out; 0 unless the mean is positive by more than
    SHARED_T of its standard errors (an ideal bench's errors are independent)."""
    et = np.asarray(cols[table.object_column("target", "alpha_err")], float)
    eb = np.asarray(cols[table.object_column("beacon", "alpha_err")], float)
    m = ok & np.isfinite(et) & np.isfinite(eb)
    p = et[m] * eb[m]
    if p.size < 3:
        return 0.0
    med = float(np.median(np.abs(p)))
    p = p[np.abs(p) <= GROSS**2 * 1.4826**2 * med] if med > 0 else p  # gross pairs out
    if p.size < 3 or np.std(p) == 0:
        return 0.0
    t = np.mean(p) / (np.std(p, ddof=1) / np.sqrt(p.size))
    return float(np.sqrt(np.mean(p))) if t > SHARED_T else 0.0


def fit_dataset(dataset_dir: str | Path) -> ErrorModel:
    """The error model of a dataset folder (its verified table), with its provenance.

    Raises
    ------
    ValueError
        If the table has too few usable rows to fit a σ law (the message says how many
        it has and needs).
    DatasetError
        If the folder holds no verified dataset table.
    """
    cols = read_columns(dataset_dir)
    return fit(cols, provenance_of(dataset_dir, cols))


def provenance_of(dataset_dir: str | Path, cols: dict) -> dict:
    """Where a model comes from: the dataset's seed, scene count and spec's name, and the
    command that fits it."""
    import json

    meta = json.loads((Path(dataset_dir) / "dataset.json").read_text())
    return {"dataset_seed": meta.get("seed"), "dataset_n": meta.get("n"),
            "rows_used": int(table.usable_rows(cols).sum()),
            "command": f"mirrorsim errormodel {Path(dataset_dir).name}"}


def read_columns(dataset_dir: str | Path) -> dict:
    """The dataset table as columns (name → list), verified
    (:func:`mirrorsim.formats.dataset_folder.read_table`)."""
    from mirrorsim.formats.dataset_folder import read_table

    return read_table(dataset_dir)


def summary(model: ErrorModel) -> str:
    """The model in a few printed lines (σ_d in %)."""
    lines = ["error model: σ = exp(w·z), z = [1, " + ", ".join(SIGMA_FEATURES)
             + "] standardized; α in degrees, d_total in % of d_total"]
    for kind, qs in model.fits.items():
        for q, m in qs.items():
            scale, unit = (1.0, "°") if q == "alpha" else (100.0, " %")
            w = ", ".join(f"{n} {c:+.3f}" for n, c in zip(SIGMA_FEATURES, m.log_sigma.weights,
                                                          strict=True))
            lines.append(f"  {kind:6s} {q:5s}: n={m.n} ({m.gross_errors} gross left out), "
                         f"RMS error {scale * m.rms:.4f}{unit}, typical σ "
                         f"{scale * m.typical_sigma:.4f}{unit}; log σ slopes: {w}")
    lines.append(f"  an α offset shared by every image of a frame (the pan reading): σ "
                 f"{model.shared_alpha_deg:.4f}°" + (
                     " (each α law above is the image's own part)" if model.shared_alpha_deg
                     else " (none found: the images' α errors are independent)"))
    return "\n".join(lines)


def plot(cols: dict, model: ErrorModel, out: str | Path) -> Path:
    """Each row's error against its measured d_total and off-axis bearing, with the σ
    the model gives that row (a ±2σ bar on each point), and the errors in σ's against a
    standard normal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(16, 8.5))
    cols, beacon_of, _ = table.image_rows(cols)  # every beacon's image; the target once
    ok = table.usable_rows(cols)
    once = table.counted_once(beacon_of)
    grid = np.linspace(-5, 5, 201)
    for r, (q, col, scale, unit) in enumerate((("alpha", "alpha_err", 1.0, "°"),
                                                ("d_rel", "d_rel_err", 100.0, "% of d_total"))):
        for k, (kind, colour) in enumerate((("target", "#c0392b"), ("beacon", "#b8860b"))):
            y = np.asarray(cols[table.object_column(kind, col)], float)
            S = sigma_features_of(cols, kind)
            m = ok & once[kind] & np.isfinite(y) & np.isfinite(S).all(axis=1)
            fx = table.focal_lengths(cols)[m]
            sd = model.whole_sigma(kind, q, S[m], fx)
            for c, (x, name) in enumerate(((np.exp(S[m, 0]), "measured d_total (cm)"),
                                           (S[m, 1], "|off-axis bearing| (°)"))):
                axes[r, c].errorbar(x + 0.15 * k, y[m] * scale, yerr=2 * sd * scale, fmt="o",
                                    ms=3, color=colour, ecolor=colour, elinewidth=0.6,
                                    alpha=0.6, label=f"{kind} (bar: ±2σ of the model)")
                axes[r, c].set_xlabel(name)
                axes[r, c].set_ylabel(f"{q} error ({unit})")
            z = y[m] / sd
            axes[r, 2].hist(np.clip(z, -5, 5), bins=40, range=(-5, 5), density=True,
                            histtype="step", color=colour, label=f"{kind}: error / σ")
        axes[r, 2].plot(grid, np.exp(-grid**2 / 2) / np.sqrt(2 * np.pi), "k--", lw=1,
                        label="standard normal")
        axes[r, 2].set_xlabel(f"{q} error / σ (clipped to ±5)")
        axes[r, 2].set_ylabel("density")
        for ax in axes[r]:
            ax.legend(fontsize=8)
    fig.suptitle("detector errors and the error model's σ per measurement (training rows)")
    return save_figure(fig, out)


def write_model(model: ErrorModel, path: str | Path) -> None:
    """Write the model file (strict JSON, atomically), sealed (see
    :func:`~mirrorsim.formats.error_model.sealed`)."""
    write_json(path, sealed(model))
