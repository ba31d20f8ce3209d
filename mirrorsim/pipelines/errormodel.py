"""The error model: each measurement's σ from what the experimenter knows, fitted on a
dataset's rows; and, to explain the errors, their bias against geometry and the bench.

For each object kind (target, beacon) and quantity (α error in degrees, relative d_total
error):

* **σ** (:mod:`mirrorsim.formats.error_model`): log σ linear in the measured features
  (:data:`~mirrorsim.formats.error_model_scope.SIGMA_FEATURES`), fitted with its degrees
  of freedom ν by maximum likelihood of a Student-t on the errors about the truth, gross
  errors (beyond GROSS predicted σ's and the t's 99.9 % reach) left out and counted.
  What the solver weights with, and what its error ellipse is made of; its ``tail``
  says how far 95 % of the training errors reach, in σ's over 1.96.
* **bias** (diagnostic): a robust linear fit (Huber loss, scipy's ``least_squares``) in
  the geometry [1, d_total, signed off-axis bearing, mirror incidence, 1/image height]
  and, for a dataset drawn with bench imperfections, each imperfection that varies in it
  (:data:`~mirrorsim.pipelines.error_features.BENCH_FEATURES`: the pan error, the
  calibration error, the mirror's curvature…).  These features come from the truth and
  from values an experimenter does not know, so the bias says what drives the errors;
  it never sets a σ.
* **the target's tail**: each row solved again with the model's σ's, the truths'
  Mahalanobis distances fitted as a scaled 2-D Student-t
  (:class:`~solver.measurements.Tail`), where the model's ellipses are drawn.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.error_model import (
    KINDS,
    ErrorModel,
    QuantityFit,
)
from mirrorsim.formats.error_model_file import sealed
from mirrorsim.formats.error_model_scope import (
    SCENE_DOMAIN,
    SIGMA_FEATURES,
    BenchTolerances,
    Domain,
)
from mirrorsim.formats.files import write_json
from mirrorsim.pipelines.error_features import (
    QUANTITY_COLUMNS,
    _design,
    features_of,
    own_errors,
    quantities_of,
    sigma_features_of,
)
from mirrorsim.pipelines.sigma_laws import (
    fit_alpha_pair,
    fit_tail,
    gross_free_fit,
    robust_fit,
    shared_of,
    stability,
)
from mirrorsim.pipelines.uncertainty import validate
from mirrorsim.scene import imperfections


def min_rows(names: tuple[str, ...] | list[str]) -> int:
    """The fewest usable rows of each kind a fit takes: five per coefficient of the σ law
    (:data:`MIN_ROWS`), and two more than the bias fit's coefficients."""
    return max(MIN_ROWS, len(names) + 2)


# five rows per coefficient of a σ law (its intercept and a slope per feature)
MIN_ROWS = 5 * (len(SIGMA_FEATURES) + 1)
# a law is unstable where its rows barely determine it: refitted on resamples of its
# own rows (STABILITY_DRAWS, drawn with replacement), the σ it gives a training row
# moves by more than this factor (the largest over the draws over the smallest, at the
# 90th percentile of the rows): refused; beyond UNSTABLE_WARN it is kept with a warning.
# A law of 400 rows of Gaussian errors moves by 1.5, of 60 rows by 3; the renders' heavy
# tails move a law of 120 rows by 2-9.  And a law whose σ's over its own rows span more
# than SPAN_REFUSE is refused: no image's error varies by four orders of magnitude
# across a domain (a d_total's σ goes as 1/height: 16-600 px is a factor 40)
UNSTABLE_REFUSE = 30.0
UNSTABLE_WARN = 4.0
SPAN_REFUSE = 1e4
TAIL_LEVEL = 0.95  # the tail factor: this share of the training errors within tail·z σ's
TAIL_Z = 1.959964


