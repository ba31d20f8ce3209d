"""Size-constancy calibration: K = s_px · d_ref per object and camera (paper eq 5).

(Precisely, K = s_px · (d_ref − f) with f the measured face's offset before the object's
centre, :data:`mirrorsim.scene.model.FRONT_OFFSET`: the panel's half-thickness, the
pencil's mean near-side radius.)

Like the paper (229 px at 1 m for its target), each object is rendered in direct view
at d_ref = 100 cm, facing the camera on its optical axis, on a plain board, and measured
exactly as the detector measures images in the mirror
(:func:`mirrorsim.detection.detector.measure_object`), so a bias common to both cancels.  Results
are cached per camera and objects in ``<cache>/calibration/`` (one verified file per
entry, :mod:`mirrorsim.formats.cache`; ``MIRRORSIM_CACHE_DIR`` or ``~/.cache/mirrorsim``):
an entry whose K does not follow from its measured pixel heights is measured again.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from mirrorsim.detection.detector import measure_object
from mirrorsim.detection.edges import panel_top_face
from mirrorsim.detection.image_geometry import Calibration
from mirrorsim.errors import BadParameter, DetectionError
from mirrorsim.formats.cache import read_entry, write_entry
from mirrorsim.formats.capture import REFERENCE_DISTANCE
from mirrorsim.scene import imperfections
from mirrorsim.scene.bench_values import check_bounds
from mirrorsim.scene.model import (
    FRONT_OFFSET,
    MAX_RESOLUTION,
    PENCIL_RADIUS,
    Beacon,
    Board,
    Camera,
    Target,
    pencil_cone_ratio,
    pencil_paint_height,
)
from mirrorsim.truth import optics
from solver.geometry import unit
from solver.measurements import is_number

# where the reference objects stand (cm): the capture record's, declared with it
D_REF = REFERENCE_DISTANCE
# per reference object: the pencil's 45 px band rests on two edges of a few columns, whose
# render noise at 64 spp erred K for every frame of a camera alike; the target's 230 px
# panel averages over ~90 columns and is well measured at 64
CALIBRATION_SPP = {"target": 64, "beacon": 1024}
REFERENCE_PAN = 45.0  # the reference camera looks along the board's diagonal
MARGIN_PX = 24  # rendered around the object's projected outline
# the least paint height (px) a reference pencil is measured at: a smaller one is
# rendered with the camera's film enlarged a whole number of times (same field of view,
# so its fx scales exactly) and its height divided back.  A 2.2 cm pencil at 100 cm on a
# 960 px frame of 88° is 7 px tall, under what find_pencils takes (2 of the ideal
# acceptance set's 100 scenes failed so), and a 12 px one reads 1-2 % off
MIN_REFERENCE_PX = 24.0
# bump whenever the measurement changes, so that no K measured the old way is reused
# (seeds-ss: the render seeds hashed by SeedSequence)
METHOD = "foot-chroma|target-foot-chroma|front-0.338|slope8|seeds-ss|film-x24"


def calibration_key(camera: Camera, target_size: tuple[float, float], pencil_height: float,
                    *, distance_error: float = 0.0, subsampled: bool = False) -> str:
    """What K depends on: the camera model, the objects' sizes, the method (and whether
    its edges are measured as in a frame of half-resolution colour), and where the
    reference really stood (a bench's error; absent from the key when 0)."""
    key = (f"{camera.width}x{camera.height_px}|hfov={camera.hfov:.9g}|h={camera.height:.9g}|"
           f"target={target_size[0]:.9g}x{target_size[1]:.9g}|pencil={pencil_height:.9g}|"
           f"spp={CALIBRATION_SPP['target']},{CALIBRATION_SPP['beacon']}|{METHOD}|"
           f"code={code_fingerprint()}")
    key += "|subsampled" if subsampled else ""
    return key + (f"|reference_error={distance_error:.9g}" if distance_error else "")


# the code a K comes out of: this module and every module of ours it imports, directly
# or through others (found by reading their imports, not by what a process has loaded).
# A K measured by other code is another K (a cache kept across a detector change served
# constants 0.011 % (panel) and 0.019 % (pencil) off those this code measures), so the
# key holds a hash of their source rather than a version someone must remember to bump,
# or a list of modules someone must remember to extend (the segmentation's move to
# detection/regions.py had left it out of such a list)
_OURS = ("mirrorsim", "solver")


def code_modules(root: str = __name__) -> dict[str, Path]:
    """``root`` and every module of mirrorsim and the solver it imports, transitively,
    with its source file: found by reading the ``import`` statements of their source
    (lazy imports too), without importing anything (Mitsuba only when a render is
    needed)."""
    seen: dict[str, Path] = {}
    todo = [root]
    while todo:
        name = todo.pop()
        path = _source_of(name)
        if name in seen or path is None:
            continue
        seen[name] = path
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                todo += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                # `from package import module` names a module, `from module import name`
                # a name in it (no source of that name: the module itself counts)
                todo += [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
    return dict(sorted(seen.items()))


def _source_of(name: str) -> Path | None:
    """The source file of module ``name`` of ours (None: not ours, or not a module)."""
    parts = name.split(".")
    if parts[0] not in _OURS:
        return None
    spec = importlib.util.find_spec(parts[0])  # a top-level package: nothing is run
    base = Path(spec.origin).parent.joinpath(*parts[1:])
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@functools.cache
def code_fingerprint() -> str:
    """SHA-256 (12 hex digits) of the source of the modules a K depends on
    (:func:`code_modules`).  Finding them parses every module's source (a tenth of a
    command's start, ``benchmarks/freeze.py``): the answer is cached, keyed by the digest of every
    source file of ours, so any change to any of them finds them again.  Key and
    fingerprint hash the same bytes, read once."""
    sources = _our_sources()
    h = hashlib.sha256(b"code-fingerprint-1")
    for path, data in sources.items():
        h.update(str(path).encode() + b"\0" + data)
    key = h.hexdigest()
    found = read_entry("code", key, check=_check_fingerprint)
    if found is not None:
        return found["fingerprint"]
    h = hashlib.sha256()
    for name, path in code_modules().items():
        data = sources.get(path)
        h.update(name.encode() + b"\0" + (data if data is not None else path.read_bytes()))
    write_entry("code", key, {"fingerprint": h.hexdigest()[:12]})
    return h.hexdigest()[:12]


def _our_sources() -> dict[Path, bytes]:
    """Every source file of mirrorsim and the solver, with its bytes."""
    out = {}
    for package in _OURS:
        root = Path(importlib.util.find_spec(package).origin).parent
        out |= {path: path.read_bytes() for path in sorted(root.rglob("*.py"))}
    return out


def _check_fingerprint(value: dict) -> None:
    """A cached fingerprint's shape: 12 hex digits."""
    f = value["fingerprint"]
    if not (isinstance(f, str) and len(f) == 12 and all(c in "0123456789abcdef" for c in f)):
        raise ValueError(f"not a code fingerprint: {f!r}")


def reference_camera(camera: Camera, film: int = 1) -> Camera:
    """The scene's camera model at the board's corner, looking along REFERENCE_PAN;
    ``film``: its film that many times as many pixels across and down (fx as many)."""
    w, h = camera.resolution
    return Camera(position=(0.0, 0.0), height=camera.height, resolution=(w * film, h * film),
                  hfov=camera.hfov, pan=REFERENCE_PAN, pan_deg=REFERENCE_PAN)


def reference_film(camera: Camera, kind: str, size: float | tuple[float, float], *,
                   distance: float = D_REF) -> int:
    """How many times to enlarge the film for a reference pencil's paint to stand at
    least MIN_REFERENCE_PX tall at ``distance`` (1 for a panel, or a pencil already so;
    never past MAX_RESOLUTION)."""
    if kind != "beacon":
        return 1
    px = camera.fx * pencil_paint_height(float(size)) / distance
    most = min(MAX_RESOLUTION[0] // camera.width, MAX_RESOLUTION[1] // camera.height_px)
    return int(max(1, min(most, math.ceil(MIN_REFERENCE_PX / px))))


def reference_object(kind: str, size: float | tuple[float, float], distance: float = D_REF
                     ) -> Target | Beacon:
    """The object on the reference camera's optical axis at ``distance``, facing it."""
    p = tuple(float(v) for v in distance * unit(REFERENCE_PAN))
    if kind == "target":
        return Target(position=p, size=tuple(size), facing_deg=REFERENCE_PAN + 180.0)
    if kind == "beacon":
        return Beacon(position=p, height=float(size))
    raise ValueError(f"unknown reference object {kind!r}")


def reference_crop(camera: Camera, obj: Target | Beacon) -> tuple[int, int, int, int]:
    """The film region (u0, v0, u1, v1) around the object's projected outline."""
    half_w = obj.size[0] / 2 if isinstance(obj, Target) else PENCIL_RADIUS
    top = obj.size[1] if isinstance(obj, Target) else obj.height
    across = unit(REFERENCE_PAN + 90)
    pts = np.array([[*(np.asarray(obj.position) + s * half_w * across), z]
                    for s in (-1, 1) for z in (0.0, top)])
    u, v, depth = optics.project(camera, pts)
    box = optics.film_box(camera, u, v, depth=depth, margin_px=MARGIN_PX)
    if box is None:  # the reference stands on the optical axis, 100 cm ahead
        raise DetectionError("the calibration's reference object is not on the film")
    return box


def measure_reference(camera: Camera, kind: str, size: float | tuple[float, float],
                      *, variant: str = "auto", distance: float = D_REF, subsampled: bool = False
                      ) -> float:
    """Pixel height of the object standing at ``distance``, as the detector measures it
    (``subsampled``: as it measures a JPEG frame), on the camera's film (a small pencil
    measured on an enlarged one: :func:`reference_film`)."""
    from mirrorsim.rendering.passes import render_direct  # Mitsuba only when a render is needed

    film = reference_film(camera, kind, size, distance=distance)
    cam = reference_camera(camera, film)
    obj = reference_object(kind, size, distance)
    # a plain board: a hole under the reference object's foot would bias its calibration
    crop = reference_crop(cam, obj)
    img = render_direct(Board(size=(80.0, 80.0), hole_pitch=0.0), cam, obj,
                        spp=CALIBRATION_SPP[kind], crop=crop, variant=variant)
    ratio = size[0] / size[1] if kind == "target" else None
    cone = None if kind == "target" else pencil_cone_ratio(size)
    # (the frame's panel is measured below its lit top face: the reference so too, its
    # principal column in the crop's pixels)
    top = replace(panel_top_face(cam, size), cx=cam.cx - crop[0]) if kind == "target" \
        else None
    try:
        m = measure_object(img, kind, ratio, subsampled=subsampled, cone_ratio=cone,
                           top_face=top)
    except DetectionError as exc:
        raise DetectionError(f"calibration: {exc} (the {kind}'s reference render)") from None
    if m.height_px is None:
        raise DetectionError(f"calibration: the {kind}'s height could not be measured")
    return m.height_px / film


def _check_distance_error(value) -> None:
    """The scene key ``calibration.distance_error``'s rule, for a caller of the library
    (NaN failed deep in a format, a string in a subtraction)."""
    imp = next(i for i in imperfections.REGISTRY if i.field == "calibration_distance_error")
    if not is_number(value) or not math.isfinite(value):
        raise BadParameter("distance_error", f"{value!r} is not a finite number (cm)")
    why = check_bounds(imp, float(value))
    if why:
        raise BadParameter("distance_error", why)


def calibrate(camera: Camera, target_size: tuple[float, float], pencil_height: float, *,
              variant: str = "auto", refresh: bool = False, distance_error: float = 0.0,
              subsampled: bool = False) -> Calibration:
    """K for the target and the pencil with this camera (cached).

    ``distance_error``: a bench's reference objects stood this much farther than the
    D_REF that K assumes (docs/scenes.md ``calibration.distance_error``), so every K, and
    every d_total measured with it, comes out too small by about that fraction.
    ``subsampled``: K for JPEG frames, whose edges the detector measures otherwise; the
    references are measured that way, so that a bias of that way common to both cancels
    (a small pencil's reference is measured on an enlarged film, :func:`reference_film`:
    a pixel-sized bias of the way then shrinks by the film's factor there; a 2.9 cm
    pencil of the ideal acceptance set read d_total 1.59 % off with its reference
    measured at the frame's own size, 0.36 % with it enlarged).

    Raises
    ------
    BadParameter
        A ``distance_error`` that is not a number within the scene key's bounds.
    """
    _check_distance_error(distance_error)
    key = calibration_key(camera, target_size, pencil_height, distance_error=distance_error,
                          subsampled=subsampled)
    found = None if refresh else read_entry("calibration", key, _check_entry)
    if found is not None:
        return Calibration(target_k=found["target_k"], pencil_k=found["pencil_k"], key=key)
    where = D_REF + distance_error
    s_t = measure_reference(camera, "target", tuple(target_size), variant=variant, distance=where,
                            subsampled=subsampled)
    s_p = measure_reference(camera, "beacon", pencil_height, variant=variant, distance=where,
                            subsampled=subsampled)
    cal = Calibration(target_k=s_t * (D_REF - FRONT_OFFSET["target"]),
                      pencil_k=s_p * (D_REF - FRONT_OFFSET["beacon"]), key=key)
    write_entry("calibration", key, {**cal.constants(),
                                     "target_px_at_100cm": s_t, "pencil_paint_px_at_100cm": s_p})
    return cal


def _check_entry(value: dict) -> None:
    """A cached calibration's numbers are finite, positive and consistent: each K is its
    measured pixel height times the reference distance (eq 5)."""
    for k_name, px_name, kind in (("target_k", "target_px_at_100cm", "target"),
                                  ("pencil_k", "pencil_paint_px_at_100cm", "beacon")):
        k, px = value[k_name], value[px_name]
        if not all(is_number(v) for v in (k, px)):
            raise TypeError(f"{k_name} and {px_name} must be numbers")
        if not (np.isfinite(k) and np.isfinite(px) and k > 0 and px > 0):
            raise ValueError(f"{k_name} = {k!r}, {px_name} = {px!r}: not positive numbers")
        if not np.isclose(k, px * (D_REF - FRONT_OFFSET[kind]), rtol=1e-9):
            raise ValueError(f"{k_name} = {k!r} does not follow from {px_name} = {px!r}")
