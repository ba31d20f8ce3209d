"""Scene translation: a :class:`~mirrorsim.scene.model.Scene` as a Mitsuba 3 scene description.

Materials, the pegboard texture, the room's environment map and the pencil meshes live
here; :mod:`mirrorsim.rendering.passes` loads the description and renders it.  The Mitsuba
variant must be set by the caller (:func:`mirrorsim.rendering.passes.variant_scope`).

World units are the scene's centimetres; the Mitsuba world frame is the board frame
(x right, y away from the front edge, z up) moved so that a scene's glass centre is the
origin (see :func:`_recentred`).
"""

from __future__ import annotations

import functools
import math

import mitsuba as mi
import numpy as np

from mirrorsim.rendering.shapes import (
    COLOURS,
    ZHAT,
    box_shape,
    ceiling_light,
    diffuse,
    mirror_shapes,
    pencil_shapes,
    target_shapes,
    v3,
)
from mirrorsim.scene.model import OCCLUDER_THICKNESS, Beacon, Board, Camera, Scene, Target
from mirrorsim.scene.projection import camera_axes, hfov_of
from mirrorsim.truth import visibility
from solver.geometry import line_normal

# Labels of the object-id pass.  Beacons take BEACON_LABEL + i, occluders after them.
BACKGROUND_LABEL, MIRROR_LABEL, TARGET_LABEL, BEACON_LABEL = 0, 1, 2, 3
BOARD_TEXELS_PER_CM = 24
# camera → mirror → object, with light sampled there: the shortest path that lights
# the mirror images (each extra bounce costs about as much again)
MAX_DEPTH = 3


def _board_texture(board: Board) -> np.ndarray:
    """Pegboard albedo: a regular grid of dark round holes, anti-aliased (made once per
    board and process, as :func:`_board_bitmap`)."""
    sx, sy = board.size
    nx, ny = (max(2, round(s * BOARD_TEXELS_PER_CM)) for s in (sx, sy))
    base = np.broadcast_to(np.array(COLOURS["board"], np.float32), (ny, nx, 3))
    pitch = board.hole_pitch
    if pitch <= 0:
        return base.copy()
    # texel centres in cm, y counted down from the far edge (y = sy); the board's mesh
    # puts the bitmap's row 0 at its near edge (y = 0), so the rendered holes sit at
    # whole pitches from the far edge (Board.hole_centres; tests/test_board.py)
    x = (np.arange(nx) + 0.5) * sx / nx
    y = sy - (np.arange(ny) + 0.5) * sy / ny
    dx = (x - pitch / 2) % pitch - pitch / 2
    dy = (y - pitch / 2) % pitch - pitch / 2
    # the grid repeats: each distinct (dx, dy) pair is computed once, then its columns
    # and rows copied out (the same floats as computing every texel, several times
    # faster where the pitch is a whole number of texels, as on the default board)
    ux, ix = np.unique(dx, return_inverse=True)
    uy, iy = np.unique(dy, return_inverse=True)
    if len(ux) * len(uy) * 16 > nx * ny:  # a pitch of no whole number of texels: no repeats
        ux, ix, uy, iy = dx, np.arange(nx), dy, np.arange(ny)
    dist = np.hypot(ux[None, :], uy[:, None])
    hole = np.clip(0.5 + (board.hole_diameter / 2 - dist) * BOARD_TEXELS_PER_CM, 0, 1)
    hole = hole[..., None].astype(np.float32)
    cell = base[:len(uy), :len(ux)] * (1 - hole) + np.array(COLOURS["hole"], np.float32) * hole
    return np.take(np.take(cell, ix, axis=1), iy, axis=0)


@functools.lru_cache(maxsize=8)
def _board_bitmap(board: Board) -> mi.Bitmap:
    """The pegboard texture as a Mitsuba bitmap, made once per board: making one copies
    the 1920² texture (19 ms a scene).  A ``raw`` bitmap texture of an RGB variant (ours)
    copies its bitmap's data and leaves the bitmap as it was (checked in Mitsuba 3.9), so
    scenes can share it; a spectral variant's non-raw texture would convert it in place."""
    return mi.Bitmap(_board_texture(board))


