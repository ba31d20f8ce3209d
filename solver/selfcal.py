"""Self-calibration's settings, one typed value: which bench errors a solve estimates
with the mirror (the nuisances), how well it knows the beacons' positions, and what it
knows of each nuisance before the frames (its prior).  Every command and pipeline that
solves self-calibrated passes one :class:`SelfCalibration`; it is checked once, where
it is made.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from solver.arguments import check_fields
from solver.errors import BadParameter, SolverError
from solver.measurements import is_number

# nuisances a bench shares across its measurements, estimated with the mirror when asked
# (self-calibration): "pan", an offset δ (deg) on every α (the mount's pan reading);
# "scale", a factor s on every d_total (the calibration's K); "power", the mirror's
# curvature c = 1/R (1/cm, > 0 concave), which moves each image by its own amount
# (:func:`solver.fit_model.power_terms`): α_meas = α + c·A + δ, d_meas = s·(d + c·D).
# Each: its name in a solution and its neutral value
NUISANCES = {"pan": ("pan_offset_deg", 0.0), "scale": ("range_scale", 1.0),
             "power": ("mirror_power_per_cm", 0.0)}
# what the 3-D solve alone estimates besides (:mod:`solver.lsq3`): "pitch", an offset δ
# (deg) on every elevation (the mount's pitch reading), of which a planar solve reads
# nothing
NUISANCES_3D = {"pitch": ("pitch_offset_deg", 0.0)}
KNOWN = {**NUISANCES, **NUISANCES_3D}
# how an estimate is said (by its name in a solution: a label, its unit, its format),
# and a prior's σ (scale's σ is a fraction, said in %)
WORDS = {"pan_offset_deg": ("pan offset", "°", ".4f"),
         "range_scale": ("range scale", "", ".4f"),
         "mirror_power_per_cm": ("mirror power 1/R", " /cm", ".2e"),
         "pitch_offset_deg": ("pitch offset", "°", ".4f")}
# the smallest σ a prior or a beacon position may have: below, the prior's weight
# swamps the measurements' by so much that the fit's information matrix is singular to
# double precision (pan 1e-7°, scale 1e-7 and power 1e-7/cm still solved a three-beacon
# exp1; scale 1e-8 and power 1e-8/cm did not).  A nuisance known better than this is
# known: leave it out of the nuisances; a beacon known better, position_sigma 0
PRIOR_MIN = {"pan": 1e-6, "scale": 1e-6, "power": 1e-6, "pitch": 1e-6}
POSITION_SIGMA_MIN_CM = 1e-4
_PRIOR_UNITS = {"pan": lambda s: f"±{s:.3g}°", "scale": lambda s: f"±{100 * s:.3g} %",
                "power": lambda s: f"±{s:.3g}/cm", "pitch": lambda s: f"±{s:.3g}°"}


@dataclass(frozen=True)
class SelfCalibration:
    """How a solve self-calibrates (the default: it does not).

    Attributes
    ----------
    nuisances : tuple of {'pan', 'scale', 'power', 'pitch'}
        Bench errors shared by every measurement, estimated jointly with the mirror
        (:data:`NUISANCES`; 'pitch' by the 3-D solve alone, :data:`NUISANCES_3D`); the
        target comes out corrected for them.
    position_sigma : float
        How well the beacons' positions are known (cm, each axis; 0: exactly).  Where
        > 0, each beacon's offset from its believed position is estimated too, with that
        prior: a misplaced beacon then moves its own image's fit, not the nuisances.
    priors : mapping of nuisance name to σ
        What the bench knows of some of ``nuisances`` before the frames: each gets the
        prior N(neutral, σ²) (pan and pitch in degrees, scale as a fraction of 1, power
        in 1/cm).

    Raises
    ------
    BadParameter
        Naming the field: a value of the wrong type, an unknown or repeated nuisance, a
        position σ that is neither 0 nor a finite length ≥
        :data:`POSITION_SIGMA_MIN_CM`, or a prior for a nuisance not estimated or whose
        σ is below :data:`PRIOR_MIN`.
    """

    nuisances: tuple[str, ...] = ()
    position_sigma: float = 0.0
    priors: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.priors is None:
            object.__setattr__(self, "priors", {})
        # the types first (a string for the names is refused: tuple("pan") would be
        # ('p', 'a', 'n')), then the values, each refusal naming its field
        check_fields(self)
        for name, check in (("nuisances", lambda: check_nuisances(self.nuisances, None, 1)),
                            ("position_sigma", lambda: check_position_sigma(
                                self.position_sigma)),
                            ("priors", lambda: check_nuisance_sigma(self.priors,
                                                                    self.nuisances))):
            try:
                check()
            except SolverError as exc:
                raise BadParameter(name, str(exc)) from None
        # plain floats (a numpy number would write itself as "np.float64(0.3)" in a
        # dataset's row and card)
        object.__setattr__(self, "position_sigma", float(self.position_sigma))
        object.__setattr__(self, "priors", {str(n): float(s) for n, s in self.priors.items()})

    def first(self, m: int) -> SelfCalibration:
        """The first ``m`` nuisances (in their order) with their priors: what fewer
        beacons can carry."""
        kept = self.nuisances[:m]
        return SelfCalibration(kept, self.position_sigma,
                               {n: s for n, s in self.priors.items() if n in kept})

    def describe_priors(self) -> str:
        """The priors in words with their units (:func:`describe_priors`)."""
        return describe_priors(self.priors)

    def to_json(self) -> dict:
        """As a document's ``self_calibration`` settings."""
        return {"nuisances": list(self.nuisances),
                "beacon_position_sigma_cm": self.position_sigma,
                **({"priors": dict(self.priors)} if self.priors else {})}

    @classmethod
    def from_json(cls, d: dict) -> SelfCalibration:
        """Inverse of :meth:`to_json`."""
        return cls(tuple(d["nuisances"]), d["beacon_position_sigma_cm"], d.get("priors", {}))