def fit(cols: dict, provenance: dict | None = None, bench: dict | None = None) -> ErrorModel:
    """Fit the model to dataset columns (name → sequence); rows with errors or missing
    values are left out.  ``bench``: the ``bench`` block of the spec the rows were drawn
    from (its ranges become the model's bench domain and tolerances).

    Each image's own error is its error less the parts every image of its frame shares
    (the pan reading, the calibration, the mirror's curvature: their bias coefficients
    times their values), which the solver estimates as nuisances with the tolerances'
    priors; the σ law is fitted to the own errors, its tail factor on them all.  Then
    each row is solved again with the model's σ's, and the truths' distances from the
    estimates give the model's target tail (where its ellipses are drawn).

    Raises
    ------
    ValueError
        When the rows mix planar and 3-D solves, too few rows are usable (the message
        says how many are needed), or a law is unstable (its σ's over its own rows span more
        than UNSTABLE_REFUSE).
    """
    names = features_of(cols)
    fits: dict[str, dict[str, QuantityFit]] = {}
    notes: list[str] = []
    scene_cols, quantities = cols, quantities_of(cols)  # (a 3-D dataset's: the elevation)
    # a row per beacon image: every beacon of a scene is fitted, its target once (the
    # pair fit and the shared α take the target beside each of its beacons)
    cols, beacon_of, scene_of = table.image_rows(cols)
    ok = table.usable_rows(cols)
    once = table.counted_once(beacon_of)
    need = min_rows(names)
    # pixel errors scale as 1/fx: each row's α errors as at the rows' median focal length
    fx = table.focal_lengths(cols)
    fx_px = float(np.median(fx[ok & np.isfinite(fx)])) if np.any(ok & np.isfinite(fx)) else None
    own_alpha: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    domain: dict[str, dict[str, tuple[float, float]]] = {}
    for kind in KINDS:
        X_all = _design(cols, kind, names)
        S_all = sigma_features_of(cols, kind)
        fits[kind] = {}
        for q in quantities:
            y = np.asarray(cols[table.object_column(kind, QUANTITY_COLUMNS[q])], float)
            m = (ok & once[kind] & np.isfinite(y) & np.isfinite(X_all).all(axis=1)
                 & np.isfinite(S_all).all(1))
            if m.sum() < need:
                raise ValueError(f"too few usable rows ({int(m.sum())}) to fit {kind} {q}: "
                                 f"{need} needed")
            bias = robust_fit(X_all[m], y[m])
            own = own_errors(cols, kind, q, names=names, bias=bias, fx_px=fx_px)
            if q == "alpha":
                own_alpha[kind] = (m, S_all, own)
            fits[kind][q] = _law(f"{kind} {q}", S_all[m], own[m], bias=bias, notes=notes)
        used = (ok & once[kind] & np.isfinite(S_all).all(1))
        domain[kind] = {n: (float(S_all[used, j].min()), float(S_all[used, j].max()))
                        for j, n in enumerate(SIGMA_FEATURES)}
    shared = _shared_alpha(fits, own_alpha, scene_of)
    model = ErrorModel(fits, Domain(domain, _scene_domain(scene_cols),
                                    imperfections.spec_ranges(bench or {})),
                       tolerances_of(bench or {}), tuple(names),
                       {**(provenance or {}), **({"warnings": notes} if notes else {})},
                       fx_px, shared)
    return _with_tail(model, scene_cols)


def _with_tail(model: ErrorModel, cols: dict) -> ErrorModel:
    """``model`` with the tail of its own rows solved again with its σ's
    (:func:`~mirrorsim.pipelines.sigma_laws.fit_tail`); rows without the geometry to
    solve them again (a table made by hand) leave the σ's at their word, and say so.  A
    3-D model's rows are solved again in 3-D (:func:`with_its_ellipsoid`)."""
    if model.three_d:
        return model
    try:
        distances = validate(model, cols).mahalanobis
    except ValueError as exc:  # a column the solve needs is missing
        return replace(model, provenance={**(model.provenance or {}),
                                          "tail_not_fitted": str(exc)})
    return replace(model, tail=fit_tail(distances))


