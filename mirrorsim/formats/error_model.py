"""The error model file (``mirrorsim errormodel`` writes it; every command that solves
reads it): per object kind (target, beacon) and quantity (α, d_total), a σ that the
experimenter can compute for each measurement, and the diagnostic bias fits.

A measurement's σ is ``exp(w · z)`` with z = [1, standardized measured features]
(:data:`SIGMA_FEATURES`): positive by construction, and a function of what is known
when the photograph is measured (the measurement itself and the capture record), never
of the truth or of a bench's imperfection values, which the experimenter does not know.
A bench's unknown imperfections enter as the spread they cause in the dataset the
model was fitted on.  The detector's errors are pixel errors: at a focal length of fx
pixels σ_α (an axis column's error over fx) and σ_d (a height's error over the height,
∝ fx) both scale as 1/fx, so a model fitted at the training frames' median fx
(``fx_px``) serves other resolutions and fields of view by the factor fx_px / fx.

Units, in the file and everywhere in mirrorsim: α errors and σ_α in degrees; d_total
errors and σ_d relative, a fraction of d_total (0.002 = 0.2 %; printed tables show %).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mirrorsim.formats.cache import seal, unseal
from mirrorsim.formats.measurements import read_shared_alpha
from mirrorsim.formats.reader import Reader, read_json
from solver.errors import InputError
from solver.measurements import (
    SIGMA_ALPHA_MAX_DEG,
    SIGMA_ALPHA_MIN_DEG,
    SIGMA_D_REL_MAX,
    SIGMA_D_REL_MIN,
    ObjectSigmas,
    Sigma,
)

FORMAT = "mirrorsim error model"
VERSION = 2
KINDS = ("target", "beacon")
QUANTITIES = ("alpha", "d_rel")
# what σ depends on, from the measurement and the capture record alone
SIGMA_FEATURES = ("log_d_total_cm", "abs_off_axis_deg")
UNITS = {"alpha": "deg", "d_rel": "fraction of d_total (0.002 = 0.2 %)"}
DEFAULT_NAME = "error_model.json"


class ErrorModelError(InputError):
    """A bad error model file."""


def measured_features(d_total: Any, alpha_deg: Any, pan_deg: Any) -> np.ndarray:
    """:data:`SIGMA_FEATURES` of measurements (broadcasts): log of the measured d_total
    (cm) and the image's bearing off the optical axis (deg, unsigned)."""
    d = np.asarray(d_total, float)
    off = (np.asarray(alpha_deg, float) - np.asarray(pan_deg, float) + 180.0) % 360.0 - 180.0
    return np.stack(np.broadcast_arrays(np.log(d), np.abs(off)), axis=-1)


@dataclass(frozen=True)
class LogSigma:
    """σ = exp(intercept + Σ weight·(feature − mean)/scale): one quantity of one kind."""

    intercept: float
    weights: tuple[float, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]

    def __call__(self, features: np.ndarray) -> np.ndarray:
        """σ for feature rows (…, len(SIGMA_FEATURES))."""
        z = (np.asarray(features, float) - np.asarray(self.mean)) / np.asarray(self.scale)
        return np.exp(self.intercept + z @ np.asarray(self.weights))

    def to_json(self) -> dict:
        """The file's entry."""
        return {"intercept": self.intercept, "weights": list(self.weights),
                "mean": list(self.mean), "scale": list(self.scale)}


@dataclass(frozen=True)
class QuantityFit:
    """One kind's one quantity: its σ law, how many rows made it and how many gross
    errors were left out, the rows' RMS error, and the diagnostic bias fit (linear in
    the model's ``bias_features``, which may include truth and bench values: it explains
    the errors, it does not predict a measurement's σ)."""

    log_sigma: LogSigma
    n: int
    gross_errors: int
    rms: float
    typical_sigma: float  # RMS over the training rows of the predicted σ
    bias: tuple[float, ...] = ()

    def to_json(self) -> dict:
        """The file's entry."""
        return {"log_sigma": self.log_sigma.to_json(), "n": self.n,
                "gross_errors": self.gross_errors, "rms": self.rms,
                "typical_sigma": self.typical_sigma, "bias": list(self.bias)}


