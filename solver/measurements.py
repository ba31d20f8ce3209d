"""Reading and writing the measurement JSON of INTERFACE.md (``detect`` writes it,
``solve`` reads it); usable for real measurements as well as simulated ones."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from solver.sltr import BeaconMeasurement, Sigma


class InputError(ValueError):
    """Bad input file: ``str(err)`` is one line naming the file, the key and the value."""

    def __init__(self, file: str | Path, key: str, message: str):
        self.file, self.key, self.message = str(file), key, message
        super().__init__(f"{file}: {key}: {message}" if key else f"{file}: {message}")


class MeasurementError(InputError):
    """A bad measurement file."""


@dataclass(frozen=True)
class Measurements:
    observer: tuple[float, float]
    targets: list[tuple[float, float]]  # (alpha_deg, d_total) observations of the target
    beacons: list[BeaconMeasurement]
    sigma: Sigma | None = None


def load_measurements(path: str | Path) -> Measurements:
    """Parse and validate a measurements file (raises :class:`MeasurementError`)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MeasurementError(path, "", "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MeasurementError(path, "", f"cannot read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise MeasurementError(path, "", f"malformed JSON: line {exc.lineno}, column "
                               f"{exc.colno}: {exc.msg}") from None
    return measurements_from_dict(data, path)


def measurements_from_dict(data: Any, source: str | Path = "<measurements>") -> Measurements:
    def fail(key, msg):
        return MeasurementError(source, key, msg)

    def num(v, key, positive=False):
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise fail(key, f"expected a finite number, got {v!r}")
        if positive and v <= 0:
            raise fail(key, f"{v!r} must be > 0")
        return float(v)

    def pair(v, key):
        if not isinstance(v, list) or len(v) != 2:
            raise fail(key, f"expected [x, y], got {v!r}")
        return num(v[0], f"{key}[0]"), num(v[1], f"{key}[1]")

    def keys(d, key, required, optional=()):
        if not isinstance(d, dict):
            raise fail(key or "(top level)", f"expected an object, got {type(d).__name__}")
        for k in d:
            if k not in (*required, *optional):
                raise fail(f"{key}.{k}" if key else k, "unknown key")
        for k in required:
            if k not in d:
                raise fail(f"{key}.{k}" if key else k, "missing required key")
        return d

    top = keys(data, "", ("observer", "target", "beacons"),
               ("sigma", "scene", "detector", "source"))
    observer = pair(top["observer"], "observer")
    raw_t = top["target"]
    raw_t = raw_t if isinstance(raw_t, list) else [raw_t]
    targets = []
    for i, t in enumerate(raw_t):
        key = "target" if not isinstance(top["target"], list) else f"target[{i}]"
        t = keys(t, key, ("alpha_deg", "d_total"), ("bbox_px", "height_px", "u_axis", "clipped",
                                                     "source"))
        targets.append((num(t["alpha_deg"], f"{key}.alpha_deg"),
                        num(t["d_total"], f"{key}.d_total", positive=True)))
    if not isinstance(top["beacons"], list) or not top["beacons"]:
        raise fail("beacons", "expected a non-empty list")
    beacons = []
    for i, b in enumerate(top["beacons"]):
        b = keys(b, f"beacons[{i}]", ("position", "alpha_deg", "d_total"),
                 ("bbox_px", "height_px", "u_axis", "clipped", "source"))
        beacons.append(BeaconMeasurement(
            pair(b["position"], f"beacons[{i}].position"),
            num(b["alpha_deg"], f"beacons[{i}].alpha_deg"),
            num(b["d_total"], f"beacons[{i}].d_total", positive=True)))
    sigma = None
    if "sigma" in top:
        s = keys(top["sigma"], "sigma", ("alpha_deg", "d_total_rel"))
        sigma = Sigma(num(s["alpha_deg"], "sigma.alpha_deg", positive=True),
                      num(s["d_total_rel"], "sigma.d_total_rel", positive=True))
    return Measurements(observer, targets, beacons, sigma)


def measurements_to_dict(m: Measurements) -> dict:
    out = {"observer": list(m.observer),
           "target": ({"alpha_deg": m.targets[0][0], "d_total": m.targets[0][1]}
                      if len(m.targets) == 1 else
                      [{"alpha_deg": a, "d_total": d} for a, d in m.targets]),
           "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                        "d_total": b.d_total} for b in m.beacons]}
    if m.sigma is not None:
        out["sigma"] = {"alpha_deg": m.sigma.alpha_deg, "d_total_rel": m.sigma.d_total_rel}
    return out


def write_json(path: str | Path, data: dict) -> None:
    Path(path).write_text(json.dumps(data, indent=2) + "\n")
