"""A dataset's columns as the error model reads them: each image's σ features (what its
frame showed, known at measurement time), the geometry and bench features of the bias
fit, and each image's own error (the parts its frame shares apart).  The fit
(:mod:`mirrorsim.pipelines.errormodel`) and its validation
(:mod:`mirrorsim.pipelines.uncertainty`) both read rows through these."""

from __future__ import annotations

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.error_model import (
    ANGLES,
    ELEVATION,
    QUANTITIES,
    ErrorModel,
    feature_vector,
    off_axis,
)
from mirrorsim.scene import imperfections

FEATURES = ("1", "d_total_cm", "off_axis_deg", "incidence_deg", "inv_height_px")
# A bench's imperfections (a dataset's bench_* columns) as bias features, each in the form
# its first-order effect is linear in (declared with its imperfection in the registry).
# A feature enters the bias fit only where its column varies.
BENCH_FEATURES = {f.name: f for f in imperfections.FEATURES}
# each quantity's error column (the elevation's in a 3-D dataset's rows alone)
QUANTITY_COLUMNS = {"alpha": "alpha_err", "d_rel": "d_rel_err", ELEVATION: "elevation_err"}


def quantities_of(cols: dict) -> tuple[str, ...]:
    """What a table's rows measured of each image: α and d_total, and in a 3-D dataset's
    rows (``geometry`` 3d) the elevation besides.

    Raises
    ------
    ValueError
        For rows of both geometries (a model is fitted on one).
    """
    kinds = set(cols.get("geometry") or ["planar"]) - {None}
    if len(kinds) > 1:
        raise ValueError("its rows mix planar and 3-D solves: fit a model on one of them")
    return (*QUANTITIES, ELEVATION) if kinds == {"3d"} else QUANTITIES


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


def sigma_features_of(cols: dict, kind: str) -> np.ndarray:
    """The σ law's features (SIGMA_FEATURES) of ``kind``'s images in dataset columns:
    what each frame showed of the image, and its bearing off the pan the capture record
    gives, as at measurement time (NaN where not measured).

    Raises
    ------
    ValueError
        For a table made before these were recorded.
    """
    col = lambda k: np.asarray(cols[k], float)  # noqa: E731
    names = [table.object_column(kind, c) for c in ("height_px_meas", "contrast", "noise",
                                                    "jpeg_quality", "alpha_meas")]
    for k in (*names, "observer_pan_deg"):
        if k not in cols or all(v is None for v in cols[k]):
            raise ValueError(f"the dataset has no column {k!r}: it was made by an older "
                             "mirrorsim; make it again")
    h, contrast, noise, jpeg, alpha = (col(k) for k in names)
    return feature_vector(h, off_axis(alpha, col("observer_pan_deg")), contrast, noise=noise,
                          jpeg_quality=jpeg)


# the bias features of the errors every image of a frame shares, which the solver
# estimates (its nuisances with their priors) rather than each image's σ holding them:
# the pan reading (α), the calibration's distance and the mirror's curvature (d_total)
SHARED_FEATURES = {"alpha": ("pan_error_deg",),
                   "d_rel": ("calibration_error_cm", "mirror_power")}


def own_errors(cols: dict, kind: str, q: str, *, names: tuple[str, ...] | list[str],
               bias: tuple[float, ...] | np.ndarray, fx_px: float | None) -> np.ndarray:
    """Each row's own error of ``kind``'s ``q``: its error less the parts every image of
    its frame shares (SHARED_FEATURES' bias coefficients times their values), and for an
    angle (α, elevation) as at the focal length ``fx_px`` (pixel errors scale as 1/fx)."""
    y = np.asarray(cols[table.object_column(kind, QUANTITY_COLUMNS[q])], float)
    X = _design(cols, kind, names)
    idx = [list(names).index(f) for f in SHARED_FEATURES.get(q, ()) if f in names]
    own = y - X[:, idx] @ np.asarray(bias, float)[idx] if idx else y
    if q in ANGLES:
        fx = table.focal_lengths(cols)
        own = own * np.where(np.isfinite(fx), fx / (fx_px or 1.0), 1.0)
    return own


def model_own_errors(cols: dict, model: ErrorModel, kind: str, *, q: str) -> np.ndarray:
    """:func:`own_errors` with ``model``'s bias fit (image rows of a table)."""
    return own_errors(cols, kind, q, names=model.bias_features, bias=model.fits[kind][q].bias,
                      fx_px=model.fx_px)
