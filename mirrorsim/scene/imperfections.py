"""A scene's bench imperfections as named sources: list them, keep one, drop all.

The error budget (:mod:`mirrorsim.pipelines.budget`) renders a scene ideal, with each source
alone, and with all; a source is named by its scene-file key path
(``camera.pan_error``, ``mirror.curvature_radius``, ``beacons[0].known_position``…).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

from mirrorsim.scene.model import Bench, Scene

# Bench field → the key path a scene file writes it under (INTERFACE.md)
KEYS = {"pan_error": "camera.pan_error", "pitch": "camera.pitch", "roll": "camera.roll",
        "distortion": "camera.distortion", "noise": "camera.noise",
        "jpeg_quality": "camera.jpeg_quality", "curvature_radius": "mirror.curvature_radius",
        "tilt": "mirror.tilt", "calibration_distance_error": "calibration.distance_error"}
_IDEAL = Bench()


@dataclass(frozen=True)
class Source:
    """One imperfection of a scene: its key path and its value as written."""

    key: str
    value: Any


def sources(scene: Scene) -> list[Source]:
    """The imperfections present in ``scene``, in INTERFACE.md's order.

    ``camera.distortion_known`` is not a source of its own: it says whether the
    ``camera.distortion`` source is corrected by the detector.
    """
    out = []
    for f in fields(Bench):
        if f.name in KEYS and getattr(scene.bench, f.name) != getattr(_IDEAL, f.name):
            value = getattr(scene.bench, f.name)
            if f.name == "noise":
                value = {"full_well": value.full_well, "read_noise": value.read_noise}
            out.append(Source(KEYS[f.name], list(value) if isinstance(value, tuple) else value))
    for i, b in enumerate(scene.beacons):
        if b.known_position is not None and tuple(b.known_position) != tuple(b.position):
            out.append(Source(f"beacons[{i}].known_position", list(b.known_position)))
    return out


def as_keys(scene: Scene) -> dict[str, Any]:
    """The scene's imperfections as a scene file writes them, by key path (with
    ``camera.distortion_known`` where it is false); empty for an ideal bench."""
    found = {s.key: s.value for s in sources(scene)}
    if "camera.distortion" in found and not scene.bench.distortion_known:
        found["camera.distortion_known"] = False
    return found


def ideal(scene: Scene) -> Scene:
    """The same scene on an ideal bench."""
    return replace(scene, bench=Bench(),
                   beacons=tuple(replace(b, known_position=None) for b in scene.beacons))


def only(scene: Scene, key: str) -> Scene:
    """The scene on an ideal bench but for the one source ``key`` (as :func:`sources`
    names it)."""
    base = ideal(scene)
    if key.startswith("beacons["):
        i = int(key[len("beacons["):key.index("]")])
        beacons = list(base.beacons)
        beacons[i] = scene.beacons[i]
        return replace(base, beacons=tuple(beacons))
    name = next(n for n, k in KEYS.items() if k == key)
    kept = {name: getattr(scene.bench, name)}
    if name == "distortion":
        kept["distortion_known"] = scene.bench.distortion_known
    return replace(base, bench=replace(Bench(), **kept))


# a dataset row's imperfection columns (every row has all of them, ideal values on an
# ideal bench, so that tables of different specs share a schema)
ROW_COLUMNS = ("bench_pan_error_deg", "bench_pitch_deg", "bench_roll_deg", "bench_k1",
               "bench_k2", "bench_distortion_known", "bench_full_well", "bench_read_noise",
               "bench_jpeg_quality", "bench_curvature_per_cm", "bench_tilt_deg",
               "bench_calibration_error_cm", "bench_beacon_dx_cm", "bench_beacon_dy_cm")


def row_values(scene: Scene) -> dict[str, Any]:
    """The scene's imperfections as a dataset row's columns (:data:`ROW_COLUMNS`):
    ``bench_full_well`` 0 means no sensor noise, ``bench_jpeg_quality`` 0 a lossless PNG,
    ``bench_curvature_per_cm`` 0 a flat mirror; the beacon offsets are believed − true."""
    b = scene.bench
    beacon = scene.beacons[0]
    believed = beacon.known_position if beacon.known_position is not None else beacon.position
    values = (b.pan_error, b.pitch, b.roll, b.distortion[0], b.distortion[1],
              b.distortion_known, b.noise.full_well if b.noise else 0.0,
              b.noise.read_noise if b.noise else 0.0, b.jpeg_quality or 0,
              1.0 / b.curvature_radius if b.curvature_radius else 0.0, b.tilt,
              b.calibration_distance_error, believed[0] - beacon.position[0],
              believed[1] - beacon.position[1])
    return dict(zip(ROW_COLUMNS, values, strict=True))
