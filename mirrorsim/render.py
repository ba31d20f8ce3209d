"""Rendering a scene with Mitsuba 3: the frame, and an object-id pass through the mirror.

The only module that imports mitsuba and drjit.  The Mitsuba variant is chosen by
:mod:`mirrorsim.backend` and set inside :func:`mi.variant_context`, never at import.

World units are the scene's centimetres; the Mitsuba world frame is the board frame
(x right, y away from the front edge, z up).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mirrorsim import optics
from mirrorsim.backend import choose_variant
from mirrorsim.scene import (
    MIRROR_FRAME,
    OCCLUDER_THICKNESS,
    PENCIL_RADIUS,
    TARGET_THICKNESS,
    Scene,
)
from solver.geometry import line_normal, signed_distance, unit

# Labels of the object-id pass.  Beacons take BEACON_LABEL + i, occluders after them.
BACKGROUND_LABEL, MIRROR_LABEL, TARGET_LABEL, BEACON_LABEL = 0, 1, 2, 3

IN_MIRROR = 100  # ids.png: label + IN_MIRROR where the pixel sees it in the mirror
PASS_SPP = 4  # samples per render pass: one progress step each (no measurable cost)
BOARD_TEXELS_PER_CM = 24
# camera → mirror → object, with light sampled there: the shortest path that lights
# the mirror images (each extra bounce costs about as much again)
MAX_DEPTH = 3

# Linear-RGB reflectances (what Mitsuba's diffuse BSDF takes)
_COLOURS = {
    "board": (0.40, 0.27, 0.15),  # hardboard pegboard
    "hole": (0.015, 0.012, 0.01),
    "board_edge": (0.30, 0.20, 0.11),
    "target": (0.18, 0.18, 0.18),  # mid-grey panel (sRGB ≈ 118)
    "paint": (0.80, 0.50, 0.02),  # yellow pencil lacquer
    "wood": (0.60, 0.38, 0.20),
    "graphite": (0.03, 0.03, 0.03),
    "mirror_back": (0.02, 0.02, 0.02),
    "frame": (0.04, 0.04, 0.045),
    # Only the target is a neutral grey: walls, floor and occluders are coloured, so the
    # detector can find the panel by its (known) appearance.
    "occluder": (0.25, 0.38, 0.60),  # blue-painted walls
    "floor": (0.14, 0.20, 0.10),  # green linoleum
    "walls": (0.50, 0.38, 0.22),  # emitted radiance of the room map from here on: beige
    "panel": (0.10, 0.07, 0.05),
    "baseboard": (0.55, 0.55, 0.52),
    "ceiling": (0.90, 0.88, 0.82),
}


@dataclass(frozen=True)
class RenderResult:
    """What :func:`render_scene` wrote and measured."""

    png: Path
    truth_json: Path
    ids_png: Path
    truth: dict
    variant: str
    seconds: float


# ------------------------------------------------------------------ scene building


def _transform(x, y, z, origin) -> mi.ScalarTransform4f:
    """Affine map whose columns are the images of the unit axes, plus a translation."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    assert np.linalg.det(m[:3, :3]) > 0, "left-handed placement would flip normals"
    return mi.ScalarTransform4f(m)


def _diffuse(name: str) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(_COLOURS[name])}}


def _box(center3, ax, ay, az, bsdf: str | dict) -> dict:
    """A cube stretched along the half-extent vectors ax, ay, az (right-handed)."""
    return {"type": "cube", "to_world": _transform(ax, ay, az, center3),
            "bsdf": _diffuse(bsdf) if isinstance(bsdf, str) else bsdf}


def _v3(v2, z=0.0) -> np.ndarray:
    return np.array([v2[0], v2[1], z], dtype=float)


def _board_texture(scene: Scene) -> np.ndarray:
    """Pegboard albedo: a regular grid of dark round holes, anti-aliased."""
    sx, sy = scene.board.size
    nx, ny = (max(2, round(s * BOARD_TEXELS_PER_CM)) for s in (sx, sy))
    base = np.broadcast_to(np.array(_COLOURS["board"], np.float32), (ny, nx, 3)).copy()
    pitch = scene.board.hole_pitch
    if pitch <= 0:
        return base
    # texel centres in cm; row 0 is the far (y = sy) edge as textures run top-down
    x = (np.arange(nx) + 0.5) * sx / nx
    y = sy - (np.arange(ny) + 0.5) * sy / ny
    dx = (x - pitch / 2) % pitch - pitch / 2
    dy = (y - pitch / 2) % pitch - pitch / 2
    dist = np.hypot(dx[None, :], dy[:, None])
    hole = np.clip(0.5 + (scene.board.hole_diameter / 2 - dist) * BOARD_TEXELS_PER_CM, 0, 1)
    hole = hole[..., None].astype(np.float32)
    return base * (1 - hole) + np.array(_COLOURS["hole"], np.float32) * hole