def check_planar(calibration: SelfCalibration) -> SelfCalibration:
    """``calibration``, refused in one line where it asks a planar solve for a nuisance
    only the 3-D solve estimates (:data:`NUISANCES_3D`)."""
    three = [n for n in calibration.nuisances if n in NUISANCES_3D]
    if three:
        raise SolverError(f"{', '.join(three)}: an offset on every elevation, which a planar "
                          "solve does not read (the 3-D solve estimates it)")
    return calibration


def as_calibration(calibration: object) -> SelfCalibration:
    """``calibration``, refused (one line) where it is not a :class:`SelfCalibration` (a
    dict had failed deep inside a solve, after the frames were rendered)."""
    if not isinstance(calibration, SelfCalibration):
        raise SolverError(f"calibration must be a SelfCalibration, e.g. "
                          f"SelfCalibration(('pan', 'scale')), got {type(calibration).__name__}"
                          f" {calibration!r}")
    return calibration


def describe_priors(priors: Mapping[str, float]) -> str:
    """Priors in words with their units, e.g. "pan ±0.29°, scale ±0.58 %"."""
    return ", ".join(f"{n} {_PRIOR_UNITS[n](s)}" for n, s in priors.items())


def priors_text(priors: Mapping[str, float]) -> str:
    """Priors as ``--prior`` takes them and a dataset's row and card hold them:
    ``pan=0.3,scale=0.006`` (each σ exactly, as Python writes a float)."""
    return ",".join(f"{n}={float(s)!r}" for n, s in priors.items())


def parse_priors(text: str) -> dict[str, float]:
    """Inverse of :func:`priors_text` (blank items skipped, spaces stripped).

    Raises
    ------
    ValueError
        An item that is not NAME=SIGMA with SIGMA a number, or a name given twice.
    """
    out: dict[str, float] = {}
    for item in (i.strip() for i in text.split(",") if i.strip()):
        name, _, value = (part.strip() for part in item.partition("="))
        if name in out:
            raise ValueError(f"{name!r} is given twice")
        try:
            out[name] = float(value)
        except ValueError:
            raise ValueError(f"{item!r} is not NAME=SIGMA, SIGMA a number") from None
    return out


