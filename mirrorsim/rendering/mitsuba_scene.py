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

from mirrorsim.scene.model import (
    MIRROR_FRAME,
    MIRROR_LIP,
    OCCLUDER_THICKNESS,
    PENCIL_RADIUS,
    TARGET_THICKNESS,
    Beacon,
    Board,
    Camera,
    Scene,
    Target,
    camera_axes,
    hfov_of,
    pencil_paint_height,
)
from mirrorsim.truth import visibility
from solver.geometry import line_normal, unit

# Labels of the object-id pass.  Beacons take BEACON_LABEL + i, occluders after them.
BACKGROUND_LABEL, MIRROR_LABEL, TARGET_LABEL, BEACON_LABEL = 0, 1, 2, 3
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


def _board_texture(board: Board) -> np.ndarray:
    """Pegboard albedo: a regular grid of dark round holes, anti-aliased (made once per
    board and process, as :func:`_board_bitmap`)."""
    sx, sy = board.size
    nx, ny = (max(2, round(s * BOARD_TEXELS_PER_CM)) for s in (sx, sy))
    base = np.broadcast_to(np.array(_COLOURS["board"], np.float32), (ny, nx, 3))
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
    cell = base[:len(uy), :len(ux)] * (1 - hole) + np.array(_COLOURS["hole"], np.float32) * hole
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
    cone, lead = height - pencil_paint_height(height), min(0.3, 0.1 * height)
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
    d.update(_mirror_shapes(scene))
    d.update(_target_shapes(scene.target))
    for i, b in enumerate(scene.beacons):
        d.update(_pencil_shapes(i, b))
    for i, o in enumerate(scene.occluders):
        p0, p1 = np.asarray(o.start, float), np.asarray(o.end, float)
        u = _v3((p1 - p0) / 2)
        nn = _v3(line_normal(math.degrees(math.atan2(u[1], u[0])))) * OCCLUDER_THICKNESS / 2
        d[f"occluder{i}_wall"] = _box(_v3((p0 + p1) / 2, o.height / 2), u, nn,
                                      ZHAT * o.height / 2, "occluder")
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
    d.update(_target_shapes(obj) if isinstance(obj, Target) else _pencil_shapes(0, obj))
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


ZHAT = np.array([0.0, 0.0, 1.0])


def _stage(board: Board, cam: Camera, spp: int, sampler: str, pitch: float = 0.0,
           roll: float = 0.0) -> dict:
    """Integrator, camera (as it stands: a bench's pitch and roll), room, light and the
    board: everything but the objects."""
    sx, sy = board.size
    bc = _v3((sx / 2, sy / 2))
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
                       "bsdf": _diffuse("floor")},
        "room_light": _ceiling_light(bc + [-20, -30, 150], 60.0, 6.0),
        "board_top": {"type": "rectangle",
                      "to_world": mi.ScalarTransform4f().translate(list(bc))
                      .scale([sx / 2, sy / 2, 1]),
                      "bsdf": {"type": "diffuse", "reflectance": {
                          "type": "bitmap", "bitmap": _board_bitmap(board),
                          "raw": True}}},
        "board_slab": _box(bc - [0, 0, 0.3], [sx / 2, 0, 0], [0, sy / 2, 0], [0, 0, 0.299],
                           "board_edge"),
    }