@dataclass(frozen=True)
class ErrorModel:
    """The fitted model: a :class:`QuantityFit` per kind and quantity."""

    fits: dict[str, dict[str, QuantityFit]]  # "target"/"beacon" → "alpha"/"d_rel" → fit
    bias_features: tuple[str, ...] = ()
    provenance: dict | None = None  # how it was made (dataset, seed, n, command)
    fx_px: float | None = None  # the training frames' median focal length (px)
    # σ (deg) of an α offset every image of a frame shares (a bench's pan reading), from
    # the training rows' covariance of target and beacon α errors; the α laws are then
    # each image's own part.  A mechanical angle: it does not scale with fx.
    shared_alpha_deg: float = 0.0
    # the file it was read from (None: made in memory), for records that name it (a
    # dataset's card); not part of the model, so not in its file, digest or equality
    source: str | None = field(default=None, compare=False)

    def fx_scale(self, fx_px: ArrayLike | None) -> float | np.ndarray:
        """The factor on σ for frames of focal length ``fx_px`` (broadcasts; 1 where it
        or the model's is unknown): pixel errors scale as fx_px(model) / fx."""
        fx = np.asarray(np.nan if fx_px is None else fx_px, float)
        ok = np.isfinite(fx) & (fx > 0) & bool(self.fx_px)
        scale = np.where(ok, (self.fx_px or 1.0) / np.where(ok, fx, 1.0), 1.0)
        return float(scale) if scale.ndim == 0 else scale

    def whole_sigma(self, kind: str, quantity: str, features: np.ndarray, fx_px: ArrayLike | None
                    ) -> np.ndarray:
        """Each row's whole σ of ``kind``'s ``quantity`` at feature rows and focal lengths:
        its own law scaled to fx, and for α the frame's shared offset besides."""
        own = self.fits[kind][quantity].log_sigma(features) * self.fx_scale(fx_px)
        return np.hypot(own, self.shared_alpha_deg) if quantity == "alpha" else own

    def sigma(self, kind: str, d_total: float, alpha_deg: float, pan_deg: float | None,
              fx_px: float | None = None) -> Sigma:
        """The σ pair of one measurement of a ``kind`` image (``pan_deg`` None: the pan
        is not known, and the image is taken as off the axis as the training rows were on
        average; ``fx_px``: the camera's focal length in pixels, None: the training's)."""
        q = self.fits[kind]
        scale = self.fx_scale(fx_px)

        def at(law: LogSigma, low: float, high: float) -> float:
            x = measured_features(d_total, alpha_deg, 0.0 if pan_deg is None else pan_deg)
            if pan_deg is None:
                x[..., 1] = law.mean[1]
            # a law taken far beyond its training rows stays within what any σ must be
            return float(np.clip(float(law(x)) * scale, low, high))

        return Sigma(at(q["alpha"].log_sigma, SIGMA_ALPHA_MIN_DEG, SIGMA_ALPHA_MAX_DEG),
                     at(q["d_rel"].log_sigma, SIGMA_D_REL_MIN, SIGMA_D_REL_MAX))

    def sigmas(self, target: tuple[float, float], beacons: list[tuple[float, float]],
               pan_deg: float | None, fx_px: float | None = None) -> ObjectSigmas:
        """Each observation's σ's: the target's (α, d_total) and each beacon's."""
        return ObjectSigmas(self.sigma("target", target[1], target[0], pan_deg, fx_px),
                            tuple(self.sigma("beacon", d, a, pan_deg, fx_px)
                                  for a, d in beacons), self.shared_alpha_deg)

    def typical_at(self, fx_px: float | None) -> ObjectSigmas:
        """:attr:`typical` for a camera of focal length ``fx_px`` (None: the training's)."""
        t = self.typical
        scale = self.fx_scale(fx_px)
        pair = lambda s: Sigma(s.alpha_deg * scale, s.d_total_rel * scale)  # noqa: E731
        return ObjectSigmas(pair(t.target), tuple(pair(b) for b in t.beacons),
                            t.shared_alpha_deg)

    @property
    def typical(self) -> ObjectSigmas:
        """The typical σ's (RMS over the training rows) per kind, for analyses without
        measurements (Monte Carlo tables, beacon placement)."""
        pair = lambda k: Sigma(self.fits[k]["alpha"].typical_sigma,  # noqa: E731
                               self.fits[k]["d_rel"].typical_sigma)
        return ObjectSigmas(pair("target"), (pair("beacon"),), self.shared_alpha_deg)

    def to_json(self) -> dict:
        """The model file's contents (:func:`sealed` adds their checksum)."""
        out = {"format": FORMAT, "version": VERSION, "units": UNITS, "fx_px": self.fx_px,
               "shared_alpha_deg": self.shared_alpha_deg,
               "sigma_features": list(SIGMA_FEATURES), "bias_features": list(self.bias_features),
               "objects": {k: {q: f.to_json() for q, f in qs.items()}
                           for k, qs in self.fits.items()}}
        if self.provenance:
            out["provenance"] = self.provenance
        return out


def sealed(model: ErrorModel) -> dict:
    """The model file as ``mirrorsim errormodel`` writes it: :meth:`ErrorModel.to_json`
    with the checksum of its contents under ``"sha256"``, so that a model damaged or
    edited since is refused rather than used (a digit changed within range passes every
    other check)."""
    return seal(model.to_json())


