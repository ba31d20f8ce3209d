"""The objects as Mitsuba shapes: their materials, the pencils' meshes, the glass (flat
or curved) in its frame, the target panel and the ceiling's light.
:mod:`mirrorsim.rendering.mitsuba_scene` places them in a scene."""

from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

from mirrorsim.scene.model import (
    MIRROR_FRAME,
    MIRROR_LIP,
    PENCIL_RADIUS,
    STAND_RADIUS,
    TARGET_THICKNESS,
    Beacon,
    Scene,
    Target,
    pencil_paint_height,
)
from mirrorsim.truth import visibility
from solver.geometry import unit

ZHAT = np.array([0.0, 0.0, 1.0])

# Linear-RGB reflectances (what Mitsuba's diffuse BSDF takes)
COLOURS = {
    "board": (0.40, 0.27, 0.15),  # hardboard pegboard
    "hole": (0.015, 0.012, 0.01),
    "board_edge": (0.30, 0.20, 0.11),
    "target": (0.18, 0.18, 0.18),  # mid-grey panel (sRGB ≈ 118)
    "paint": (0.80, 0.50, 0.02),  # yellow pencil lacquer
    "wood": (0.60, 0.38, 0.20),
    "graphite": (0.03, 0.03, 0.03),
    "mirror_back": (0.02, 0.02, 0.02),
    "frame": (0.04, 0.04, 0.045),
    # a raised object's post, thinner than the pencil and below its paint.  A pencil's
    # is dark steel (its foot measures on it as on the board: 0.2 σ of elevation on the
    # development scenes; a teal one read it 5 σ low); the panel's is painted teal, a
    # colour nothing else has, so that its foot stands against it as against the board
    # (a dark one continued the panel's grey below its foot, read 2 px low)
    "stand": (0.06, 0.06, 0.065),
    "panel_stand": (0.02, 0.25, 0.30),
    # Only the target is a neutral grey: walls, floor and occluders are coloured, so the
    # detector can find the panel by its (known) appearance.
    "occluder": (0.25, 0.38, 0.60),  # blue-painted walls
    "floor": (0.14, 0.20, 0.10),  # green linoleum
    "walls": (0.50, 0.38, 0.22),  # emitted radiance of the room map from here on: beige
    "panel": (0.10, 0.07, 0.05),
    "baseboard": (0.55, 0.55, 0.52),
    "ceiling": (0.90, 0.88, 0.82),
}


def _placed(x, y, z, origin) -> mi.ScalarTransform4f:
    """Affine map whose columns are the images of the unit axes, plus a translation."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    assert np.linalg.det(m[:3, :3]) > 0, "left-handed placement would flip normals"
    return mi.ScalarTransform4f(m)


def diffuse(name: str) -> dict:
    """Mitsuba's diffuse BSDF of one of :data:`COLOURS`."""
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(COLOURS[name])}}


def box_shape(center3: np.ndarray, axes: tuple[np.ndarray, np.ndarray, np.ndarray],
              bsdf: str | dict) -> dict:
    """A cube stretched along the half-extent vectors ``axes`` (right-handed)."""
    return {"type": "cube", "to_world": _placed(*axes, center3),
            "bsdf": diffuse(bsdf) if isinstance(bsdf, str) else bsdf}


def v3(v2: np.ndarray | tuple[float, float], z: float = 0.0) -> np.ndarray:
    """A board point (x, y) at height ``z``."""
    return np.array([v2[0], v2[1], z], dtype=float)


def pencil_meshes(position: tuple[float, float] | np.ndarray, height: float, z0: float = 0.0
                  ) -> dict[str, mi.Mesh]:
    """An upright hexagonal pencil, its foot ``z0`` above the board: painted prism,
    sharpened wood cone, graphite tip."""
    cone, lead = height - pencil_paint_height(height), min(0.3, 0.1 * height)
    angles = np.deg2rad(np.arange(6) * 60.0 + 30.0)

    def ring(radius: float, z: float) -> np.ndarray:
        return np.stack([position[0] + radius * np.cos(angles),
                         position[1] + radius * np.sin(angles), np.full(6, z0 + z)], axis=1)

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
        "graphite": pyramid(ring(r_lead, height - lead),
                            [position[0], position[1], z0 + height]),
    }
    meshes = {}
    for part, (verts, faces) in parts.items():
        props = mi.Properties()
        props["bsdf"] = mi.load_dict(diffuse(part))
        mesh = mi.Mesh(part, len(verts), len(faces), props=props, has_vertex_normals=False)
        params = mi.traverse(mesh)
        # the buffers' own types differ between scalar and JIT variants
        pos, idx = params["vertex_positions"], params["faces"]
        params["vertex_positions"] = type(pos)(verts.astype(np.float32).ravel())
        params["faces"] = type(idx)(faces.astype(np.uint32).ravel())
        params.update()
        meshes[part] = mesh
    return meshes