def _room_envmap(width: int = 64) -> np.ndarray:
    """A latitude-longitude room: floor, walls with darker doors/shelves, bright ceiling.

    Rows run from straight up (row 0) to straight down; the map is rotated so that its
    pole is the world's +z.  Deterministic: no randomness.
    """
    h = width // 2
    elev = 90.0 - (np.arange(h) + 0.5) * 180.0 / h
    azim = (np.arange(width) + 0.5) * 360.0 / width
    env = np.empty((h, width, 3), np.float32)
    env[:] = np.array(_COLOURS["walls"], np.float32)
    panels = np.zeros(width, bool)
    for start, span in ((20, 25), (95, 15), (150, 40), (230, 20), (300, 30)):
        panels |= (azim - start) % 360.0 < span
    tall = (elev[:, None] < 25.0) & panels[None, :]
    env[tall] = np.array(_COLOURS["panel"], np.float32)
    env[(elev >= 0.0) & (elev < 2.0)] = np.array(_COLOURS["baseboard"], np.float32)
    env[elev >= 35.0] = np.array(_COLOURS["ceiling"], np.float32)
    env[elev < 0.0] = np.array(_COLOURS["floor"], np.float32)
    return env


def _pencil_meshes(position, height: float) -> dict[str, mi.Mesh]:
    """An upright hexagonal pencil: painted prism, sharpened wood cone, graphite tip."""
    cone, lead = min(1.2, 0.35 * height), min(0.3, 0.1 * height)
    angles = np.deg2rad(np.arange(6) * 60.0 + 30.0)

    def ring(radius: float, z: float) -> np.ndarray:
        return np.stack([position[0] + radius * np.cos(angles),
                         position[1] + radius * np.sin(angles), np.full(6, z)], axis=1)

    def band(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        verts = np.vstack([lower, upper])
        faces = []
        for k in range(6):
            k1 = (k + 1) % 6
            # counter-clockwise seen from outside: outward normals
            faces += [[k, k1, 6 + k1], [k, 6 + k1, 6 + k]]
        return verts, np.array(faces)

    def pyramid(base: np.ndarray, apex) -> tuple[np.ndarray, np.ndarray]:
        verts = np.vstack([base, apex])
        return verts, np.array([[k, (k + 1) % 6, 6] for k in range(6)])

    r_lead = PENCIL_RADIUS * 0.3
    parts = {
        "paint": band(ring(PENCIL_RADIUS, 0.0), ring(PENCIL_RADIUS, height - cone)),
        "wood": band(ring(PENCIL_RADIUS, height - cone), ring(r_lead, height - lead)),
        "graphite": pyramid(ring(r_lead, height - lead), [position[0], position[1], height]),
    }
    meshes = {}
    for part, (verts, faces) in parts.items():
        props = mi.Properties()
        props["bsdf"] = mi.load_dict(_diffuse(part))
        mesh = mi.Mesh(part, len(verts), len(faces), props=props, has_vertex_normals=False)
        params = mi.traverse(mesh)
        # the buffers' own types differ between scalar and JIT variants
        pos, idx = params["vertex_positions"], params["faces"]
        params["vertex_positions"] = type(pos)(verts.astype(np.float32).ravel())
        params["faces"] = type(idx)(faces.astype(np.uint32).ravel())
        params.update()
        meshes[part] = mesh
    return meshes


def build_scene_dict(scene: Scene, *, spp: int) -> dict:
    """The Mitsuba scene description (the variant must already be set).

    Shape keys are prefixed with the object they belong to (``mirror``, ``target``,
    ``beacon0``, ``occluder0``…), which is how the id pass labels pixels.
    """
    cam = scene.camera
    sx, sy = scene.board.size
    bc = _v3((sx / 2, sy / 2))
    zhat = np.array([0.0, 0.0, 1.0])
    forward, _, _ = optics.camera_axes(cam)
    d: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH},
        "sensor": {
            "type": "perspective",
            "fov": cam.hfov,
            "fov_axis": "x",
            "near_clip": 0.1,
            "far_clip": 10000.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=list(cam.center3), target=list(cam.center3 + forward), up=[0, 0, 1]),
            "sampler": {"type": "independent", "sample_count": spp},
            "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height_px,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        },
        # The room is an environment map (walls with doors and shelves, a bright
        # ceiling, a floor) plus an overhead area light: escaping paths end at one
        # texture lookup, several times cheaper than bouncing between real walls.
        "room": {"type": "envmap", "bitmap": mi.Bitmap(_room_envmap()),
                 "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], 90)},
        "room_floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f()
                       .translate(list(bc + [0, 0, -0.6])).scale([140, 140, 1]),
                       "bsdf": _diffuse("floor")},
        "room_light": {"type": "rectangle", "to_world": mi.ScalarTransform4f()
                       .translate(list(bc + [-20, -30, 150])).rotate([1, 0, 0], 180)
                       .scale([60, 60, 1]),
                       "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 6.0}}},
        "board_top": {"type": "rectangle",
                      "to_world": mi.ScalarTransform4f().translate(list(bc))
                      .scale([sx / 2, sy / 2, 1]),
                      "bsdf": {"type": "diffuse", "reflectance": {
                          "type": "bitmap", "bitmap": mi.Bitmap(_board_texture(scene)),
                          "raw": True}}},
        "board_slab": _box(bc - [0, 0, 0.3], [sx / 2, 0, 0], [0, sy / 2, 0], [0, 0, 0.299],
                           "board_edge"),
    }

    # Mirror: the reflective rectangle faces the camera; behind it a dark backing, and a
    # thin dark frame on its sides and top (outside the reflective area).
    m = scene.mirror
    w, h = m.size
    side = np.sign(signed_distance(cam.position, m.center, m.yaw))
    n = _v3(line_normal(m.yaw) * side)  # towards the camera
    along = np.array([-n[1], n[0], 0.0])  # so that along × z = n (right-handed)
    c = _v3(m.center)
    d["mirror_glass"] = {"type": "rectangle", "bsdf": {"type": "conductor"},
                         "to_world": _transform(along * w / 2, zhat * h / 2, n, c + zhat * h / 2)}
    d["mirror_back"] = _box(c + zhat * h / 2 - n * 0.21, n * 0.2, along * w / 2, zhat * h / 2,
                            "mirror_back")
    fw, depth = MIRROR_FRAME, 0.275  # frame front stands 0.05 proud of the glass
    for k, s in enumerate((-1, 1)):
        d[f"mirror_frame{k}"] = _box(c + along * s * (w + fw) / 2 + zhat * (h + fw) / 2
                                     - n * 0.225, n * depth, along * fw / 2,
                                     zhat * (h + fw) / 2, "frame")
    d["mirror_frame_top"] = _box(c + zhat * (h + fw / 2) - n * 0.225, n * depth,
                                 along * (w / 2 + fw), zhat * fw / 2, "frame")

    t = scene.target
    f = _v3(unit(t.facing_deg))
    a = _v3(unit(t.facing_deg + 90.0))
    d["target_panel"] = _box(_v3(t.position, t.size[1] / 2), f * TARGET_THICKNESS / 2,
                             a * t.size[0] / 2, zhat * t.size[1] / 2, "target")

    for i, b in enumerate(scene.beacons):
        for part, mesh in _pencil_meshes(b.position, b.height).items():
            d[f"beacon{i}_{part}"] = mesh

    for i, o in enumerate(scene.occluders):
        p0, p1 = np.asarray(o.start, float), np.asarray(o.end, float)
        u = _v3((p1 - p0) / 2)
        nn = _v3(line_normal(math.degrees(math.atan2(u[1], u[0])))) * OCCLUDER_THICKNESS / 2
        d[f"occluder{i}_wall"] = _box(_v3((p0 + p1) / 2, o.height / 2), u, nn,
                                      zhat * o.height / 2, "occluder")
    return d


