"""The measurement JSON of INTERFACE.md (``detect`` writes it, ``solve`` reads it);
usable for real measurements as well as simulated ones."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from solver.errors import InputError
from solver.reader import Reader, read_json
from solver.sltr import BeaconMeasurement, Sigma

# σ's beyond these are no measurement: a bearing known to ±45° or a distance to ±100 %
SIGMA_ALPHA_MAX_DEG = 45.0
SIGMA_D_REL_MAX = 1.0
# what detect adds beside the solver's inputs; the solver ignores it
_DETECTOR_KEYS = ("bbox_px", "height_px", "u_axis", "clipped", "source")


class MeasurementError(InputError):
    """A bad measurement file."""


@dataclass(frozen=True)
class Measurements:
    """The solver's inputs: observer, target observations, beacons, optional σ's."""

    observer: tuple[float, float]
    targets: list[tuple[float, float]]  # (alpha_deg, d_total) observations of the target
    beacons: list[BeaconMeasurement]
    sigma: Sigma | None = None

    def to_json(self) -> dict:
        """The measurements document (one target observation as an object, several as a
        list)."""
        t = [{"alpha_deg": a, "d_total": d} for a, d in self.targets]
        out = {"observer": list(self.observer),
               "target": t[0] if len(t) == 1 else t,
               "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                            "d_total": b.d_total} for b in self.beacons]}
        if self.sigma is not None:
            out["sigma"] = {"alpha_deg": self.sigma.alpha_deg,
                            "d_total_rel": self.sigma.d_total_rel}
        return out

    @classmethod
    def from_json(cls, data: Any, source: str | Path = "<measurements>") -> Measurements:
        """Parse and validate (raises :class:`MeasurementError` naming file and key)."""
        return measurements_from_dict(data, source)


def load_measurements(path: str | Path) -> Measurements:
    """Parse and validate a measurements file (raises :class:`MeasurementError`)."""
    return measurements_from_dict(read_json(path, MeasurementError), path)


def measurements_from_dict(data: Any, source: str | Path = "<measurements>") -> Measurements:
    """Validate parsed measurement JSON (see :meth:`Measurements.from_json`)."""
    r = Reader(source, MeasurementError)
    top = r.mapping(data, "", ("observer", "target", "beacons"),
                    ("sigma", "scene", "detector", "source"))
    observer = r.pair(top["observer"], "observer")
    raw_t = top["target"]
    listed = isinstance(raw_t, list)
    if listed and not raw_t:
        raise r.fail("target", "expected an observation or a non-empty list of them")
    targets = []
    for i, t in enumerate(raw_t if listed else [raw_t]):
        key = f"target[{i}]" if listed else "target"
        t = r.mapping(t, key, ("alpha_deg", "d_total"), _DETECTOR_KEYS)
        targets.append((r.number(t["alpha_deg"], f"{key}.alpha_deg"),
                        r.number(t["d_total"], f"{key}.d_total", positive=True)))
    if not isinstance(top["beacons"], list) or not top["beacons"]:
        raise r.fail("beacons", "expected a non-empty list")
    beacons = []
    for i, b in enumerate(top["beacons"]):
        key = f"beacons[{i}]"
        b = r.mapping(b, key, ("position", "alpha_deg", "d_total"), _DETECTOR_KEYS)
        beacons.append(BeaconMeasurement(
            r.pair(b["position"], f"{key}.position"),
            r.number(b["alpha_deg"], f"{key}.alpha_deg"),
            r.number(b["d_total"], f"{key}.d_total", positive=True)))
    sigma = read_sigma(r, top["sigma"]) if "sigma" in top else None
    return Measurements(observer, targets, beacons, sigma)


def read_sigma(r: Reader, value: Any, key: str = "sigma") -> Sigma:
    """A ``sigma`` block: α in degrees and d_total relative, each > 0 and sensible."""
    s = r.mapping(value, key, ("alpha_deg", "d_total_rel"))
    return Sigma(r.number(s["alpha_deg"], f"{key}.alpha_deg", positive=True,
                          high=SIGMA_ALPHA_MAX_DEG),
                 r.number(s["d_total_rel"], f"{key}.d_total_rel", positive=True,
                          high=SIGMA_D_REL_MAX))