def _ceiling_light(centre, half: float, radiance: float) -> mi.Mesh:
    """A square area light facing down, as a two-triangle mesh.

    A mesh and not a ``rectangle``: a rectangle's transform is compiled into the
    render kernels as constants, and the light moves with every scene (the world is
    centred on the glass), so each new scene compiled its whole-film kernel again
    (0.4–0.5 s); a mesh's vertices are data, and the kernel is reused.
    """
    x, y, z = (float(v) for v in centre)
    verts = np.array([[x - half, y - half, z], [x + half, y - half, z],
                      [x + half, y + half, z], [x - half, y + half, z]], np.float32)
    faces = np.array([[0, 2, 1], [0, 3, 2]], np.uint32)  # clockwise from above: facing down
    props = mi.Properties()
    props["emitter"] = mi.load_dict({"type": "area",
                                     "radiance": {"type": "rgb", "value": radiance}})
    mesh = mi.Mesh("room_light", 4, 2, props=props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = type(params["vertex_positions"])(verts.ravel())
    params["faces"] = type(params["faces"])(faces.ravel())
    params.update()
    return mesh


def _mirror_shapes(scene: Scene) -> dict:
    """The reflective surface facing the camera; behind it a dark backing, and a thin
    dark frame on its sides and top (outside the reflective area).

    A bench's mirror may lean back (``tilt``: the whole assembly turns about its bottom
    edge) and be spherical (``curvature_radius``: the glass is a finely tessellated cap
    with the sphere's normals at its vertices, see :func:`_spherical_glass`).
    """
    m, bench = scene.mirror, scene.bench
    w, h = m.size
    g, along, up, n = visibility.glass_frame(scene)
    c = g - up * h / 2  # the middle of its bottom edge
    back = 0.0  # how far the curved glass's rim stands behind its centre
    if bench.curvature_radius is None:
        glass = {"type": "rectangle", "bsdf": {"type": "conductor"},
                 "to_world": _transform(along * w / 2, up * h / 2, n, c + up * h / 2)}
    else:
        glass, sag = _spherical_glass(c + up * h / 2, along, up, n, m.size,
                                      bench.curvature_radius)
        back = max(0.0, -sag.min())
    d = {"mirror_glass": glass,
         "mirror_back": _box(c + up * h / 2 - n * (0.21 + back), n * 0.2, along * w / 2,
                             up * h / 2, "mirror_back")}
    # the frame runs from 0.5 behind the glass's rim to MIRROR_LIP before it
    fw, depth = MIRROR_FRAME, (0.5 + MIRROR_LIP) / 2
    mid = visibility.frame_front(scene) - depth
    for k, s in enumerate((-1, 1)):
        d[f"mirror_frame{k}"] = _box(c + along * s * (w + fw) / 2 + up * (h + fw) / 2
                                     + n * mid, n * depth, along * fw / 2,
                                     up * (h + fw) / 2, "frame")
    d["mirror_frame_top"] = _box(c + up * (h + fw / 2) + n * mid, n * depth,
                                 along * (w / 2 + fw), up * fw / 2, "frame")
    return d


GLASS_CELL_CM = 0.25  # tessellation of a curved mirror: chord error cell²/(8R) < 1e-5 cm


def _spherical_glass(centre, along, up, n, size, radius: float) -> tuple[mi.Mesh, np.ndarray]:
    """A spherical cap over the mirror's rectangle, tangent to its plane at ``centre``:
    the centre of curvature at centre + radius·n (radius > 0: on the camera's side,
    concave).  Vertex normals are the sphere's, which is exact under interpolation: a
    sphere's normal (C − P)/R is linear in P.  Returns the mesh and each vertex's sag
    (its offset along n, cm)."""
    w, h = size
    na, nb = (max(2, math.ceil(s / GLASS_CELL_CM) + 1) for s in (w, h))
    a, b = np.meshgrid(np.linspace(-w / 2, w / 2, na), np.linspace(-h / 2, h / 2, nb))
    a, b = a.ravel(), b.ravel()
    sag = visibility.sag(a, b, radius)
    verts = centre + np.outer(a, along) + np.outer(b, up) + np.outer(sag, n)
    normals = (np.outer(-a, along) + np.outer(-b, up) + np.outer(radius - sag, n)) / radius
    faces = []
    for j in range(nb - 1):
        for i in range(na - 1):
            k = j * na + i  # counter-clockwise seen from the camera: along × up = n
            faces += [[k, k + 1, k + na + 1], [k, k + na + 1, k + na]]
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "conductor"})
    mesh = mi.Mesh("mirror_glass", len(verts), len(faces), props=props,
                   has_vertex_normals=True)
    params = mi.traverse(mesh)
    for key, arr, dtype in (("vertex_positions", verts, np.float32),
                            ("vertex_normals", normals, np.float32),
                            ("faces", np.asarray(faces), np.uint32)):
        params[key] = type(params[key])(arr.astype(dtype).ravel())
    params.update()
    return mesh, sag


def _target_shapes(t: Target) -> dict:
    f = _v3(unit(t.facing_deg))
    a = _v3(unit(t.facing_deg + 90.0))
    return {"target_panel": _box(_v3(t.position, t.size[1] / 2), f * TARGET_THICKNESS / 2,
                                 a * t.size[0] / 2, ZHAT * t.size[1] / 2, "target")}


def _pencil_shapes(i: int, b: Beacon) -> dict:
    return {f"beacon{i}_{part}": mesh
            for part, mesh in _pencil_meshes(b.position, b.height).items()}


def label_of(key: str, n_beacons: int) -> int:
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
