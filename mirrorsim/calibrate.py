"""Size-constancy calibration: K = s_px · d_ref per object and camera (paper eq 5).

(Precisely, K = s_px · (d_ref − f) with f the measured face's offset before the object's
centre, :data:`mirrorsim.detect.FRONT_OFFSET`: the panel's half-thickness, the
pencil's mean near-side radius.)

Like the paper (229 px at 1 m for its target), each object is rendered in direct view
at d_ref = 100 cm, facing the camera on its optical axis, and measured exactly as the
detector measures images in the mirror (:func:`mirrorsim.detect.measure_region`), so a
bias common to both cancels.  Results are cached per camera and object in
``<cache>/calibration.json`` (``MIRRORSIM_CACHE_DIR`` or ``~/.cache/mirrorsim``).
"""

from __future__ import annotations

from pathlib import Path

from mirrorsim.backend import cache_path, read_cache, write_cache
from mirrorsim.detect import (
    FRONT_OFFSET,
    Calibration,
    DetectionError,
    _pencil_regions,
    _target_region,
    measure_region,
    to_linear,
)
from mirrorsim.scene import Camera

D_REF = 100.0
CALIBRATION_SPP = 64


def calibration_key(camera: Camera, target_size, pencil_height: float) -> str:
    return (f"{camera.width}x{camera.height_px}|hfov={camera.hfov:.9g}|h={camera.height:.9g}|"
            f"target={target_size[0]:.9g}x{target_size[1]:.9g}|pencil={pencil_height:.9g}|"
            f"spp={CALIBRATION_SPP}|front-offset|plain")


def _cache_file() -> Path:
    return cache_path().with_name("calibration.json")


def measure_reference(camera: Camera, kind: str, size, variant: str = "auto") -> float:
    """Pixel height of the object at D_REF, as the detector measures it."""
    from mirrorsim.render import render_reference

    img = render_reference(camera, kind, size, distance=D_REF, spp=CALIBRATION_SPP,
                           variant=variant).astype("float32")
    if kind == "target":
        box = _target_region(img, size[0] / size[1])
        boxes = [] if box is None else [box]
    else:
        boxes = _pencil_regions(img)
    if not boxes:
        raise DetectionError(f"calibration: the {kind} was not found in its reference render")
    box = max(boxes, key=lambda b: (b[2] - b[0]) * (b[3] - b[1]))
    linear = to_linear(img)
    if kind == "pencil":  # as the detector does: the paint's blue channel
        linear = linear[..., 2:3]
    m = measure_region(linear, box, kind, size[0] / size[1] if kind == "target" else None)
    if m.height_px is None:
        raise DetectionError(f"calibration: the {kind}'s height could not be measured")
    return m.height_px


def calibrate(camera: Camera, target_size, pencil_height: float, *, variant: str = "auto",
              refresh: bool = False) -> Calibration:
    """K for the target and the pencil with this camera (cached)."""
    key = calibration_key(camera, target_size, pencil_height)
    path = _cache_file()
    cache = read_cache(path)
    if key in cache and not refresh:
        c = cache[key]
        return Calibration(target_k=c["target_k"], pencil_k=c["pencil_k"], key=key)
    s_t = measure_reference(camera, "target", tuple(target_size), variant)
    s_p = measure_reference(camera, "pencil", pencil_height, variant)
    cal = Calibration(target_k=s_t * (D_REF - FRONT_OFFSET["target"]),
                      pencil_k=s_p * (D_REF - FRONT_OFFSET["beacon"]), key=key)
    cache[key] = {"target_k": cal.target_k, "pencil_k": cal.pencil_k,
                  "target_px_at_100cm": s_t, "pencil_paint_px_at_100cm": s_p}
    write_cache(path, cache)
    return cal