@functools.lru_cache(maxsize=1)
def _room_envmap(width: int = 64) -> np.ndarray:
    """A latitude-longitude room: floor, walls with darker doors/shelves, bright ceiling.

    Rows run from straight up (row 0) to straight down; the map is rotated so that its
    pole is the world's +z.  Deterministic: no randomness.
    """
    h = width // 2
    elev = 90.0 - (np.arange(h) + 0.5) * 180.0 / h
    azim = (np.arange(width) + 0.5) * 360.0 / width
    env = np.empty((h, width, 3), np.float32)
    env[:] = np.array(COLOURS["walls"], np.float32)
    panels = np.zeros(width, bool)
    for start, span in ((20, 25), (95, 15), (150, 40), (230, 20), (300, 30)):
        panels |= (azim - start) % 360.0 < span
    tall = (elev[:, None] < 25.0) & panels[None, :]
    env[tall] = np.array(COLOURS["panel"], np.float32)
    env[(elev >= 0.0) & (elev < 2.0)] = np.array(COLOURS["baseboard"], np.float32)
    env[elev >= 35.0] = np.array(COLOURS["ceiling"], np.float32)
    env[elev < 0.0] = np.array(COLOURS["floor"], np.float32)
    return env


def build_scene_dict(scene: Scene, tiles: tuple[int, ...] = ()) -> dict:
    """The Mitsuba scene description with the scene's sampler and spp (the variant must
    already be set).

    Shape keys are prefixed with the object they belong to (``mirror``, ``target``,
    ``beacon0``, ``occluder0``…), which is how the id pass labels pixels.  Each size T
    of ``tiles`` adds a sensor ``sensor_tile<T>``: the same camera with a T × T film and
    the full film's focal length, aimed at any T × T window of the full film by its
    principal point (:func:`aim_tile`).  Its kernel depends on T alone, so one compiled
    kernel serves every window of every scene (a film crop's offset and size were
    compiled in: a new kernel for each new scene's mirror and beacon boxes).
    """
    d = _stage(scene.board, scene.camera, scene.render.spp, scene.render.sampler, scene.bench.pitch,
               scene.bench.roll)
    for t in tiles:
        d[f"sensor_tile{t}"] = _tile_sensor(d["sensor"], scene.camera, t)
    d.update(mirror_shapes(scene))
    d.update(target_shapes(scene.target))
    for i, b in enumerate(scene.beacons):
        d.update(pencil_shapes(i, b))
    for i, o in enumerate(scene.occluders):
        p0, p1 = np.asarray(o.start, float), np.asarray(o.end, float)
        u = v3((p1 - p0) / 2)
        nn = v3(line_normal(math.degrees(math.atan2(u[1], u[0])))) * OCCLUDER_THICKNESS / 2
        d[f"occluder{i}_wall"] = box_shape(v3((p0 + p1) / 2, o.height / 2),
                                           (u, nn, ZHAT * o.height / 2), "occluder")
    return _recentred(d, visibility.glass_frame(scene)[0])


# Mitsuba spawns each reflected ray (1 + max|p|)·2⁻²⁴·1500 off the surface along its
# normal (Interaction::offset_p; p in world units).  In the board frame the glass stands
# 30–70 cm from the origin, so every mirror image was drawn as if 0.005 cm nearer the
# camera: 0.04–0.07 px sideways at the default scene's angles (a steady target α error of
# −0.0015°).  With the glass's centre at the world origin the offset is at most
# (1 + half the glass's diagonal)·8.9e-5 cm, and ~0 near its centre.
def _recentred(d: dict, origin: np.ndarray) -> dict:
    """The scene description ``d`` moved by −``origin`` (sensors, shapes and meshes;
    the environment map, which is directions only, stays)."""
    shift = mi.ScalarTransform4f().translate([-float(c) for c in origin])
    out = {}
    for key, item in d.items():
        if isinstance(item, mi.Mesh):
            params = mi.traverse(item)
            pos = np.array(params["vertex_positions"]).reshape(-1, 3) - origin
            params["vertex_positions"] = type(params["vertex_positions"])(
                pos.astype(np.float32).ravel())
            params.update()
        elif isinstance(item, dict) and "to_world" in item and item.get("type") != "envmap":
            item = {**item, "to_world": shift @ item["to_world"]}
        out[key] = item
    return out


