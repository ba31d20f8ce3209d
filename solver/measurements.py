"""The solver's inputs: each beacon's measurement, the σ's that weigh them, and all of
them as one value (reading them from a file is :mod:`mirrorsim.formats.measurements`')."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from solver.arguments import check_fields
from solver.errors import SolverError


@dataclass(frozen=True)
class BeaconMeasurement:
    """A beacon's known position and its image's measured α and d_total."""

    position: tuple[float, float]
    alpha_deg: float
    d_total: float

    def __post_init__(self) -> None:
        check_fields(self)  # finite numbers, made plain (BadParameter naming the field)


@dataclass(frozen=True)
class Tail:
    """How far the truth lies from an estimate in its covariance's σ's: that distance
    over ``scale`` follows the radial law of a 2-D Student-t of ``dof`` degrees of freedom
    (∞: a Gaussian's, √χ²₂).  The default, scale 1 and dof ∞, takes the σ's at their
    word.  An error model fits its own on the rows it was fitted on (the detector's
    errors are heavier-tailed than a Gaussian's, and its σ's cannot foresee every
    fault), and a level's ellipse is drawn at :meth:`radius`."""

    scale: float = 1.0
    dof: float = math.inf

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0 and self.dof > 0):
            raise SolverError(f"a tail needs a finite scale > 0 and dof > 0, got scale "
                              f"{self.scale!r}, dof {self.dof!r}")

    @property
    def gaussian(self) -> bool:
        """Whether the σ's are taken at their word (scale 1, dof ∞)."""
        return self.scale == 1.0 and math.isinf(self.dof)

    def radius(self, level: float) -> float:
        """The Mahalanobis radius of the ``level`` region: scale·√(2 F₂,ν⁻¹(level)), in
        closed form √(ν((1 − level)^(−2/ν) − 1)); √(−2 ln(1 − level)) as ν → ∞."""
        if math.isinf(self.dof):
            return self.scale * math.sqrt(-2.0 * math.log1p(-level))
        nu = self.dof
        return self.scale * math.sqrt(nu * math.expm1(-2.0 / nu * math.log1p(-level)))

    def density(self, distance: ArrayLike) -> np.ndarray:
        """The probability density of the distance m (broadcasts): with s = m/scale,
        s (1 + s²/ν)^−(ν/2+1) / scale; s e^(−s²/2) / scale as ν → ∞."""
        s = np.asarray(distance, float) / self.scale
        if math.isinf(self.dof):
            return s * np.exp(-s * s / 2.0) / self.scale
        return s * (1.0 + s * s / self.dof) ** -(self.dof / 2.0 + 1.0) / self.scale

    def to_json(self) -> dict:
        """As files keep it (an infinite dof as null)."""
        return {"scale": self.scale, "dof": None if math.isinf(self.dof) else self.dof}

    @classmethod
    def from_json(cls, d: dict | None) -> Tail:
        """Inverse of :meth:`to_json` (None or a missing dof: a Gaussian's)."""
        if not d:
            return cls()
        dof = d.get("dof")
        return cls(float(d.get("scale", 1.0)), math.inf if dof is None else float(dof))


GAUSSIAN = Tail()  # the σ's at their word


@dataclass(frozen=True)
class Sigma:
    """One measurement's standard deviations: α in degrees, d_total relative (a
    fraction: 0.002 = 0.2 %)."""

    alpha_deg: float = 0.01
    d_total_rel: float = 0.002