def _law(which: str, S: np.ndarray, own: np.ndarray, *, bias: np.ndarray,
         notes: list[str]) -> QuantityFit:
    """One quantity's σ law fitted to its rows' own errors (gross errors apart), its tail
    factor on them all; refused where its σ's span more than SPAN_REFUSE or it moves by
    more than UNSTABLE_REFUSE on resamples of its rows (a note beyond UNSTABLE_WARN)."""
    law, nu, gross = gross_free_fit(S, own)
    sig = law(S)
    if not (np.isfinite(nu) and np.all(np.isfinite(sig))):
        raise ValueError(f"the {which} law did not converge (ν {nu:g}); fit it on more "
                         "rows, or rows that vary more evenly")
    tail = max(1.0, float(np.quantile(np.abs(own) / sig, TAIL_LEVEL)) / TAIL_Z)
    span = float(sig.max() / sig.min())
    if span > SPAN_REFUSE:
        raise ValueError(f"the {which} law is unstable: its σ's over its own "
                         f"{len(own)} rows span a factor {span:.3g} (from "
                         f"{sig.min():.3g}); fit it on more rows, or rows that vary "
                         "more evenly")
    moves = stability(S, own)
    if moves > UNSTABLE_REFUSE:
        raise ValueError(f"the {which} law is unstable: refitted on resamples of "
                         f"its own {len(own)} rows, the σ it gives a row moves by "
                         f"a factor {moves:.3g} (its rows barely determine it); fit "
                         "it on more rows, or rows that vary more evenly")
    if moves > UNSTABLE_WARN:
        notes.append(f"{which}: refitted on resamples of its rows, its σ's move by "
                     f"a factor {moves:.3g}")
    return QuantityFit(log_sigma=law, n=len(own), gross_errors=int(gross.sum()),
                       rms=float(np.sqrt(np.mean(own ** 2))),
                       typical_sigma=float(np.sqrt(np.mean(sig[~gross] ** 2))),
                       bias=tuple(bias.tolist()), tail=tail, dof=nu)


def _shared_alpha(fits: dict[str, dict[str, QuantityFit]],
                  own_alpha: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                  scene_of: np.ndarray) -> float:
    """The α error every image of a frame shares (σ, deg; 0 where none is found), from
    each beacon's image beside its scene's target; where there is one, both α laws
    refitted with it (in ``fits``)."""
    (mt, St, et), (mb, Sb, eb) = (own_alpha[k] for k in KINDS)
    both = mt[scene_of] & mb
    shared = shared_of(et, eb, both)
    if not shared:
        return shared
    # each kind's own α law is nearly free in its own likelihood when the shared part
    # dominates: both laws and the shared σ from the pair's likelihood, where the
    # difference of the two errors holds the own parts
    law_t, law_b, shared = fit_alpha_pair(St[both], et[both], Sb[both], yb=eb[both],
                                          shared0=shared)
    for kind, law, S, (m, _, own) in (("target", law_t, St, own_alpha["target"]),
                                      ("beacon", law_b, Sb, own_alpha["beacon"])):
        whole = np.hypot(law(S[m]), shared)
        tail = max(1.0, float(np.quantile(np.abs(own[m]) / whole, TAIL_LEVEL)) / TAIL_Z)
        fits[kind]["alpha"] = replace(
            fits[kind]["alpha"], log_sigma=law, tail=tail,
            typical_sigma=float(np.sqrt(np.mean(law(S[m]) ** 2))))
    return shared


