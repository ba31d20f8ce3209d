"""The measurement JSON of docs/files.md (``detect`` writes it, ``solve`` reads it);
usable for real measurements as well as simulated ones."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mirrorsim.formats.reader import Reader, parse_json, read_json, read_stdin_text, show
from solver.errors import InputError
from solver.lsq3 import Measurements3
from solver.measurements import (
    D_TOTAL_RANGE_CM,
    SIGMA_ALPHA_MAX_DEG,
    SIGMA_ALPHA_MIN_DEG,
    SIGMA_D_REL_MAX,
    SIGMA_D_REL_MIN,
    BeaconMeasurement,
    Measurements,
    ObjectSigmas,
    Sigma,
)

# what detect adds beside the solver's inputs; the solver ignores it
_DETECTOR_KEYS = ("bbox_px", "height_px", "u_axis", "clipped", "source")


class MeasurementError(InputError):
    """A bad measurement file."""


def load_measurements(path: str | Path) -> Measurements | Measurements3:
    """Parse and validate a measurements file (raises :class:`MeasurementError`); ``-``
    reads standard input (``check --measurements - | solve -``)."""
    if str(path) == "-":
        return measurements_from_dict(parse_json(read_stdin_text(MeasurementError), "<stdin>",
                                                 MeasurementError), "<stdin>")
    return measurements_from_dict(read_json(path, MeasurementError), path)


def measurements_from_dict(data: Any, source: str | Path = "<measurements>"
                           ) -> Measurements | Measurements3:
    """Validate parsed measurement JSON (raises :class:`MeasurementError` naming the
    source and the key): planar, or 3-D where the observer has a height and every image
    an ``elevation_deg`` (:func:`measurements3_from_dict`)."""
    if (isinstance(data, dict) and isinstance(data.get("observer"), list)
            and len(data["observer"]) == 3):
        return measurements3_from_dict(data, source)
    r = Reader(source, MeasurementError)
    top = r.mapping(data, "", ("observer", "target", "beacons"),
                    optional=("sigma", "observer_pan_deg", "scene", "detector", "source"))
    observer = r.pair(top["observer"], "observer")
    raw_t = top["target"]
    listed = isinstance(raw_t, list)
    if listed and not raw_t:
        raise r.fail("target", "expected an observation or a non-empty list of them")
    targets = []
    for i, t in enumerate(raw_t if listed else [raw_t]):
        key = f"target[{i}]" if listed else "target"
        t = r.mapping(t, key, ("alpha_deg", "d_total"), optional=_DETECTOR_KEYS)
        targets.append((r.number(t["alpha_deg"], f"{key}.alpha_deg"),
                        r.number(t["d_total"], f"{key}.d_total", low=D_TOTAL_RANGE_CM[0],
                                 high=D_TOTAL_RANGE_CM[1])))
    if not isinstance(top["beacons"], list) or not top["beacons"]:
        raise r.fail("beacons", "expected a non-empty list")
    beacons = []
    for i, b in enumerate(top["beacons"]):
        key = f"beacons[{i}]"
        b = r.mapping(b, key, ("position", "alpha_deg", "d_total"), optional=_DETECTOR_KEYS)
        beacons.append(BeaconMeasurement(
            r.pair(b["position"], f"{key}.position"),
            r.number(b["alpha_deg"], f"{key}.alpha_deg"),
            r.number(b["d_total"], f"{key}.d_total", low=D_TOTAL_RANGE_CM[0],
                     high=D_TOTAL_RANGE_CM[1])))
    sigma = read_sigmas(r, top["sigma"], len(beacons)) if "sigma" in top else None
    pan = (r.number(top["observer_pan_deg"], "observer_pan_deg", low=-360.0, high=360.0)
           if "observer_pan_deg" in top else None)
    return Measurements(observer, targets, beacons, sigma, pan)


def read_sigmas(r: Reader, value: Any, n_beacons: int, *, key: str = "sigma") -> ObjectSigmas:
    """A ``sigma`` block: one pair for every observation, or ``target`` and ``beacons``
    (one pair for all beacons, or a list of one per beacon)."""
    if isinstance(value, dict) and "target" in value:
        s = r.mapping(value, key, ("target", "beacons"), optional=("shared_alpha_deg",))
        raw = s["beacons"]
        if isinstance(raw, list):
            if len(raw) != n_beacons:
                raise r.fail(f"{key}.beacons", f"{len(raw)} entries for {n_beacons} beacons")
            beacons = tuple(read_sigma(r, b, f"{key}.beacons[{i}]") for i, b in enumerate(raw))
        else:
            beacons = (read_sigma(r, raw, f"{key}.beacons"),)
        shared = read_shared_alpha(r, s.get("shared_alpha_deg", 0.0),
                                   f"{key}.shared_alpha_deg")
        return ObjectSigmas(read_sigma(r, s["target"], f"{key}.target"), beacons, shared)
    return ObjectSigmas.same(read_sigma(r, value, key))


def read_sigma(r: Reader, value: Any, key: str = "sigma") -> Sigma:
    """A σ pair: α in degrees and d_total relative (a fraction), each > 0 and sensible."""
    s = r.mapping(value, key, ("alpha_deg", "d_total_rel"))
    return Sigma(r.number(s["alpha_deg"], f"{key}.alpha_deg", low=SIGMA_ALPHA_MIN_DEG,
                          high=SIGMA_ALPHA_MAX_DEG),
                 r.number(s["d_total_rel"], f"{key}.d_total_rel", low=SIGMA_D_REL_MIN,
                          high=SIGMA_D_REL_MAX))


def read_shared_alpha(r: Reader, value: Any, key: str) -> float:
    """The σ (deg) of an α offset every image of a frame shares: 0 (none) or a σ_α."""
    shared = r.number(value, key, low=0.0, high=SIGMA_ALPHA_MAX_DEG)
    if 0 < shared < SIGMA_ALPHA_MIN_DEG:
        raise r.fail(key, f"{shared:g} must be 0 (none) or ≥ {SIGMA_ALPHA_MIN_DEG:g}")
    return shared


_IMAGE3 = ("alpha_deg", "elevation_deg", "d_total")


def measurements3_from_dict(data: Any, source: str | Path = "<measurements>"
                            ) -> Measurements3:
    """Validate parsed 3-D measurement JSON (docs/files.md): the observer [x, y, z], the
    target's and each beacon's ``alpha_deg``, ``elevation_deg`` and ``d_total``, each
    beacon's ``position`` [x, y] or [x, y, z]; optionally ``heights`` and ``fronts`` (one
    per beacon, then the target's), ``sigma`` (one ``{alpha_deg, elevation_deg,
    d_total_rel}`` for every observation, or a list, the beacons' then the target's) and
    ``observer_pan_deg`` (the pan the readings were made at)."""
    r = Reader(source, MeasurementError)
    top = r.mapping(data, "", ("observer", "target", "beacons"),
                    optional=("heights", "fronts", "sigma", "observer_pan_deg", "scene",
                              "source", "detector"))
    raw = top["observer"]
    if not isinstance(raw, list) or len(raw) != 3:
        raise r.fail("observer", f"expected [x, y, z] (the lens's height: 3-D measurements), "
                     f"got {show(raw)}")
    observer = (*r.pair(raw[:2], "observer"), r.number(raw[2], "observer[2]"))

    def image(value: Any, key: str) -> tuple[float, float, float]:
        v = r.mapping(value, key, _IMAGE3, optional=("position",) if key != "target" else ())
        return (r.number(v["alpha_deg"], f"{key}.alpha_deg"),
                r.number(v["elevation_deg"], f"{key}.elevation_deg", low=-90.0, high=90.0),
                r.number(v["d_total"], f"{key}.d_total", low=D_TOTAL_RANGE_CM[0],
                         high=D_TOTAL_RANGE_CM[1]))

    beacons = _beacons3(r, top["beacons"], image)
    n = len(beacons) + 1

    def per_object(key: str) -> tuple[float, ...] | None:
        if key not in top:
            return None
        v = top[key]
        if not isinstance(v, list) or len(v) != n:
            raise r.fail(key, f"expected {n} numbers (each beacon's, then the target's)")
        return tuple(r.number(x, f"{key}[{k}]", low=0.0) for k, x in enumerate(v))

    sigma = None
    if "sigma" in top:
        raw_s = top["sigma"] if isinstance(top["sigma"], list) else [top["sigma"]] * n
        if len(raw_s) != n:
            raise r.fail("sigma", f"expected one σ triple, or {n} (each beacon's, then the "
                         "target's)")
        sigma = tuple(_sigma3(r, v, f"sigma[{k}]") for k, v in enumerate(raw_s))
    heights = per_object("heights")
    if heights is not None and min(heights) <= 0:
        raise r.fail("heights", "each height must be > 0")
    fronts = per_object("fronts")
    if fronts is not None and heights is None:
        raise r.fail("fronts", "given without `heights` (they model a detector's readings)")
    pan = (r.number(top["observer_pan_deg"], "observer_pan_deg", low=-360.0, high=360.0)
           if "observer_pan_deg" in top else None)
    return Measurements3(observer=observer, beacons=tuple(beacons),
                         target=image(top["target"], "target"), heights=heights,
                         fronts=fronts, sigma=sigma, pan_deg=pan)


def _beacons3(r: Reader, raw: Any, image: Any) -> list:
    """Each beacon's believed base [x, y(, z)] and its image's reading (``image``)."""
    if not isinstance(raw, list) or not raw:
        raise r.fail("beacons", "expected a non-empty list")
    beacons = []
    for i, b in enumerate(raw):
        key = f"beacons[{i}]"
        if not isinstance(b, dict) or "position" not in b:
            raise r.fail(f"{key}.position", "missing required key")
        xy, z = r.point(b["position"], f"{key}.position")
        beacons.append(((*xy, z), image(b, key)))
    return beacons


def _sigma3(r: Reader, value: Any, key: str) -> tuple[float, float, float]:
    """A 3-D observation's σ's: α and elevation in degrees, d_total relative."""
    s = r.mapping(value, key, ("alpha_deg", "elevation_deg", "d_total_rel"))
    return (r.number(s["alpha_deg"], f"{key}.alpha_deg", low=SIGMA_ALPHA_MIN_DEG,
                     high=SIGMA_ALPHA_MAX_DEG),
            r.number(s["elevation_deg"], f"{key}.elevation_deg", low=SIGMA_ALPHA_MIN_DEG,
                     high=SIGMA_ALPHA_MAX_DEG),
            r.number(s["d_total_rel"], f"{key}.d_total_rel", low=SIGMA_D_REL_MIN,
                     high=SIGMA_D_REL_MAX))
