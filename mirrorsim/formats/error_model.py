"""The error model file (``mirrorsim errormodel`` writes it; every command that solves
reads it): per object kind (target, beacon) and quantity (α, d_total), a σ that the
experimenter can compute for each measurement from what its frame shows; the domain
the model was fitted on; and, for a model of hand-built benches, the population of
benches it describes (the tolerances of the errors every image of a frame shares).

A measurement's σ is ``tail · exp(w · z)`` with z = [1, standardized features of the
image] (:data:`SIGMA_FEATURES`: its height in pixels, its angle off the optical axis,
the contrast of its edges, the frame's noise and its JPEG compression), all known when
the photograph is measured, never the truth or a bench's imperfection values.  ``tail``
widens the Gaussian fit so that 95 % of the training rows' errors lie within 1.96 σ
(the detector's errors are heavier-tailed than a Gaussian).  The α law is in pixels at
the training frames' median focal length (``fx_px``): σ_α scales as fx_px / fx; the
d_total law needs no such factor, the image's height in pixels already says it.

A bench model's ``tolerances`` are the half-widths of the shared errors its benches
were drawn with (the mount's pan reading, the calibration's distance, the mirror's
curvature, the beacons' believed positions).  The solver estimates each as a nuisance
with the prior they give (:meth:`BenchTolerances.calibration`), so an ellipse holds
them; a user who knows their own bench better states it (``--prior``).

Units, in the file and everywhere in mirrorsim: α errors and σ_α in degrees; d_total
errors and σ_d relative, a fraction of d_total (0.002 = 0.2 %; printed tables show %).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mirrorsim.formats.cache import seal, unseal
from mirrorsim.formats.capture import REFERENCE_DISTANCE
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
from solver.selfcal import PRIOR_MIN, SelfCalibration

FORMAT = "mirrorsim error model"
VERSION = 3
KINDS = ("target", "beacon")
QUANTITIES = ("alpha", "d_rel")
# what σ depends on: what the frame shows of the image, known when it is measured
SIGMA_FEATURES = ("log_height_px", "abs_off_axis_deg", "log_contrast", "log_noise",
                  "jpeg_loss")
FEATURE_WORDS = {"log_height_px": ("image height", "px", math.exp),
                 "abs_off_axis_deg": ("angle off the optical axis", "°", abs),
                 "log_contrast": ("edge contrast", "", math.exp),
                 "log_noise": ("frame noise", "", math.exp),
                 "jpeg_loss": ("JPEG loss (100 − quality)/100", "", float)}
UNITS = {"alpha": "deg", "d_rel": "fraction of d_total (0.002 = 0.2 %)"}
MODEL_KINDS = ("ideal", "bench")
DEFAULT_NAMES = {"ideal": "error_model.json", "bench": "error_model_bench.json"}
DEFAULT_NAME = DEFAULT_NAMES["ideal"]
# the floors of the logged features: a contrast or noise of 0 is "below measurable"
CONTRAST_FLOOR = 1e-3
NOISE_FLOOR = 1e-4
# a scene's facts the model was fitted over (min, max), checked against a scene's
# capture record: the camera's focal length, its height, the pencils' heights, the
# beacons a scene
SCENE_DOMAIN = {"fx_px": "focal length (px)", "camera_height_cm": "camera height (cm)",
                "pencil_height_cm": "pencil height (cm)", "beacons": "beacons a scene"}
# the σ of a uniform draw of half-width h is h/√3
UNIFORM_SD = 1.0 / math.sqrt(3.0)


class ErrorModelError(InputError):
    """A bad error model file."""


def feature_vector(height_px: Any, off_axis_deg: Any, contrast: Any, *, noise: Any,
                   jpeg_quality: Any) -> np.ndarray:
    """:data:`SIGMA_FEATURES` of images (broadcasts; last axis the features): log of the
    image's height (px), |angle off the optical axis| (deg), log of its edges' relative
    contrast, log of the frame's relative noise, and (100 − JPEG quality)/100 (0 for a
    lossless frame, quality 0)."""
    q = np.asarray(jpeg_quality, float)
    cols = np.broadcast_arrays(
        np.log(np.asarray(height_px, float)), np.abs(np.asarray(off_axis_deg, float)),
        np.log(np.maximum(np.asarray(contrast, float), CONTRAST_FLOOR)),
        np.log(np.maximum(np.asarray(noise, float), NOISE_FLOOR)),
        np.where(q > 0, (100.0 - q) / 100.0, 0.0))
    return np.stack(cols, axis=-1)


def off_axis(alpha_deg: Any, pan_deg: Any) -> np.ndarray:
    """An image's bearing off the optical axis (deg, signed), from α and the pan."""
    return (np.asarray(alpha_deg, float) - np.asarray(pan_deg, float) + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class ImageFeatures:
    """What the detector saw of one image, all known when the photograph is measured:
    its measurement, its height in pixels, the relative contrast of its edges, the
    frame's relative noise and the frame's JPEG quality (0: a lossless frame)."""

    alpha_deg: float
    d_total: float
    height_px: float
    contrast: float
    noise: float
    jpeg_quality: int = 0

    def vector(self, pan_deg: float) -> np.ndarray:
        """:func:`feature_vector` of this image for a camera panned to ``pan_deg``."""
        return feature_vector(self.height_px, off_axis(self.alpha_deg, pan_deg),
                              self.contrast, noise=self.noise, jpeg_quality=self.jpeg_quality)

    def to_json(self) -> dict:
        """As a report's entry (:meth:`from_json` reads it back)."""
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> ImageFeatures:
        """Inverse of :meth:`to_json` (a feature not measured is null there, NaN here)."""
        return cls(**{k: math.nan if v is None else v for k, v in d.items()})


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
    """One kind's one quantity: its σ law and its tail factor, how many rows made it and
    how many gross errors were left out of the law's fit, the rows' RMS error, and the
    diagnostic bias fit (linear in the model's ``bias_features``, which may include
    truth and bench values: it explains the errors, it does not predict a σ)."""

    log_sigma: LogSigma
    n: int
    gross_errors: int
    rms: float
    typical_sigma: float  # RMS over the training rows of the predicted σ (tail included)
    bias: tuple[float, ...] = ()
    # the factor on the Gaussian law's σ that puts 95 % of the training rows' errors
    # within 1.96 σ (≥ 1): the tails a Gaussian fit does not see
    tail: float = 1.0

    def sigma(self, features: np.ndarray) -> np.ndarray:
        """The σ of images with these feature rows (at the training's focal length)."""
        return self.tail * self.log_sigma(features)

    def to_json(self) -> dict:
        """The file's entry."""
        return {"log_sigma": self.log_sigma.to_json(), "tail": self.tail, "n": self.n,
                "gross_errors": self.gross_errors, "rms": self.rms,
                "typical_sigma": self.typical_sigma, "bias": list(self.bias)}


@dataclass(frozen=True)
class BenchTolerances:
    """The population of benches a model describes: the half-width of each error that
    every image of a frame shares, drawn uniformly (0: none; an ideal bench's are all
    0).  Each becomes a nuisance the solver estimates with a prior of σ = half-width/√3.

    Attributes
    ----------
    pan_deg : float
        The mount's pan reading (``camera.pan_error``).
    calibration_cm : float
        The calibration reference's distance (``calibration.distance_error``): every
        d_total scaled by about 1 − e/100.
    curvature_per_cm : float
        The mirror's curvature 1/R (``mirror.curvature_radius``).
    beacon_position_cm : float
        Each beacon's believed position, per axis (``known_position``).
    """

    pan_deg: float = 0.0
    calibration_cm: float = 0.0
    curvature_per_cm: float = 0.0
    beacon_position_cm: float = 0.0

    @property
    def ideal(self) -> bool:
        """Whether no shared error is drawn."""
        return not any((self.pan_deg, self.calibration_cm, self.curvature_per_cm,
                        self.beacon_position_cm))

    def priors(self) -> dict[str, float]:
        """Each shared error's prior σ as the solver's nuisance (pan in degrees, scale as
        a fraction, power in 1/cm); only those drawn."""
        out = {"pan": self.pan_deg * UNIFORM_SD,
               "scale": self.calibration_cm * UNIFORM_SD / REFERENCE_DISTANCE,
               "power": self.curvature_per_cm * UNIFORM_SD}
        return {n: max(s, PRIOR_MIN[n]) for n, s in out.items() if s > 0}

    def calibration(self) -> SelfCalibration:
        """The nuisances a solve of such a bench estimates, each with its prior, and the
        beacons' position σ."""
        priors = self.priors()
        return SelfCalibration(tuple(priors), self.beacon_position_cm * UNIFORM_SD, priors)

    def to_json(self) -> dict:
        """The file's ``tolerances`` entry."""
        return {"pan_deg": self.pan_deg, "calibration_cm": self.calibration_cm,
                "curvature_per_cm": self.curvature_per_cm,
                "beacon_position_cm": self.beacon_position_cm}


@dataclass(frozen=True)
class Domain:
    """What a model was fitted on: each kind's σ features' (min, max) over its training
    rows, the scenes' facts (:data:`SCENE_DOMAIN`), and the bench imperfections' ranges
    by scene-file key path (a spec's ``bench`` block; empty for an ideal bench)."""

    features: dict[str, dict[str, tuple[float, float]]]  # kind → feature → (lo, hi)
    scene: dict[str, tuple[float, float]]
    bench: dict[str, tuple[float, float]] = field(default_factory=dict)

    def to_json(self) -> dict:
        """The file's ``domain`` entry."""
        return {"features": {k: {f: list(v) for f, v in fs.items()}
                             for k, fs in self.features.items()},
                "scene": {k: list(v) for k, v in self.scene.items()},
                "bench": {k: list(v) for k, v in self.bench.items()}}

    def image_warnings(self, who: str, kind: str, x: np.ndarray) -> list[str]:
        """One line per σ feature of an image (``x``: its feature vector) outside this
        kind's domain, naming the image (``who``) and the range."""
        out = []
        for name, value in zip(SIGMA_FEATURES, x, strict=True):
            lo, hi = self.features[kind][name]
            if not lo <= value <= hi:
                words, unit, show = FEATURE_WORDS[name]
                out.append(f"{who}'s {words} is {_fmt(show(value))}{unit}, the model was "
                           f"fitted on {_fmt(show(lo))}–{_fmt(show(hi))}{unit}; its σ's are "
                           "extrapolated")
        return out

    def scene_warnings(self, facts: dict[str, float | tuple[float, ...]]) -> list[str]:
        """One line per fact of a scene (a value, or several: every pencil's height)
        outside the scene domain, naming its first value outside."""
        out = []
        for key, values in facts.items():
            if key not in self.scene:
                continue
            lo, hi = self.scene[key]
            outside = [v for v in np.atleast_1d(values) if not lo <= v <= hi]
            if outside:
                out.append(f"the scene's {SCENE_DOMAIN[key]} is {_fmt(outside[0])}, the model "
                           f"was fitted on {_fmt(lo)}–{_fmt(hi)}; its σ's are extrapolated")
        return out

    def bench_warnings(self, values: dict[str, float]) -> list[str]:
        """One line per bench imperfection of a scene (key path → the value its first-
        order size is judged by) beyond the model's bench ranges, or absent from them."""
        out = []
        for key, value in values.items():
            lo, hi = self.bench.get(key, (0.0, 0.0))
            if not lo - 1e-12 <= value <= hi + 1e-12:
                out.append(f"{key} {_fmt(value)} lies outside the model's benches "
                           f"({_fmt(lo)} to {_fmt(hi)}); its σ's do not cover it")
        return out


def _fmt(x: float) -> str:
    return f"{x:.3g}"


@dataclass(frozen=True)
class ErrorModel:
    """The fitted model: a :class:`QuantityFit` per kind and quantity, its domain and,
    for a bench model, the population of benches it describes."""

    fits: dict[str, dict[str, QuantityFit]]  # "target"/"beacon" → "alpha"/"d_rel" → fit
    domain: Domain
    tolerances: BenchTolerances = field(default_factory=BenchTolerances)
    bias_features: tuple[str, ...] = ()
    provenance: dict | None = None  # how it was made (dataset, seed, n, command)
    fx_px: float | None = None  # the training frames' median focal length (px)
    # σ (deg) of an α offset every image of a frame shares beyond what the tolerances
    # hold (found in the training rows' pairs of target and beacon α errors)
    shared_alpha_deg: float = 0.0
    # the file it was read from (None: made in memory), for records that name it (a
    # dataset's card); not part of the model, so not in its file, digest or equality
    source: str | None = field(default=None, compare=False)

    @property
    def kind(self) -> str:
        """``ideal`` or ``bench``: whether it describes benches with imperfections."""
        return "bench" if self.domain.bench or not self.tolerances.ideal else "ideal"

    def name(self) -> str:
        """How a table names the model: the shipped one by its kind, else its file."""
        words = {"ideal": "ideal-bench model", "bench": "bench model"}[self.kind]
        if self.source and Path(self.source).name in DEFAULT_NAMES.values() and \
                Path(self.source).parent == default_model_path().parent:
            return f"the shipped {words}"
        return f"the {words} {self.source or '(made in memory)'}"

    def fx_scale(self, fx_px: ArrayLike | None) -> float | np.ndarray:
        """The factor on σ_α for frames of focal length ``fx_px`` (broadcasts; 1 where it
        or the model's is unknown): pixel errors scale as fx_px(model) / fx."""
        fx = np.asarray(np.nan if fx_px is None else fx_px, float)
        ok = np.isfinite(fx) & (fx > 0) & bool(self.fx_px)
        scale = np.where(ok, (self.fx_px or 1.0) / np.where(ok, fx, 1.0), 1.0)
        return float(scale) if scale.ndim == 0 else scale

    def own_sigma(self, kind: str, quantity: str, features: np.ndarray,
                  *, fx_px: ArrayLike | None) -> np.ndarray:
        """Each image's own σ (the frame's shared errors apart) at feature rows and focal
        lengths, clipped to what any σ may be."""
        fit = self.fits[kind][quantity]
        x = np.asarray(features, float)
        if not np.isfinite(x).all():  # a feature the frame could not show: as on average
            x = np.where(np.isfinite(x), x, np.asarray(fit.log_sigma.mean))
        s = fit.sigma(x)
        if quantity == "alpha":
            return np.clip(s * self.fx_scale(fx_px), SIGMA_ALPHA_MIN_DEG, SIGMA_ALPHA_MAX_DEG)
        return np.clip(s, SIGMA_D_REL_MIN, SIGMA_D_REL_MAX)

    def whole_sigma(self, kind: str, quantity: str, features: np.ndarray,
                    *, fx_px: ArrayLike | None) -> np.ndarray:
        """:meth:`own_sigma`, and for α the frame's shared offset besides."""
        own = self.own_sigma(kind, quantity, features, fx_px=fx_px)
        return np.hypot(own, self.shared_alpha_deg) if quantity == "alpha" else own

    def sigma(self, kind: str, image: ImageFeatures, pan_deg: float,
              *, fx_px: float | None = None) -> Sigma:
        """The σ pair of one ``kind`` image (``fx_px``: the camera's focal length, None:
        the training's)."""
        x = image.vector(pan_deg)
        return Sigma(float(self.own_sigma(kind, "alpha", x, fx_px=fx_px)),
                     float(self.own_sigma(kind, "d_rel", x, fx_px=fx_px)))

    def sigmas(self, target: ImageFeatures, beacons: list[ImageFeatures], pan_deg: float,
               *, fx_px: float | None = None) -> ObjectSigmas:
        """Each observation's σ's: the target's and each beacon's."""
        return ObjectSigmas(self.sigma("target", target, pan_deg, fx_px=fx_px),
                            tuple(self.sigma("beacon", b, pan_deg, fx_px=fx_px) for b in beacons),
                            self.shared_alpha_deg)

    def domain_warnings(self, target: ImageFeatures, beacons: list[ImageFeatures],
                        pan_deg: float, *, scene: dict[str, Any] | None = None,
                        bench: dict[str, float] | None = None) -> list[str]:
        """Every way these images, the scene's facts (:data:`SCENE_DOMAIN`) and its
        bench imperfections lie outside the model's domain, one line each."""
        out = self.domain.scene_warnings(scene or {})
        out += self.domain.image_warnings("the target", "target", target.vector(pan_deg))
        for i, b in enumerate(beacons):
            out += self.domain.image_warnings(f"beacon {i}", "beacon", b.vector(pan_deg))
        if bench is not None and self.kind == "bench":
            out += self.domain.bench_warnings(bench)
        return out

    def typical_at(self, fx_px: float | None) -> ObjectSigmas:
        """:attr:`typical` for a camera of focal length ``fx_px`` (None: the training's)."""
        t = self.typical
        scale = self.fx_scale(fx_px)
        pair = lambda s: Sigma(s.alpha_deg * scale, s.d_total_rel)  # noqa: E731
        return ObjectSigmas(pair(t.target), tuple(pair(b) for b in t.beacons),
                            t.shared_alpha_deg)

    def typical_whole(self, fx_px: float | None) -> ObjectSigmas:
        """:meth:`typical_at` with every shared error folded into each image's σ as if
        independent: the shared α offset and the tolerances' pan into σ_α, their range
        scale into σ_d (for analyses that take independent errors: conservative)."""
        t = self.typical_at(fx_px).independent()
        priors = self.tolerances.priors()
        pan, scale = priors.get("pan", 0.0), priors.get("scale", 0.0)
        whole = lambda s: Sigma(float(np.hypot(s.alpha_deg, pan)),  # noqa: E731
                                float(np.hypot(s.d_total_rel, scale)))
        return ObjectSigmas(whole(t.target), tuple(whole(b) for b in t.beacons))

    @property
    def typical(self) -> ObjectSigmas:
        """The typical σ's (RMS over the training rows) per kind, for analyses without
        measurements (Monte Carlo tables, beacon placement)."""
        pair = lambda k: Sigma(self.fits[k]["alpha"].typical_sigma,  # noqa: E731
                               self.fits[k]["d_rel"].typical_sigma)
        return ObjectSigmas(pair("target"), (pair("beacon"),), self.shared_alpha_deg)

    def to_json(self) -> dict:
        """The model file's contents (:func:`sealed` adds their checksum)."""
        out = {"format": FORMAT, "version": VERSION, "kind": self.kind, "units": UNITS,
               "fx_px": self.fx_px, "shared_alpha_deg": self.shared_alpha_deg,
               "sigma_features": list(SIGMA_FEATURES),
               "bias_features": list(self.bias_features),
               "domain": self.domain.to_json(), "tolerances": self.tolerances.to_json(),
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
                     "shared_alpha_deg", "kind"))
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
    model = ErrorModel(fits, _domain(r, top["domain"]), _tolerances(r, top["tolerances"]),
                       tuple(bias_features), prov if isinstance(prov, dict) else None, fx,
                       shared)
    _check_consistent(r, model)
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
    f = r.mapping(value, key, ("log_sigma", "n", "typical_sigma", "tail"),
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
    low, high = ((SIGMA_ALPHA_MIN_DEG, SIGMA_ALPHA_MAX_DEG) if q == "alpha"
                 else (SIGMA_D_REL_MIN, SIGMA_D_REL_MAX))
    typical = r.number(f["typical_sigma"], f"{key}.typical_sigma", low=low, high=high)
    bias = f.get("bias", [])
    return QuantityFit(law, int(r.number(f["n"], f"{key}.n", low=0)),
                       int(r.number(f.get("gross_errors", 0), f"{key}.gross_errors", low=0)),
                       r.number(f.get("rms", 0.0), f"{key}.rms", low=0),
                       typical,
                       tuple(r.number(b, f"{key}.bias[{i}]")
                             for i, b in enumerate(_list(r, bias, f"{key}.bias"))),
                       r.number(f["tail"], f"{key}.tail", low=1.0, high=100.0))


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


def default_model_path(kind: str = "ideal") -> Path:
    """A model shipped with mirrorsim: ``ideal`` (benches without imperfections) or
    ``bench`` (hand-built benches, docs/reliability.md), each fitted on the project's
    own datasets across the scene format's domain (``make error-model``)."""
    if kind not in DEFAULT_NAMES:
        raise ValueError(f"kind {kind!r}: choose from {', '.join(DEFAULT_NAMES)}")
    return Path(str(resources.files("mirrorsim") / "data" / DEFAULT_NAMES[kind]))


def default_error_model(kind: str = "ideal") -> ErrorModel:
    """:func:`default_model_path`'s model."""
    return load_error_model(default_model_path(kind))