def ceiling_light(centre: np.ndarray, half: float, radiance: float) -> mi.Mesh:
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


def mirror_shapes(scene: Scene) -> dict:
    """The reflective surface facing the camera; behind it a dark backing, and a thin
    dark frame on its sides and top (outside the reflective area).

    A bench's mirror may lean back (``tilt``: the whole assembly turns about its bottom
    edge) and be spherical (``curvature_radius``: the glass is a finely tessellated cap
    with the sphere's normals at its vertices, see :func:`spherical_glass`).
    """
    m, bench = scene.mirror, scene.bench
    w, h = m.size
    g, along, up, n = visibility.glass_frame(scene)
    c = g - up * h / 2  # the middle of its bottom edge
    back = 0.0  # how far the curved glass's rim stands behind its centre
    if bench.curvature_radius is None:
        glass = {"type": "rectangle", "bsdf": {"type": "conductor"},
                 "to_world": _placed(along * w / 2, up * h / 2, n, c + up * h / 2)}
    else:
        glass, sag = _spherical_glass(c + up * h / 2, along, up, n, m.size,
                                      bench.curvature_radius)
        back = max(0.0, -sag.min())
    d = {"mirror_glass": glass,
         "mirror_back": box_shape(c + up * h / 2 - n * (0.21 + back), (n * 0.2, along * w / 2,
                             up * h / 2), "mirror_back")}
    # the frame runs from 0.5 behind the glass's rim to MIRROR_LIP before it
    fw, depth = MIRROR_FRAME, (0.5 + MIRROR_LIP) / 2
    mid = visibility.frame_front(scene) - depth
    for k, s in enumerate((-1, 1)):
        d[f"mirror_frame{k}"] = box_shape(c + along * s * (w + fw) / 2 + up * (h + fw) / 2
                                     + n * mid, (n * depth, along * fw / 2,
                                     up * (h + fw) / 2), "frame")
    d["mirror_frame_top"] = box_shape(c + up * (h + fw / 2) + n * mid, (n * depth,
                                 along * (w / 2 + fw), up * fw / 2), "frame")
    if m.z > 0.0:  # a raised mirror's pedestal, behind its bottom edge: it shows nothing
        n0 = np.array([n[0], n[1], 0.0]) / math.hypot(n[0], n[1])
        d["mirror_pedestal"] = box_shape(np.r_[c[:2], m.z / 2] - n0 * 0.31,
                                         (n0 * 0.3, along * (w / 2 + fw), ZHAT * m.z / 2),
                                         "frame")
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


def target_shapes(t: Target) -> dict:
    """The target panel: a grey slab facing ``t.facing_deg``, on a post when raised."""
    f = v3(unit(t.facing_deg))
    a = v3(unit(t.facing_deg + 90.0))
    d = {"target_panel": box_shape(v3(t.position, t.z + t.size[1] / 2),
                                   (f * TARGET_THICKNESS / 2, a * t.size[0] / 2,
                                    ZHAT * t.size[1] / 2), "target")}
    return d | stand_shapes("target", t.position, t.z, colour="panel_stand")


def pencil_shapes(i: int, b: Beacon) -> dict:
    """Beacon ``i``'s pencil meshes, keyed ``beacon<i>_<part>``, on a post when raised."""
    return {f"beacon{i}_{part}": mesh
            for part, mesh in pencil_meshes(b.position, b.height, b.z).items()
            } | stand_shapes(f"beacon{i}", b.position, b.z)


def stand_shapes(key: str, position: tuple[float, float], z: float, *, colour: str = "stand"
                 ) -> dict:
    """A raised object's post from the board to its base, ``<key>_stand`` (none for an
    object on the board): a cylinder of STAND_RADIUS under its axis, thinner than a
    pencil, so that it hides nothing of the object and is not taken for it, of
    ``colour`` (:data:`COLOURS`; the id pass labels it background: it is not the
    object)."""
    if z <= 0.0:
        return {}
    # Mitsuba's unit cylinder runs (0,0,0)–(0,0,1) with radius 1; its transform may
    # scale x and y alike (the radius) and z (the length)
    to_world = (mi.ScalarTransform4f().translate([float(position[0]), float(position[1]), 0.0])
                @ mi.ScalarTransform4f().scale([STAND_RADIUS, STAND_RADIUS, float(z)]))
    return {f"{key}_stand": {"type": "cylinder", "to_world": to_world,
                             "bsdf": diffuse(colour)}}
