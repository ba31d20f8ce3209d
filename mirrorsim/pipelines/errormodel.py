"""The error model: bias and spread of the detector's α and d_total/d against geometry.

For each object (target, beacon) and quantity (α error in degrees, relative d_total
error), a linear model in the features [1, d_total, signed off-axis bearing, mirror
incidence, 1/image height in px]: the bias by a robust fit (Huber loss, scipy's
``least_squares``: a few gross errors do not drag it), the spread by the same on the
absolute residuals (× √(π/2), so it estimates a Gaussian σ) of the rows within
``GROSS`` robust σ's; the rows beyond are counted as gross errors.  The off-axis bearing is
signed (α − pan: + = left of the axis): a bias that changes sign across the axis is a line
through zero, which |off-axis| cannot represent.  A dataset drawn with bench
imperfections (the spec's ``bench:`` block) adds a feature for each imperfection that
varies in it (:data:`BENCH_FEATURES`), so the bias and spread are fitted against the
pan error, the calibration error, the mirror's curvature…  The model file also holds the
typical σ's that `solve`, `montecarlo` and `plan` take (``--error-model FILE``): the
RMS over the rows of bias and spread together, so a bench's imperfections enter them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.files import atomic_path, write_json
from mirrorsim.formats.measurements import read_sigma
from mirrorsim.formats.reader import Reader, read_json
from mirrorsim.scene import imperfections
from solver.lsq import Sigma

FEATURES = ("1", "d_total_cm", "off_axis_deg", "incidence_deg", "inv_height_px")
# A bench's imperfections (a dataset's bench_* columns) as features, each in the form its
# first-order effect is linear in (declared with its imperfection in the registry).  A
# feature enters a model only where its column varies.
BENCH_FEATURES = {f.name: f for f in imperfections.FEATURES}
QUANTITIES = {"alpha": "alpha_err", "d_rel": "d_rel_err"}
GROSS = 6.0  # residuals beyond this many robust σ's are gross errors, counted apart


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
    ok = np.array([not e for e in cols.get("error", [""] * len(cols["index"]))])
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


@dataclass(frozen=True)
class QuantityFit:
    """One object's one quantity (α error in degrees, or relative d_total error): its
    bias and spread as linear models in the features, and how many rows made them."""

    bias: tuple[float, ...]
    spread: tuple[float, ...]
    n: int
    gross_errors: int
    rms: float
    typical_sigma: float  # RMS over the rows of bias and spread together

    def to_json(self) -> dict:
        """The model file's entry."""
        return {"bias": list(self.bias), "spread": list(self.spread), "n": self.n,
                "gross_errors": self.gross_errors, "rms": self.rms,
                "typical_sigma": self.typical_sigma}


@dataclass(frozen=True)
class ErrorModel:
    """The fitted model: its features, a fit per object and quantity, and the σ pair the
    solver takes."""

    features: tuple[str, ...]
    fits: dict[str, dict[str, QuantityFit]]  # "target"/"beacon" → "alpha"/"d_rel" → fit
    sigma: Sigma

    def to_json(self) -> dict:
        """The model file (``mirrorsim errormodel``)."""
        return {"features": list(self.features),
                "objects": {k: {q: f.to_json() for q, f in qs.items()}
                            for k, qs in self.fits.items()},
                "sigma": {"alpha_deg": self.sigma.alpha_deg,
                          "d_total_rel": self.sigma.d_total_rel}}


def fit(cols: dict) -> ErrorModel:
    """Fit the model to dataset columns (name → sequence); rows with errors or missing
    values are left out."""
    names = features_of(cols)
    fits: dict[str, dict[str, QuantityFit]] = {}
    ok = np.array([not e for e in cols.get("error", [""] * len(cols["index"]))])
    for kind in ("target", "beacon"):
        X_all = _design(cols, kind, names)
        fits[kind] = {}
        for q, col in QUANTITIES.items():
            y = np.asarray(cols[table.object_column(kind, col)], float)
            m = ok & np.isfinite(y) & np.isfinite(X_all).all(axis=1)
            X, yy = X_all[m], y[m]
            if len(yy) < len(names) + 2:
                raise ValueError(f"too few usable rows ({len(yy)}) to fit {kind} {q}: "
                                 f"{len(names) + 2} needed")
            bias = _robust_fit(X, yy)
            resid = yy - X @ bias
            # gross errors (beyond GROSS robust σ's) are counted, not fitted: the spread
            # is the Gaussian part's
            sigma0 = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
            keep = np.abs(resid) <= GROSS * sigma0 if sigma0 > 0 else np.ones(len(yy), bool)
            spread = _robust_fit(X[keep], np.abs(resid[keep]) * math.sqrt(math.pi / 2),
                                 cut=GROSS)
            sd = np.maximum(X @ spread, 0.0)
            fits[kind][q] = QuantityFit(
                bias=tuple(bias.tolist()), spread=tuple(spread.tolist()), n=int(len(yy)),
                gross_errors=int((~keep).sum()), rms=float(np.sqrt(np.mean(yy**2))),
                typical_sigma=float(np.sqrt(np.mean(sd**2 + (X @ bias) ** 2))))
    # the larger of target's and beacon's: one σ pair for the solver
    sigma = Sigma(alpha_deg=max(f["alpha"].typical_sigma for f in fits.values()),
                  d_total_rel=max(f["d_rel"].typical_sigma for f in fits.values()))
    return ErrorModel(tuple(names), fits, sigma)