def model_from_dict(data: Any, source: str | Path) -> ErrorModel:
    """Validate a parsed model file (raises :class:`ErrorModelError` naming the file and
    the key).  A file that carries a checksum (``"sha256"``: every file mirrorsim writes)
    must match it; a model written by hand carries none and is checked as the rest."""
    r = Reader(source, ErrorModelError)
    if isinstance(data, dict) and "sha256" in data:
        try:
            data = unseal(data, "the model")
        except ValueError:
            raise r.fail("sha256", "the checksum does not match the model's contents: the "
                                   "file was damaged or edited since mirrorsim wrote it (fit "
                                   "it again, or drop the sha256 key to use an edited "
                                   "model)") from None
    top = r.mapping(data, "", ("format", "version", "objects"),
                    ("units", "sigma_features", "bias_features", "provenance", "fx_px",
                     "shared_alpha_deg"))
    if top["format"] != FORMAT or top["version"] != VERSION:
        raise r.fail("version", f"{top['version']!r}: not a version-{VERSION} {FORMAT}; fit it "
                                "again with this mirrorsim (`mirrorsim errormodel DATASET`)")
    if top.get("sigma_features", list(SIGMA_FEATURES)) != list(SIGMA_FEATURES):
        raise r.fail("sigma_features", f"{top['sigma_features']!r}: this mirrorsim computes "
                                       f"{list(SIGMA_FEATURES)}")
    objects = r.mapping(top["objects"], "objects", KINDS)
    fits: dict[str, dict[str, QuantityFit]] = {}
    for kind in KINDS:
        qs = r.mapping(objects[kind], f"objects.{kind}", QUANTITIES)
        fits[kind] = {q: _quantity(r, qs[q], f"objects.{kind}.{q}", q) for q in QUANTITIES}
    bias_features = top.get("bias_features", [])
    if not isinstance(bias_features, list) or not all(isinstance(b, str) for b in bias_features):
        raise r.fail("bias_features", "expected a list of names")
    prov = top.get("provenance")
    fx = top.get("fx_px")
    fx = None if fx is None else r.number(fx, "fx_px", positive=True, high=1e6)
    shared = read_shared_alpha(r, top.get("shared_alpha_deg", 0.0), "shared_alpha_deg")
    return ErrorModel(fits, tuple(bias_features), prov if isinstance(prov, dict) else None, fx,
                      shared)


def _quantity(r: Reader, value: Any, key: str, q: str) -> QuantityFit:
    f = r.mapping(value, key, ("log_sigma", "n", "typical_sigma"),
                  ("gross_errors", "rms", "bias"))
    ls = r.mapping(f["log_sigma"], f"{key}.log_sigma", ("intercept", "weights", "mean", "scale"))
    k = len(SIGMA_FEATURES)
    vec = lambda name: tuple(r.number(v, f"{key}.log_sigma.{name}[{i}]")  # noqa: E731
                             for i, v in enumerate(_list(r, ls[name], f"{key}.log_sigma.{name}",
                                                         k)))
    law = LogSigma(r.number(ls["intercept"], f"{key}.log_sigma.intercept", low=-50, high=50),
                   vec("weights"), vec("mean"), vec("scale"))
    if not all(s > 0 for s in law.scale):
        raise r.fail(f"{key}.log_sigma.scale", f"{list(law.scale)}: scales must be > 0")
    low, high = ((SIGMA_ALPHA_MIN_DEG, SIGMA_ALPHA_MAX_DEG) if q == "alpha"
                 else (SIGMA_D_REL_MIN, SIGMA_D_REL_MAX))
    typical = r.number(f["typical_sigma"], f"{key}.typical_sigma", low=low, high=high)
    bias = f.get("bias", [])
    return QuantityFit(law, int(r.number(f["n"], f"{key}.n", low=0)),
                       int(r.number(f.get("gross_errors", 0), f"{key}.gross_errors", low=0)),
                       r.number(f.get("rms", 0.0), f"{key}.rms", low=0),
                       typical,
                       tuple(r.number(b, f"{key}.bias[{i}]")
                             for i, b in enumerate(_list(r, bias, f"{key}.bias"))))


def _list(r: Reader, value: Any, key: str, length: int | None = None) -> list:
    if not isinstance(value, list) or (length is not None and len(value) != length):
        want = f"a list of {length} numbers" if length is not None else "a list of numbers"
        raise r.fail(key, f"expected {want}")
    return value


def load_error_model(path: str | Path) -> ErrorModel:
    """Read and validate a model file (see :func:`model_from_dict`)."""
    return replace(model_from_dict(read_json(path, ErrorModelError), path), source=str(path))


def load_error_model_or_default(path: str | Path | None = None) -> ErrorModel:
    """The model file at ``path``, or (None) the shipped one."""
    return default_error_model() if path is None else load_error_model(path)


def default_model_path() -> Path:
    """The model shipped with mirrorsim: the ideal bench at the default render settings,
    fitted on the project's own dataset (``make error-model`` regenerates it)."""
    return Path(str(resources.files("mirrorsim") / "data" / DEFAULT_NAME))


def default_error_model() -> ErrorModel:
    """:func:`default_model_path`'s model."""
    return load_error_model(default_model_path())