def _label_of(key: str, n_beacons: int) -> int:
    """Id-pass label of a shape, from its key in :func:`build_scene_dict`."""
    if key == "mirror_glass":
        return MIRROR_LABEL
    if key.startswith("target"):
        return TARGET_LABEL
    if key.startswith("beacon"):
        return BEACON_LABEL + int(key[len("beacon"):].split("_")[0])
    if key.startswith("occluder"):
        return BEACON_LABEL + n_beacons + int(key[len("occluder"):].split("_")[0])
    return BACKGROUND_LABEL


# ------------------------------------------------------------------------ passes


def _render_frame(mi_scene, spp: int, seed: int, progress) -> np.ndarray:
    """Linear RGB, averaged over passes of PASS_SPP samples (one progress step each)."""
    passes = [PASS_SPP] * (spp // PASS_SPP) + ([spp % PASS_SPP] if spp % PASS_SPP else [])
    acc = None
    done = 0
    for k, n in enumerate(passes):
        # seeds are spaced so that passes of different renders never share one
        img = np.asarray(mi.render(mi_scene, spp=n, seed=seed * 65536 + k), dtype=np.float64)
        acc = img * n if acc is None else acc + img * n
        done += n
        progress(done / spp)
    return (acc / spp).astype(np.float32)


def id_pass(mi_scene, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Object ids at pixel centres: the first surface hit, and what the mirror shows.

    The ``aov`` integrator's ``shape_index`` only records the first hit, which for
    every pixel of the mirror is the mirror itself; so the id pass casts the camera
    ray, and where it meets the glass, the specularly reflected ray.

    Returns
    -------
    first, in_mirror : ndarray of uint8, shape (H, W)
        Labels (MIRROR_LABEL, TARGET_LABEL, BEACON_LABEL + i, …; 0 for anything else).
        ``in_mirror`` is 0 off the glass.
    """
    cam = scene.camera
    shapes = [(s, _label_of(s.id(), len(scene.beacons))) for s in mi_scene.shapes()]
    sensor = mi_scene.sensors()[0]
    cast = _id_pass_jit if dr.is_jit_v(mi.Float) else _id_pass_scalar
    return cast(mi_scene, sensor, shapes, cam.width, cam.height_px)


def _reflected_ray(ray, si):
    n = si.n
    return si.spawn_ray(ray.d - 2.0 * dr.dot(ray.d, n) * n)


def _id_pass_jit(mi_scene, sensor, shapes, W, H):
    idx = dr.arange(mi.UInt32, W * H)
    px = mi.Float(idx % W) + 0.5
    py = mi.Float(idx // W) + 0.5
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(px / W, py / H), mi.Point2f(0.5, 0.5))

    def labels(si):
        lab = mi.UInt32(BACKGROUND_LABEL)
        for shape, label in shapes:
            if label != BACKGROUND_LABEL:
                lab = dr.select(si.is_valid() & (si.shape == mi.ShapePtr(shape)), label, lab)
        return lab

    si = mi_scene.ray_intersect(ray)
    first = labels(si)
    on_glass = first == MIRROR_LABEL
    si2 = mi_scene.ray_intersect(_reflected_ray(ray, si), on_glass)
    second = dr.select(on_glass, labels(si2), BACKGROUND_LABEL)
    to_np = lambda a: np.asarray(a, dtype=np.uint8).reshape(H, W)  # noqa: E731
    return to_np(first), to_np(second)


def _id_pass_scalar(mi_scene, sensor, shapes, W, H):
    by_id = {s.id(): label for s, label in shapes}
    first = np.zeros((H, W), np.uint8)
    second = np.zeros_like(first)
    for j in range(H):
        for i in range(W):
            ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f((i + 0.5) / W, (j + 0.5) / H),
                                       mi.Point2f(0.5, 0.5))
            si = mi_scene.ray_intersect(ray)
            if not si.is_valid():
                continue
            lab = by_id.get(si.shape.id(), BACKGROUND_LABEL)
            first[j, i] = lab
            if lab == MIRROR_LABEL:
                si2 = mi_scene.ray_intersect(_reflected_ray(ray, si))
                if si2.is_valid():
                    second[j, i] = by_id.get(si2.shape.id(), BACKGROUND_LABEL)
    return first, second


def encode_ids(first: np.ndarray, in_mirror: np.ndarray) -> np.ndarray:
    """One uint8 image of both id maps: the direct label, or IN_MIRROR + the label that
    the mirror shows on the glass (so IN_MIRROR alone is glass showing the room)."""
    return np.where(first == MIRROR_LABEL, IN_MIRROR + in_mirror, first).astype(np.uint8)


def to_srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear RGB → 8-bit sRGB (IEC 61966-2-1 transfer curve), rounded."""
    x = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


# ----------------------------------------------------------------------- writing


def _mask_stats(mask: np.ndarray) -> tuple[list[int] | None, int]:
    vs, us = np.nonzero(mask)
    if len(us) == 0:
        return None, 0
    return [int(us.min()), int(vs.min()), int(us.max()), int(vs.max())], int(len(us))


def _write_png(path: Path, pixels: np.ndarray) -> None:
    bmp = mi.Bitmap(np.ascontiguousarray(pixels))
    bmp.set_srgb_gamma(pixels.ndim == 3)
    bmp.write(str(path))


def render_scene(
    scene: Scene,
    out_dir: str | Path | None = None,
    *,
    spp: int | None = None,
    seed: int | None = None,
    variant: str = "auto",
    progress: bool = True,
    fingerprint: str | None = None,
) -> RenderResult:
    """Render ``scene`` and write ``<name>.png``, ``<name>.json`` and ``<name>.ids.png``.

    Parameters
    ----------
    scene : Scene
        A validated scene.
    out_dir : path, optional
        Output folder (default ``renders/<name>``).  Files appear atomically: each is
        written to a temporary name and renamed once complete.
    spp, seed : int, optional
        Override the scene's ``render`` block.
    variant : {'auto', 'cuda', 'llvm', 'scalar'} or a Mitsuba variant name
    progress : bool
        Print a progress line on stderr.
    fingerprint : str, optional
        Recorded in the ground truth's ``render`` block (``evaluate`` reuses a render
        whose fingerprint matches).
    """
    spp = scene.render.spp if spp is None else spp
    seed = scene.render.seed if seed is None else seed
    if spp < 1 or seed < 0:
        raise ValueError(f"spp must be ≥ 1 and seed ≥ 0 (got spp={spp}, seed={seed})")
    out = Path(out_dir) if out_dir is not None else Path("renders") / scene.name
    chosen = choose_variant(variant)
    t0 = time.perf_counter()
    show = _Progress(f"rendering {scene.name} ({chosen}, {spp} spp)", enabled=progress)
    with _variant(chosen):
        mi_scene = mi.load_dict(build_scene_dict(scene, spp=spp), optimize=False)
        show(0.0)
        linear = _render_frame(mi_scene, spp, seed, show)
        t_render = time.perf_counter() - t0
        first, in_mirror = id_pass(mi_scene, scene)
    seconds = time.perf_counter() - t0
    show.done(f"{seconds:.1f} s")

    truth = optics.ground_truth(scene)
    for entry, label in [(truth["target"], TARGET_LABEL)] + [
        (b, BEACON_LABEL + i) for i, b in enumerate(truth["beacons"])
    ]:
        entry["bbox_px"], entry["visible_px"] = _mask_stats(in_mirror == label)
    truth["mirror"]["bbox_px"], truth["mirror"]["visible_px"] = _mask_stats(first == MIRROR_LABEL)
    truth["id_labels"] = {"background": BACKGROUND_LABEL, "mirror": MIRROR_LABEL,
                          "target": TARGET_LABEL, "beacons": BEACON_LABEL,
                          "occluders": BEACON_LABEL + len(scene.beacons),
                          "seen_in_mirror_offset": IN_MIRROR}
    truth["render"] = {"variant": chosen, "spp": spp, "seed": seed,
                       "seconds_render": round(t_render, 3), "seconds_total": round(seconds, 3),
                       "mitsuba": mi.__version__, "fingerprint": fingerprint}

    out.mkdir(parents=True, exist_ok=True)
    files = {
        out / f"{scene.name}.png": to_srgb8(linear),
        out / f"{scene.name}.ids.png": encode_ids(first, in_mirror),
    }
    tmp_paths = []
    try:
        for path, pixels in files.items():
            tmp = path.with_name(f".{path.name}.tmp{os.getpid()}.png")
            _write_png(tmp, pixels)
            tmp_paths.append((tmp, path))
        json_path = out / f"{scene.name}.json"
        tmp = json_path.with_name(f".{json_path.name}.tmp{os.getpid()}")
        tmp.write_text(json.dumps(truth, indent=2) + "\n")
        tmp_paths.append((tmp, json_path))
        for tmp, path in tmp_paths:
            os.replace(tmp, path)
    finally:
        for tmp, _ in tmp_paths:
            tmp.unlink(missing_ok=True)
    return RenderResult(png=out / f"{scene.name}.png", truth_json=json_path,
                        ids_png=out / f"{scene.name}.ids.png", truth=truth, variant=chosen,
                        seconds=seconds)


@contextlib.contextmanager
def _variant(name: str):
    """Scope the process-global Mitsuba variant (variant_context needs a previous one)."""
    if mi.variant() is None:
        mi.set_variant(name)
        yield
    else:
        with mi.variant_context(name):
            yield


class _Progress:
    """A one-line progress display on stderr with elapsed time and ETA."""

    def __init__(self, label: str, enabled: bool = True):
        self.label, self.enabled = label, enabled
        self.t0 = time.perf_counter()

    def __call__(self, fraction: float) -> None:
        if not self.enabled:
            return
        el = time.perf_counter() - self.t0
        eta = f", ~{el / fraction * (1 - fraction):.0f} s left" if fraction > 0.05 else ""
        bar = "#" * int(20 * fraction)
        sys.stderr.write(f"\r{self.label} [{bar:<20}] {100 * fraction:3.0f}% {el:.1f} s{eta}  ")
        sys.stderr.flush()

    def done(self, message: str) -> None:
        if self.enabled:
            sys.stderr.write(f"\r{self.label}: done in {message}{' ' * 30}\n")
            sys.stderr.flush()


def render_reference(camera, kind: str, size: tuple[float, float] | float, *,
                     distance: float = 100.0, spp: int = 64, variant: str = "auto",
                     margin_px: int = 24) -> np.ndarray:
    """An object seen directly, facing the camera on its optical axis at ``distance``.

    For size-constancy calibration: ``kind`` is ``"target"`` (size = (width, height))
    or ``"pencil"`` (size = its height).  Only the object's neighbourhood is rendered
    (a film crop); the camera model is the given one.  Returns the crop as 8-bit sRGB.
    """
    from mirrorsim.scene import Beacon, Board, Camera, Mirror, RenderSettings, Target

    pan = 45.0
    cam = Camera(position=(0.0, 0.0), height=camera.height, resolution=camera.resolution,
                 hfov=camera.hfov, pan=pan, pan_deg=pan)
    p = tuple(distance * unit(pan))
    behind = (-25.0, -5.0)  # what the reference does not show stands behind the camera
    if kind == "target":
        w, h = size
        target = Target(position=p, size=(w, h), facing_deg=pan + 180.0)
        beacons: tuple = ()
        half_w, top = w / 2, h
    elif kind == "pencil":
        target = Target(position=behind, size=(9.9, 15.25), facing_deg=pan)
        beacons = (Beacon(position=p, height=float(size)),)
        half_w, top = PENCIL_RADIUS, float(size)
    else:
        raise ValueError(f"unknown reference object {kind!r}")
    # a plain board: a hole under the reference object's foot would bias its calibration
    scene = Scene(name=f"reference-{kind}", board=Board(size=(80.0, 80.0), hole_pitch=0.0),
                  camera=cam,
                  mirror=Mirror(center=(-10.0, -20.0), yaw=0.0, size=(18.2, 13.25)),
                  target=target, beacons=beacons, render=RenderSettings(spp=spp))
    pts = np.array([[*(np.array(p) + s * half_w * unit(pan + 90)), z]
                    for s in (-1, 1) for z in (0.0, top)])
    u, v, _ = optics.project(cam, pts)
    u0 = int(max(0, math.floor(u.min()) - margin_px))
    v0 = int(max(0, math.floor(v.min()) - margin_px))
    u1 = int(min(cam.width, math.ceil(u.max()) + margin_px + 1))
    v1 = int(min(cam.height_px, math.ceil(v.max()) + margin_px + 1))
    chosen = choose_variant(variant)
    with _variant(chosen):
        d = build_scene_dict(scene, spp=spp)
        d["sensor"]["film"].update({"crop_offset_x": u0, "crop_offset_y": v0,
                                    "crop_width": u1 - u0, "crop_height": v1 - v0})
        mi_scene = mi.load_dict(d, optimize=False)
        linear = _render_frame(mi_scene, spp, 0, lambda f: None)
    return to_srgb8(linear)