def predict(model: ErrorModel, kind: str, quantity: str, features: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """(bias, σ) of a quantity for feature rows (k, len(model.features)), in the order
    of ``model.features``."""
    m = model.fits[kind][quantity]
    X = np.atleast_2d(features)
    return X @ np.asarray(m.bias), np.maximum(X @ np.asarray(m.spread), 0.0)


def load_sigma(path: str | Path) -> Sigma:
    """The typical σ's of a model file, as the solver takes them (checked as a
    measurement file's ``sigma`` is)."""
    model = read_json(path)
    r = Reader(path)
    if not isinstance(model, dict) or "sigma" not in model:
        raise r.fail("sigma", "missing: not an error model file (`mirrorsim errormodel`)")
    return read_sigma(r, model["sigma"])


def read_columns(dataset_dir: str | Path) -> dict:
    """The dataset table as columns (name → list), verified
    (:func:`mirrorsim.formats.dataset_folder.read_table`)."""
    from mirrorsim.formats.dataset_folder import read_table

    return read_table(dataset_dir)


def summary(model: ErrorModel) -> str:
    """The model in a few printed lines."""
    lines = [f"error model: features {', '.join(model.features)}"]
    for kind, qs in model.fits.items():
        for q, m in qs.items():
            unit = "°" if q == "alpha" else " (relative)"
            coef = ", ".join(f"{n} {c:.4g}" for n, c in zip(model.features, m.bias, strict=True))
            lines.append(f"  {kind:6s} {q:5s}: n={m.n} ({m.gross_errors} gross), "
                         f"RMS {m.rms:.5f}{unit}, typical σ {m.typical_sigma:.5f}; "
                         f"bias: {coef}")
    s = model.sigma
    lines.append(f"  σ for the solver: α {s.alpha_deg:.5f}°, d_total {100 * s.d_total_rel:.3f} %")
    return "\n".join(lines)


def plot(cols: dict, model: ErrorModel, out: str | Path) -> Path:
    """Errors against distance and incidence, with the fitted bias ± σ, and histograms."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(18, 8))
    ok = np.array([not e for e in cols.get("error", [""] * len(cols["index"]))])
    for r, (q, col, scale, unit) in enumerate((("alpha", "alpha_err", 1.0, "°"),
                                                ("d_rel", "d_rel_err", 100.0, "%"))):
        for kind, colour in (("target", "#c0392b"), ("beacon", "#d4a017")):
            y = np.asarray(cols[table.object_column(kind, col)], float) * scale
            X = _design(cols, kind, model.features)
            m = ok & np.isfinite(y)
            for c, (fi, name) in enumerate(((1, "d_total (cm)"), (3, "incidence (°)"))):
                ax = axes[r, c]
                ax.scatter(X[m, fi], y[m], s=8, color=colour, alpha=0.6, label=kind)
                xs = np.linspace(X[m, fi].min(), X[m, fi].max(), 50)
                F = np.tile(X[m].mean(axis=0), (50, 1))
                F[:, fi] = xs
                b, sd = predict(model, kind, q, F)
                ax.plot(xs, b * scale, color=colour)
                ax.fill_between(xs, (b - sd) * scale, (b + sd) * scale, color=colour, alpha=0.15)
                ax.set_xlabel(name)
                ax.set_ylabel(f"{q} error ({unit})")
            axes[r, 2 if kind == "target" else 3].hist(y[m], bins=30, color=colour, alpha=0.8)
            axes[r, 2 if kind == "target" else 3].set_title(f"{kind}: {q} error ({unit})")
        axes[r, 0].legend(fontsize=8)
    fig.suptitle("detector error against geometry (lines: fitted bias, bands: ±σ at mean "
                 "features)")
    fig.tight_layout()
    out = Path(out)
    try:
        with atomic_path(out) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return out


def write_model(model: ErrorModel, path: str | Path) -> None:
    """Write the model file (strict JSON, atomically)."""
    write_json(path, model.to_json())
