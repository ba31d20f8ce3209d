"""The error model's file: written sealed, read and checked key by key; and the models
shipped with the package (``mirrorsim/data/``).  The model itself is
:mod:`mirrorsim.formats.error_model`'s."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from mirrorsim.formats.cache import seal, unseal
from mirrorsim.formats.error_model import (
    ANGLES,
    ELEVATION,
    FORMAT,
    KINDS,
    QUANTITIES,
    SIGMA_DOF_RANGE,
    VERSION,
    ErrorModel,
    ErrorModelError,
    LogSigma,
    QuantityFit,
    default_model_path,
)
from mirrorsim.formats.error_model_scope import (
    SCENE_DOMAIN,
    SIGMA_FEATURES,
    BenchTolerances,
    Domain,
)
from mirrorsim.formats.measurements import read_shared_alpha
from mirrorsim.formats.reader import Reader, read_json
from solver.measurements import (
    SIGMA_ALPHA_MAX_DEG,
    SIGMA_ALPHA_MIN_DEG,
    SIGMA_D_REL_MAX,
    SIGMA_D_REL_MIN,
    Tail,
)


def sealed(model: ErrorModel) -> dict:
    """The model file as ``mirrorsim errormodel`` writes it: :meth:`ErrorModel.to_json`
    with the checksum of its contents under ``"sha256"``, so that a model damaged or
    edited since is refused rather than used (a digit changed within range passes every
    other check)."""
    return seal(model.to_json())


def model_from_dict(data: Any, source: str | Path) -> ErrorModel:
    """Validate a parsed model file (raises :class:`ErrorModelError` naming the file and
    the key).  A file that carries a checksum (``"sha256"``: every file mirrorsim writes)
    must match it; a model written by hand carries none and is checked as the rest: its
    domain and its tolerances present and consistent, every number finite."""
    r = Reader(source, ErrorModelError)
    if isinstance(data, dict) and "sha256" in data:
        try:
            data = unseal(data, "the model")
        except ValueError:
            raise r.fail("sha256", "the checksum does not match the model's contents: the "
                                   "file was damaged or edited since mirrorsim wrote it (fit "
                                   "it again, or drop the sha256 key to use an edited "
                                   "model)") from None
    top = r.mapping(data, "", ("format", "version", "objects", "domain", "tolerances"),
                    optional=("units", "sigma_features", "bias_features", "provenance", "fx_px",
                     "shared_alpha_deg", "kind", "target_tail", "ellipsoid_scale"))
    if top["format"] != FORMAT or top["version"] != VERSION:
        raise r.fail("version", f"{top['version']!r}: not a version-{VERSION} {FORMAT}; fit it "
                                "again with this mirrorsim (`mirrorsim errormodel DATASET`)")
    if top.get("sigma_features", list(SIGMA_FEATURES)) != list(SIGMA_FEATURES):
        raise r.fail("sigma_features", f"{top['sigma_features']!r}: this mirrorsim computes "
                                       f"{list(SIGMA_FEATURES)}")
    objects = r.mapping(top["objects"], "objects", KINDS)
    fits: dict[str, dict[str, QuantityFit]] = {}
    for kind in KINDS:
        qs = r.mapping(objects[kind], f"objects.{kind}", QUANTITIES, optional=(ELEVATION,))
        fits[kind] = {q: _quantity(r, qs[q], f"objects.{kind}.{q}", q) for q in qs}
    lacking = [k for k in KINDS if ELEVATION not in fits[k]]
    if 0 < len(lacking) < len(KINDS):  # a 3-D model's, for each kind
        raise r.fail(f"objects.{lacking[0]}.{ELEVATION}", "missing: a 3-D model has an "
                     "elevation law for each kind")
    bias_features = top.get("bias_features", [])
    if not isinstance(bias_features, list) or not all(isinstance(b, str) for b in bias_features):
        raise r.fail("bias_features", "expected a list of names")
    prov = top.get("provenance")
    fx = top.get("fx_px")
    fx = None if fx is None else r.number(fx, "fx_px", positive=True, high=1e6)
    shared = read_shared_alpha(r, top.get("shared_alpha_deg", 0.0), "shared_alpha_deg")
    model = ErrorModel(fits, _domain(r, top["domain"]), _tolerances(r, top["tolerances"]),
                       tuple(bias_features), prov if isinstance(prov, dict) else None, fx,
                       shared, _tail(r, top.get("target_tail")),
                       r.number(top.get("ellipsoid_scale", 1.0), "ellipsoid_scale", low=1.0,
                                high=1e3))
    _check_consistent(r, model)
    if ("ellipsoid_scale" in top) != model.three_d:  # a 3-D model's, and only its
        raise r.fail("ellipsoid_scale", "a 3-D model's (its 3-D solves' covariance widened): "
                     + ("this model has no elevation laws" if "ellipsoid_scale" in top
                        else "missing beside its elevation laws"))
    if "kind" in top and top["kind"] != model.kind:
        raise r.fail("kind", f"{top['kind']!r}, but its tolerances and bench domain make it "
                             f"a {model.kind}-bench model")
    return model


def _check_consistent(r: Reader, model: ErrorModel) -> None:
    """Refuse a model whose parts disagree: a law standardized about a mean outside the
    domain its rows spanned, or whose typical σ is not what the law gives there (within
    a factor 10: the law is the typical σ's source)."""
    for kind, qs in model.fits.items():
        for q, fit in qs.items():
            key = f"objects.{kind}.{q}"
            for name, mean in zip(SIGMA_FEATURES, fit.log_sigma.mean, strict=True):
                lo, hi = model.domain.features[kind][name]
                if not lo - 1e-9 * max(1.0, abs(lo)) <= mean <= hi + 1e-9 * max(1.0, abs(hi)):
                    raise r.fail(f"{key}.log_sigma.mean", f"{name} {mean:.4g} lies outside the "
                                 f"domain the model declares ({lo:.4g} to {hi:.4g}): the law "
                                 "and the domain are of different fits")
            at_mean = float(fit.sigma(np.asarray(fit.log_sigma.mean)))
            if not 0.1 <= fit.typical_sigma / at_mean <= 10.0:
                raise r.fail(f"{key}.typical_sigma", f"{fit.typical_sigma:.3g}, but the law "
                             f"gives {at_mean:.3g} at its rows' mean: they are of different "
                             "fits")


def _tail(r: Reader, value: Any) -> Tail:
    """The ``target_tail`` entry (missing: the σ's at their word): a scale > 0 and a dof
    > 0 or null (a Gaussian's)."""
    if value is None:
        return Tail()
    d = r.mapping(value, "target_tail", ("scale", "dof"))
    scale = r.number(d["scale"], "target_tail.scale", positive=True, high=1e3)
    dof = None if d["dof"] is None else r.number(d["dof"], "target_tail.dof", positive=True,
                                                   high=1e9)
    return Tail(scale, math.inf if dof is None else dof)


def _range(r: Reader, value: Any, key: str, low: float | None = None) -> tuple[float, float]:
    pair = _list(r, value, key, 2)
    lo, hi = (r.number(v, f"{key}[{i}]", low=low) for i, v in enumerate(pair))
    if lo > hi:
        raise r.fail(key, f"{pair}: the range's low end exceeds its high end")
    return lo, hi


def _domain(r: Reader, value: Any) -> Domain:
    d = r.mapping(value, "domain", ("features", "scene"), optional=("bench",))
    feats = r.mapping(d["features"], "domain.features", KINDS)
    features = {}
    for kind in KINDS:
        f = r.mapping(feats[kind], f"domain.features.{kind}", SIGMA_FEATURES)
        features[kind] = {n: _range(r, f[n], f"domain.features.{kind}.{n}")
                          for n in SIGMA_FEATURES}
    scene = r.mapping(d["scene"], "domain.scene", tuple(SCENE_DOMAIN))
    bench = d.get("bench", {})
    if not isinstance(bench, dict):
        raise r.fail("domain.bench", "expected a mapping of key paths to [low, high]")
    return Domain(features,
                  {k: _range(r, scene[k], f"domain.scene.{k}", low=0.0) for k in SCENE_DOMAIN},
                  {str(k): _range(r, v, f"domain.bench.{k}") for k, v in bench.items()})


def _tolerances(r: Reader, value: Any) -> BenchTolerances:
    t = r.mapping(value, "tolerances", (),
                  optional=("pan_deg", "calibration_cm", "curvature_per_cm",
                                            "beacon_position_cm"))
    highs = {"pan_deg": 10.0, "calibration_cm": 50.0, "curvature_per_cm": 0.1,
             "beacon_position_cm": 10.0}
    return BenchTolerances(**{k: r.number(t.get(k, 0.0), f"tolerances.{k}", low=0.0,
                                          high=highs[k]) for k in highs})


def _quantity(r: Reader, value: Any, key: str, q: str) -> QuantityFit:
    f = r.mapping(value, key, ("log_sigma", "n", "typical_sigma", "tail", "dof"),
                  optional=("gross_errors", "rms", "bias"))
    ls = r.mapping(f["log_sigma"], f"{key}.log_sigma", ("intercept", "weights", "mean", "scale"))
    k = len(SIGMA_FEATURES)
    vec = lambda name: tuple(r.number(v, f"{key}.log_sigma.{name}[{i}]")  # noqa: E731
                             for i, v in enumerate(_list(r, ls[name], f"{key}.log_sigma.{name}",
                                                         k)))
    law = LogSigma(r.number(ls["intercept"], f"{key}.log_sigma.intercept", low=-50, high=50),
                   vec("weights"), vec("mean"), vec("scale"))
    if not all(s > 0 for s in law.scale):
        raise r.fail(f"{key}.log_sigma.scale", f"{list(law.scale)}: scales must be > 0")
    if not all(abs(w) <= 20 for w in law.weights):
        raise r.fail(f"{key}.log_sigma.weights", f"{list(law.weights)}: a slope beyond ±20 "
                     "per standard deviation of its feature is no fit")
    low, high = ((SIGMA_ALPHA_MIN_DEG, SIGMA_ALPHA_MAX_DEG) if q in ANGLES
                 else (SIGMA_D_REL_MIN, SIGMA_D_REL_MAX))
    typical = r.number(f["typical_sigma"], f"{key}.typical_sigma", low=low, high=high)
    bias = f.get("bias", [])
    return QuantityFit(law, int(r.number(f["n"], f"{key}.n", low=0)),
                       int(r.number(f.get("gross_errors", 0), f"{key}.gross_errors", low=0)),
                       r.number(f.get("rms", 0.0), f"{key}.rms", low=0),
                       typical,
                       tuple(r.number(b, f"{key}.bias[{i}]")
                             for i, b in enumerate(_list(r, bias, f"{key}.bias"))),
                       r.number(f["tail"], f"{key}.tail", low=1.0, high=100.0),
                       math.inf if f["dof"] is None else
                       r.number(f["dof"], f"{key}.dof", low=SIGMA_DOF_RANGE[0],
                                high=SIGMA_DOF_RANGE[1] * (1 + 1e-9)))


def _list(r: Reader, value: Any, key: str, length: int | None = None) -> list:
    if not isinstance(value, list) or (length is not None and len(value) != length):
        want = f"a list of {length} numbers" if length is not None else "a list of numbers"
        raise r.fail(key, f"expected {want}")
    return value


def load_error_model(path: str | Path) -> ErrorModel:
    """Read and validate a model file (see :func:`model_from_dict`)."""
    return replace(model_from_dict(read_json(path, ErrorModelError), path), source=str(path))


def load_error_model_or_default(path: str | Path | None = None, kind: str = "ideal"
                                ) -> ErrorModel:
    """The model file at ``path``, or (None) the shipped model of ``kind`` (``ideal`` or
    ``bench``).

    Raises
    ------
    ErrorModelError
        A file that is missing or not a valid model (one line naming the key); a
        ``path`` that is not a path.
    """
    if path is None:
        return default_error_model(kind)
    if not isinstance(path, str | Path):
        raise ErrorModelError(str(path), "", f"an error model's path must be a str or a "
                              f"Path, got {type(path).__name__}")
    return load_error_model(path)


def default_error_model(kind: str = "ideal") -> ErrorModel:
    """:func:`default_model_path`'s model."""
    return load_error_model(default_model_path(kind))