@dataclass(frozen=True)
class ObjectSigmas:
    """σ's per observation: the target's and each beacon observation's (a single beacon
    σ serves every beacon observation).  The target's image and a pencil's are measured
    with different accuracy, so one pair for both would over- or under-weight one."""

    target: Sigma
    beacons: tuple[Sigma, ...]
    # σ (deg) of an α offset that every image of one frame shares (the mount's pan
    # reading): on a bench it is most of each α's error, and counted as independent
    # per image it would misplace the ellipse (errors that move every α alike largely
    # cancel in the target); the α σ's above are then each image's own part
    shared_alpha_deg: float = 0.0
    # how the truth's distance from an estimate made with these σ's is spread (their
    # error model's): where a level's ellipse is drawn
    tail: Tail = GAUSSIAN

    @classmethod
    def same(cls, sigma: Sigma) -> ObjectSigmas:
        """One pair for every observation."""
        return cls(sigma, (sigma,))

    def alpha_covariance(self, sa: np.ndarray) -> np.ndarray:
        """The α's covariance diag(sa²) + shared²·11ᵀ (sa: each α's own σ)."""
        return np.diag(sa**2) + self.shared_alpha_deg**2

    def alpha_whitener(self, sa: np.ndarray) -> np.ndarray:
        """L⁻¹ for :meth:`alpha_covariance` = L Lᵀ: whitened residuals L⁻¹ (α − α_meas)
        are independent with unit variance (the Cramér–Rao bound's information)."""
        return np.linalg.inv(np.linalg.cholesky(self.alpha_covariance(sa)))

    def independent(self) -> ObjectSigmas:
        """The same σ's with the shared α offset folded into each α (as if independent:
        for analyses that take independent errors, a conservative choice)."""
        if not self.shared_alpha_deg:
            return self
        whole = lambda s: Sigma(float(np.hypot(s.alpha_deg, self.shared_alpha_deg)),  # noqa: E731
                                s.d_total_rel)
        return ObjectSigmas(whole(self.target), tuple(whole(b) for b in self.beacons),
                            tail=self.tail)

    def describe(self) -> str:
        """The σ's in words: α in degrees, d_total in % of d_total."""
        pair = lambda s: f"{s.alpha_deg:.3g}°, {100 * s.d_total_rel:.3g} %"  # noqa: E731
        shared = (f"; an α offset shared by every image, σ {self.shared_alpha_deg:.3g}°"
                  if self.shared_alpha_deg else "")
        if self.beacons == (self.target,):
            return f"σ ({pair(self.target)}){shared}"
        bs = "; ".join(pair(b) for b in dict.fromkeys(self.beacons))
        return f"σ target ({pair(self.target)}), beacon ({bs}){shared}"

    def arrays(self, n_beacons: int, n_targets: int) -> tuple[np.ndarray, np.ndarray]:
        """σ_α (deg) and relative σ_d of each observation, beacons first then targets
        (the order of the solver's residuals)."""
        if len(self.beacons) not in (1, n_beacons):
            raise SolverError(f"{len(self.beacons)} beacon σ's for {n_beacons} beacon "
                              "observations: give one, or one per observation")
        bs = self.beacons * n_beacons if len(self.beacons) == 1 else self.beacons
        every = [*bs, *([self.target] * n_targets)]
        sa = np.array([s.alpha_deg for s in every], float)
        sd = np.array([s.d_total_rel for s in every], float)
        shared = self.shared_alpha_deg
        if not (np.all(sa >= SIGMA_ALPHA_MIN_DEG) and np.all(sa <= SIGMA_ALPHA_MAX_DEG)
                and np.all(sd >= SIGMA_D_REL_MIN) and np.all(sd <= SIGMA_D_REL_MAX)
                and (shared == 0 or SIGMA_ALPHA_MIN_DEG <= shared <= SIGMA_ALPHA_MAX_DEG)):
            raise SolverError(
                f"each σ_α must be within [{SIGMA_ALPHA_MIN_DEG:g}, {SIGMA_ALPHA_MAX_DEG:g}]° "
                f"(the shared one 0 or within them) and each σ_d within "
                f"[{SIGMA_D_REL_MIN:g}, {SIGMA_D_REL_MAX:g}] of d_total; got σ_α "
                f"{', '.join(f'{a:.3g}' for a in sa)}, σ_d "
                f"{', '.join(f'{d:.3g}' for d in sd)}, shared {shared:.3g}")
        return sa, sd


def as_object_sigmas(sigma: Sigma | ObjectSigmas) -> ObjectSigmas:
    """Either form of σ's as :class:`ObjectSigmas` (anything else refused in one line)."""
    if isinstance(sigma, ObjectSigmas):
        return sigma
    if isinstance(sigma, Sigma):
        return ObjectSigmas.same(sigma)
    raise SolverError(f"sigma must be a Sigma or ObjectSigmas, e.g. Sigma(0.01, 0.002), "
                      f"got {type(sigma).__name__} {sigma!r}")


# σ's beyond these are no measurement: a bearing known to ±45° or a distance to ±100 %
SIGMA_ALPHA_MAX_DEG = 45.0
SIGMA_D_REL_MAX = 1.0
# nor below these: a bearing to 1e-6° (3e-5 px on these cameras) or a distance to a
# millionth of itself; the solver weighs each residual by 1/σ, and a σ of 1e-320 made
# every weighted residual infinite (a crash, not an answer)
SIGMA_ALPHA_MIN_DEG = 1e-6
SIGMA_D_REL_MIN = 1e-6
# a d_total beyond these is no bench's (cm): a path a kilometre long, or a tenth of a
# millimetre; 1e300 overflowed the solver's arithmetic
D_TOTAL_RANGE_CM = (0.01, 1e5)