def describe_estimates(estimates: Mapping[str, float], sd: Mapping[str, float]) -> str:
    """A solution's nuisance estimates (keyed by their solution names) with their σ's
    where known, e.g. "pan offset 0.1234° ± 0.0100°"."""
    out = []
    for name, v in estimates.items():
        e = sd.get(name)
        label, unit, f = WORDS.get(name, (name, "", ".4g"))
        out.append(f"{label} {v:{f}}{unit}" + ("" if e is None else f" ± {e:{f}}{unit}"))
    return ", ".join(out)


def check_position_sigma(position_sigma: float) -> None:
    """Refuse a beacon position σ that is not 0 (exactly known) or a finite length of at
    least :data:`POSITION_SIGMA_MIN_CM` (cm per axis)."""
    if not (is_number(position_sigma) and np.isfinite(position_sigma)
            and (position_sigma == 0 or position_sigma >= POSITION_SIGMA_MIN_CM)):
        # (its callers name the parameter, or the flag)
        raise SolverError(f"{position_sigma!r} must be 0 (known exactly) or a finite number "
                          f"≥ {POSITION_SIGMA_MIN_CM:g} (cm)")


def check_nuisance_sigma(priors: Mapping[str, float], nuisances: tuple[str, ...]) -> None:
    """Refuse a prior σ for a nuisance that is not estimated, or one that is not a
    finite number of at least :data:`PRIOR_MIN`."""
    for name, s in priors.items():
        if name not in KNOWN:
            raise SolverError(f"a prior σ for an unknown nuisance {name!r}: choose from "
                              f"{', '.join(KNOWN)}")
        if name not in nuisances:
            raise SolverError(f"a prior σ for {name!r}, which is not estimated (estimated: "
                              f"{', '.join(nuisances) or 'none'})")
        if not (is_number(s) and np.isfinite(s) and s >= PRIOR_MIN[name]):
            raise SolverError(f"the prior σ of {name} must be a number ≥ {PRIOR_MIN[name]:g} "
                              f"(one known better is known: leave it out of the nuisances), "
                              f"got {s!r}")


def check_nuisances(nuisances: tuple[str, ...], nb: int | None, nt: int,
                    *, priors: Mapping[str, float] | None = None, readings: int = 2) -> None:
    """Refuse unknown nuisances, and more unknowns than measurements (``nb`` None: the
    beacons are not known yet, the names only).  A nuisance with a prior brings its own
    measurement (the prior's row), so it does not count against the beacons.
    ``readings``: what each image gives (α and d_total; 3 in 3-D, its elevation besides),
    and as many unknowns the mirror and the target have each (its line and a point in
    the plane; its plane and a point in space)."""
    bad = [n for n in nuisances if n not in KNOWN]
    if bad:
        raise SolverError(f"unknown nuisance(s) {', '.join(map(repr, bad))}: choose from "
                          f"{', '.join(KNOWN)}")
    twice = sorted({n for n in nuisances if nuisances.count(n) > 1})
    if twice:
        raise SolverError(f"{', '.join(twice)} given twice: name each nuisance once")
    free = [n for n in nuisances if n not in (priors or {})]
    unknowns = 2 * readings + len(free)
    # the target's observations (one per frame) repeat one image's measurement: they
    # count once
    if free and nb is not None and readings * (nb + min(nt, 1)) < unknowns:
        need = -(-(unknowns - readings) // readings)
        raise SolverError(f"calibrating {' and '.join(free)} needs at least {need} beacon "
                          f"observations ({nb} given): each image gives {readings} "
                          f"measurements, and the mirror, the target and {len(free)} "
                          f"nuisance(s) without a prior are {unknowns} unknowns")


PLAIN = SelfCalibration()  # plain least squares: nothing estimated, positions exact