def _scene_domain(cols: dict) -> dict[str, tuple[float, float]]:
    """The scenes' facts (SCENE_DOMAIN) over a table's usable rows: (min, max)."""
    ok = table.usable_rows(cols)
    names = {"fx_px": "fx_px", "camera_height_cm": "camera_height",
             "pencil_height_cm": "pencil_height_cm", "beacons": "beacons"}
    out = {}
    for key, column in names.items():
        v = np.asarray([np.nan if x is None else x for x in cols[column]], float)[ok]
        v = v[np.isfinite(v)]
        if not v.size:
            raise ValueError(f"the dataset's {column!r} column holds no value: it was made by "
                             "an older mirrorsim; make it again")
        out[key] = (float(v.min()), float(v.max()))
    assert set(out) == set(SCENE_DOMAIN)
    return out


def tolerances_of(bench: dict) -> BenchTolerances:
    """A spec's ``bench`` block as the population its benches were drawn from: each
    shared error's largest |value| (0 where not drawn)."""
    r = imperfections.spec_ranges(bench)
    half = lambda key: max((abs(x) for x in r.get(key, (0.0, 0.0))), default=0.0)  # noqa: E731
    return BenchTolerances(pan_deg=half("camera.pan_error"),
                           calibration_cm=half("calibration.distance_error"),
                           curvature_per_cm=half("mirror.curvature"),
                           beacon_position_cm=half("beacon.known_position_offset"))


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
    return with_its_ellipsoid(
        fit(cols, provenance_of(dataset_dir, cols), spec_of(dataset_dir).get("bench")),
        dataset_dir, cols)


def with_its_ellipsoid(model: ErrorModel, dataset_dir: str | Path, cols: dict) -> ErrorModel:
    """A 3-D model (:attr:`~ErrorModel.three_d`) with the ellipsoid scale its training
    rows, solved again in 3-D, give
    (:func:`~mirrorsim.pipelines.validate3d.with_ellipsoid_scale`); a planar one as it
    is (its target tail is fitted with it)."""
    if not model.three_d:
        return model
    from mirrorsim.pipelines.validate3d import with_ellipsoid_scale

    return with_ellipsoid_scale(model, dataset_dir, cols)


def spec_of(dataset_dir: str | Path) -> dict:
    """The spec a dataset folder's scenes were drawn from, as its ``dataset.json`` keeps
    it (empty where it keeps none)."""
    import json

    spec = json.loads((Path(dataset_dir) / "dataset.json").read_text()).get("spec")
    return spec if isinstance(spec, dict) else {}


def provenance_of(dataset_dir: str | Path, cols: dict) -> dict:
    """Where a model comes from: the dataset's seed, scene count and spec's name, and the
    command that fits it."""
    import json

    meta = json.loads((Path(dataset_dir) / "dataset.json").read_text())
    ok = np.flatnonzero(table.usable_rows(cols))
    # a few rows' measured errors, so that the rows can be made again and compared
    # (tests/test_uncertainty.py renders them anew)
    check = [{"index": int(cols["index"][i]),
              **{c: float(cols[c][i]) for c in CHECK_COLUMNS}} for i in ok[:CHECK_ROWS]]
    return {"dataset_seed": meta.get("seed"), "dataset_n": meta.get("n"),
            "spec_file": meta.get("spec_file"),
            "rows_used": int(table.usable_rows(cols).sum()),
            "command": f"mirrorsim errormodel {Path(dataset_dir).name}",
            "check_rows": check}


CHECK_ROWS = 2
CHECK_COLUMNS = tuple(table.object_column(k, c) for k in KINDS
                      for c in ("alpha_err", "d_rel_err", "height_px_meas", "noise"))


def read_columns(dataset_dir: str | Path) -> dict:
    """The dataset table as columns (name → list), verified
    (:func:`mirrorsim.formats.dataset_folder.read_table`)."""
    from mirrorsim.formats.dataset_folder import read_table

    return read_table(dataset_dir)


def write_model(model: ErrorModel, path: str | Path) -> None:
    """Write the model file (strict JSON, atomically), sealed (see
    :func:`~mirrorsim.formats.error_model_file.sealed`)."""
    write_json(path, sealed(model))