def is_number(x: object) -> bool:
    """A real number (numpy's too, a 0-d array of one as well), not a bool: what every
    measured value and σ must be."""
    if isinstance(x, np.ndarray) and x.ndim == 0:
        x = x[()]
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool)


def check_measurements(observer: ArrayLike, beacons: list[BeaconMeasurement],
                       targets: list[tuple[float, float]]) -> None:
    """Refuse what no solve can use: no beacon or target, a number that is not finite,
    or a d_total outside :data:`D_TOTAL_RANGE_CM` (the file reader says so naming the
    key; this is the same rule for a caller of the library)."""
    if not beacons or not targets:
        raise SolverError("give at least one beacon and one target observation")
    for i, b in enumerate(beacons):  # a tuple failed as an AttributeError deep in the solve
        if not isinstance(b, BeaconMeasurement):
            raise SolverError(f"beacons[{i}] must be a BeaconMeasurement(position, alpha_deg, "
                              f"d_total), not {type(b).__name__}")
    for i, t in enumerate(targets):
        if np.shape(t) != (2,):
            raise SolverError(f"targets[{i}] must be a pair (alpha_deg, d_total), got {t!r}")
    lo, hi = D_TOTAL_RANGE_CM
    values = [("observer", v) for v in np.ravel(np.asarray(observer, float))]
    for i, b in enumerate(beacons):
        values += [(f"beacons[{i}].position", v) for v in np.ravel(np.asarray(b.position,
                                                                               float))]
        values += [(f"beacons[{i}].alpha_deg", b.alpha_deg), (f"beacons[{i}].d_total",
                                                               b.d_total)]
    for i, (a, d) in enumerate(targets):
        values += [(f"targets[{i}].alpha_deg", a), (f"targets[{i}].d_total", d)]
    for name, v in values:
        if not is_number(v):  # a string, None: a TypeError deep in numpy otherwise
            raise SolverError(f"{name} is {v!r}: every measurement must be a finite number")
        if not np.isfinite(v):
            raise SolverError(f"{name} is {v}: every measurement must be a finite number")
        if name.endswith("d_total") and not lo <= v <= hi:
            raise SolverError(f"{name} {v:g} cm is outside {lo:g}..{hi:g} cm")
    if np.asarray(observer, float).shape != (2,):
        raise SolverError(f"observer must be (x, y), got {observer!r}")


@dataclass(frozen=True)
class Measurements:
    """The solver's inputs: observer, target observations, beacons, optional σ's per
    observation."""

    observer: tuple[float, float]
    targets: list[tuple[float, float]]  # (alpha_deg, d_total) observations of the target
    beacons: list[BeaconMeasurement]
    sigma: ObjectSigmas | None = None
    # the optical axis's bearing (deg), where known: an error model's σ's depend on how
    # far off the axis each image is
    observer_pan_deg: float | None = None

    def to_json(self) -> dict:
        """The measurements document (one target observation as an object, several as a
        list)."""
        t = [{"alpha_deg": a, "d_total": d} for a, d in self.targets]
        out = {"observer": list(self.observer),
               "target": t[0] if len(t) == 1 else t,
               "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                            "d_total": b.d_total} for b in self.beacons]}
        if self.observer_pan_deg is not None:
            out["observer_pan_deg"] = self.observer_pan_deg
        if self.sigma is not None:
            out["sigma"] = sigma_json(self.sigma)
        return out


def sigma_json(sigma: ObjectSigmas) -> dict:
    """A ``sigma`` block: one pair where every observation shares it, else the target's
    and the beacons' (d_total_rel a fraction: 0.002 = 0.2 %)."""
    pair = lambda s: {"alpha_deg": s.alpha_deg, "d_total_rel": s.d_total_rel}  # noqa: E731
    if sigma.beacons == (sigma.target,) and not sigma.shared_alpha_deg:
        return pair(sigma.target)
    beacons = pair(sigma.beacons[0]) if len(sigma.beacons) == 1 else [pair(b) for b in
                                                                      sigma.beacons]
    out = {"target": pair(sigma.target), "beacons": beacons}
    if sigma.shared_alpha_deg:
        out["shared_alpha_deg"] = sigma.shared_alpha_deg
    return out
