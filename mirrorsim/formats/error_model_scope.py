"""Where an error model holds: the domain it was fitted on (and the warnings a scene
outside it gets), and the population of benches it describes (each shared error a
nuisance with its prior)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mirrorsim.formats.capture import REFERENCE_DISTANCE
from solver.selfcal import PRIOR_MIN, SelfCalibration

# what σ depends on: what the frame shows of the image, known when it is measured
SIGMA_FEATURES = ("log_height_px", "abs_off_axis_deg", "log_contrast", "log_noise",
                  "jpeg_loss")
# how a warning names each feature: words, unit, and the feature back in its units
FEATURE_WORDS = {"log_height_px": ("image height", "px", math.exp),
                 "abs_off_axis_deg": ("angle off the optical axis", "°", abs),
                 "log_contrast": ("edge contrast", "", math.exp),
                 "log_noise": ("frame noise", "", math.exp),
                 "jpeg_loss": ("JPEG loss (100 − quality)/100", "", float)}

# a scene's facts the model was fitted over (min, max), checked against a scene's
# capture record: the camera's focal length, its height, the pencils' heights, the
# beacons a scene
SCENE_DOMAIN = {"fx_px": "focal length (px)", "camera_height_cm": "camera height (cm)",
                "pencil_height_cm": "pencil height (cm)", "beacons": "beacons a scene"}


# the σ of a uniform draw of half-width h is h/√3
UNIFORM_SD = 1.0 / math.sqrt(3.0)


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