def build_direct_dict(board: Board, camera: Camera, obj: Target | Beacon, *, spp: int,
                      crop: tuple[int, int, int, int] | None = None) -> dict:
    """One object on the board, seen directly (no mirror): calibration's reference.

    ``crop`` = (u0, v0, u1, v1) renders only that part of the film.
    """
    d = _stage(board, camera, spp, "independent")
    # no room floor: its far edge, 2.4 m off, lies just behind a reference panel's top
    # where the camera stands 6.4 cm above it (at 1 m), and its darker strip there read
    # as the panel (K 0.4-1.0 % high, every d_total as much too long); the room map's
    # floor behind the reference is uniform
    del d["room_floor"]
    d.update(target_shapes(obj) if isinstance(obj, Target) else pencil_shapes(0, obj))
    if crop is not None:
        d["sensor"] = _cropped(d["sensor"], crop)
    return d


def _tile_sensor(sensor: dict, cam: Camera, t: int) -> dict:
    """A copy of a sensor description with a t × t film and the same pixel size."""
    fov = hfov_of(t, cam.fx)
    return {**sensor, "fov": fov, "sampler": dict(sensor["sampler"]),
            "film": {**sensor["film"], "width": t, "height": t}}


def aim_tile(params: mi.SceneParameters, cam: Camera, t: int, *, u0: int, v0: int) -> None:
    """Aim a tile sensor (its ``mi.traverse`` parameters) at the full film's window with
    top-left pixel (u0, v0): the full film's optical axis, at (W/2, H/2), falls at
    (W/2 − u0, H/2 − v0) of the tile, so that tile pixel (i, j) is film pixel
    (u0 + i, v0 + j).  Mitsuba's offset is in tile sizes, from the tile's centre, with
    the opposite sign (checked: a tile renders the crop of the same window bit for bit
    at the same seed)."""
    params["principal_point_offset_x"] = (u0 + t / 2.0 - cam.width / 2.0) / t
    params["principal_point_offset_y"] = (v0 + t / 2.0 - cam.height_px / 2.0) / t
    params.update()


def _cropped(sensor: dict, crop: tuple[int, int, int, int]) -> dict:
    """A copy of a sensor description that renders only the film's ``crop``."""
    u0, v0, u1, v1 = crop
    film = {**sensor["film"], "crop_offset_x": u0, "crop_offset_y": v0,
            "crop_width": u1 - u0, "crop_height": v1 - v0}
    return {**sensor, "sampler": dict(sensor["sampler"]), "film": film}




def _stage(board: Board, cam: Camera, spp: int, sampler: str, pitch: float = 0.0,
           roll: float = 0.0) -> dict:
    """Integrator, camera (as it stands: a bench's pitch and roll), room, light and the
    board: everything but the objects."""
    sx, sy = board.size
    bc = v3((sx / 2, sy / 2))
    forward, _, down = camera_axes(cam, pitch, roll)
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": MAX_DEPTH},
        "sensor": {
            "type": "perspective",
            "fov": cam.hfov,
            "fov_axis": "x",
            "near_clip": 0.1,
            "far_clip": 10000.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=list(cam.center3), target=list(cam.center3 + forward), up=list(-down)),
            "sampler": {"type": sampler, "sample_count": spp},
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
                       "bsdf": diffuse("floor")},
        "room_light": ceiling_light(bc + [-20, -30, 150], 60.0, 6.0),
        "board_top": {"type": "rectangle",
                      "to_world": mi.ScalarTransform4f().translate(list(bc))
                      .scale([sx / 2, sy / 2, 1]),
                      "bsdf": {"type": "diffuse", "reflectance": {
                          "type": "bitmap", "bitmap": _board_bitmap(board),
                          "raw": True}}},
        "board_slab": box_shape(bc - [0, 0, 0.3], ([sx / 2, 0, 0], [0, sy / 2, 0], [0, 0, 0.299]),
                           "board_edge"),
    }


def label_of(key: str, n_beacons: int) -> int:
    """Id-pass label of a shape, from its key in :func:`build_scene_dict`."""
    if key == "mirror_glass":
        return MIRROR_LABEL
    if key.endswith("_stand"):  # what holds a raised object is not the object
        return BACKGROUND_LABEL
    if key.startswith("target"):
        return TARGET_LABEL
    if key.startswith("beacon"):
        return BEACON_LABEL + int(key[len("beacon"):].split("_")[0])
    if key.startswith("occluder"):
        return BEACON_LABEL + n_beacons + int(key[len("occluder"):].split("_")[0])
    return BACKGROUND_LABEL
