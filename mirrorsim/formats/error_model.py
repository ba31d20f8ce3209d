"""The error model file (``mirrorsim errormodel`` writes it; every command that solves
reads it): per object kind (target, beacon) and quantity (α, d_total), a σ that the
experimenter can compute for each measurement from what its frame shows; the domain
the model was fitted on; and, for a model of hand-built benches, the population of
benches it describes (the tolerances of the errors every image of a frame shares).

A measurement's σ is ``exp(w · z)`` with z = [1, standardized features of the image]
(:data:`SIGMA_FEATURES`: its height in pixels, its angle off the optical axis, the
contrast of its edges, the frame's noise and its JPEG compression), all known when the
photograph is measured, never the truth or a bench's imperfection values: the scale of
a Student-t of ``dof`` degrees of freedom fitted with it (the detector's errors are
heavier-tailed than a Gaussian's; a Gaussian's σ, their RMS, is wide for most of them).
``tail`` says how far 95 % of the training rows' errors reach: within 1.96·tail σ.
The target's :class:`~solver.measurements.Tail` then says where the solve's ellipses
are drawn.  The α law is in pixels at
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
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mirrorsim.formats.error_model_scope import SIGMA_FEATURES, BenchTolerances, Domain
from solver.errors import InputError
from solver.measurements import (
    GAUSSIAN,
    SIGMA_ALPHA_MAX_DEG,
    SIGMA_ALPHA_MIN_DEG,
    SIGMA_D_REL_MAX,
    SIGMA_D_REL_MIN,
    ObjectSigmas,
    Sigma,
    Tail,
)

FORMAT = "mirrorsim error model"
VERSION = 4
KINDS = ("target", "beacon")
# the bounds of a σ law's degrees of freedom: from a Cauchy's to a Gaussian's
SIGMA_DOF_RANGE = (1.0, 1e4)
QUANTITIES = ("alpha", "d_rel")
# a model fitted on a 3-D dataset's rows has, besides, each image's elevation (deg): it
# then weighs the 3-D solve with its own laws (:attr:`ErrorModel.three_d`)
ELEVATION = "elevation"
ANGLES = ("alpha", ELEVATION)  # in degrees, their pixel errors scaling as 1/fx
UNITS = {"alpha": "deg", "d_rel": "fraction of d_total (0.002 = 0.2 %)", ELEVATION: "deg"}
DEFAULT_NAMES = {"ideal": "error_model.json", "bench": "error_model_bench.json"}
# the floors of the logged features: a contrast or noise of 0 is "below measurable"
CONTRAST_FLOOR = 1e-3
NOISE_FLOOR = 1e-4


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
    typical_sigma: float  # RMS over the training rows (gross errors apart) of the σ
    bias: tuple[float, ...] = ()
    # how far 95 % of the training rows' errors reach: within 1.96·tail σ (≥ 1; a
    # Student-t's of ``dof``: 1.6 at ν 3, 1 for a Gaussian).  Said, not applied: the
    # target's tail widens the ellipse
    tail: float = 1.0
    dof: float = math.inf  # the Student-t's degrees of freedom fitted with the law

    def sigma(self, features: np.ndarray) -> np.ndarray:
        """The σ of images with these feature rows (at the training's focal length)."""
        return self.log_sigma(features)

    def to_json(self) -> dict:
        """The file's entry (an infinite dof as null)."""
        return {"log_sigma": self.log_sigma.to_json(), "tail": self.tail,
                "dof": None if math.isinf(self.dof) else self.dof, "n": self.n,
                "gross_errors": self.gross_errors, "rms": self.rms,
                "typical_sigma": self.typical_sigma, "bias": list(self.bias)}


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
    # how far the truth lies from an estimate in σ's of the covariance these σ's give
    # (fitted on the training rows solved again: the detector's errors are heavier-
    # tailed than a Gaussian's), so that a 95 % ellipse holds 95 % (a file without it:
    # the σ's at their word)
    tail: Tail = GAUSSIAN
    # a 3-D model's: how much wider than its σ's make it the 3-D solve's covariance is
    # taken, so that 95 % of its training rows' truths lie in the 95 % ellipsoid (the
    # 95th percentile of their Mahalanobis distances over χ₃'s radius, ≥ 1)
    ellipsoid_scale: float = 1.0
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
        if quantity in ANGLES:
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
                            self.shared_alpha_deg, self.tail)

    @property
    def three_d(self) -> bool:
        """Whether it was fitted on a 3-D dataset's rows: an elevation law for each kind,
        its α and d_total laws fitted on 3-D frames' readings."""
        return all(ELEVATION in qs for qs in self.fits.values())

    def gaussian_elevations(self, images: tuple[ImageFeatures, ...], pan_deg: float, *,
                            fx_px: float | None = None) -> tuple[float, ...] | None:
        """Each image's elevation σ (deg; ``images``: the target's, then each beacon's) as
        a Gaussian's (its law's Student-t scale times its tail, as :meth:`gaussian`);
        None for a model without elevation laws (not :attr:`three_d`)."""
        if not self.three_d:
            return None
        return tuple(float(self.own_sigma(kind, ELEVATION, im.vector(pan_deg), fx_px=fx_px)
                           * self.fits[kind][ELEVATION].tail)
                     for kind, im in zip(["target"] + ["beacon"] * (len(images) - 1), images,
                                         strict=True))

    @property
    def typical_elevations(self) -> tuple[float, float] | None:
        """A 3-D model's typical elevation σ (the target's, a beacon's) as a Gaussian's,
        as :attr:`typical`'s (None: not :attr:`three_d`)."""
        if not self.three_d:
            return None
        return tuple(self.fits[k][ELEVATION].typical_sigma * self.fits[k][ELEVATION].tail
                     for k in KINDS)

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

    def gaussian(self, sigma: ObjectSigmas) -> ObjectSigmas:
        """These σ's (the Student-t scales :meth:`sigmas` gives) as a Gaussian's that holds
        95 % of the training errors within 1.96 σ: each times its quantity's ``tail``.
        For whatever draws or solves with Gaussian errors and no tail (the 3-D solve,
        Monte Carlo tables, beacon placement, the particle filter): at the t-scales a
        Gaussian's regions would hold far fewer than they say."""
        def wide(kind: str, s: Sigma) -> Sigma:
            return Sigma(s.alpha_deg * self.fits[kind]["alpha"].tail,
                         s.d_total_rel * self.fits[kind]["d_rel"].tail)
        return ObjectSigmas(wide("target", sigma.target),
                            tuple(wide("beacon", b) for b in sigma.beacons),
                            sigma.shared_alpha_deg)

    @property
    def typical(self) -> ObjectSigmas:
        """The typical σ's (RMS over the training rows) per kind, as a Gaussian's
        (:meth:`gaussian`), for analyses without measurements (Monte Carlo tables, beacon
        placement, the particle filter, ``solve`` of measurements without σ's)."""
        pair = lambda k: Sigma(self.fits[k]["alpha"].typical_sigma,  # noqa: E731
                               self.fits[k]["d_rel"].typical_sigma)
        return self.gaussian(ObjectSigmas(pair("target"), (pair("beacon"),),
                                          self.shared_alpha_deg))

    def to_json(self) -> dict:
        """The model file's contents (:func:`sealed` adds their checksum)."""
        quantities = (*QUANTITIES, *((ELEVATION,) if self.three_d else ()))
        out = {"format": FORMAT, "version": VERSION, "kind": self.kind,
               "units": {q: UNITS[q] for q in quantities},
               "fx_px": self.fx_px, "shared_alpha_deg": self.shared_alpha_deg,
               "target_tail": self.tail.to_json(),
               "sigma_features": list(SIGMA_FEATURES),
               "bias_features": list(self.bias_features),
               "domain": self.domain.to_json(), "tolerances": self.tolerances.to_json(),
               "objects": {k: {q: f.to_json() for q, f in qs.items()}
                           for k, qs in self.fits.items()}}
        if self.three_d:
            out["ellipsoid_scale"] = self.ellipsoid_scale
        if self.provenance:
            out["provenance"] = self.provenance
        return out


def default_model_path(kind: str = "ideal") -> Path:
    """A model shipped with mirrorsim: ``ideal`` (benches without imperfections) or
    ``bench`` (hand-built benches, docs/reliability.md), each fitted on the project's
    own datasets across the scene format's domain (``make error-model``)."""
    if kind not in DEFAULT_NAMES:
        raise ValueError(f"kind {kind!r}: choose from {', '.join(DEFAULT_NAMES)}")
    return Path(str(resources.files("mirrorsim") / "data" / DEFAULT_NAMES[kind]))
