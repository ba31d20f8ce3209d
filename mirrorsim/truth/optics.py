"""Exact optics of the mirror space: the ground truth everything is scored against.

A vertical planar mirror reflects the board plane across its surface line and leaves
heights unchanged.  So an object's virtual image is its top-view reflection, the angle
of arrival α is the bearing of that image from the camera, and d_total = d1 + d2 is
the camera's distance to it (paper eqs 1–4).  Whether the image actually reaches the
camera depends on the mirror's finite rectangle (horizontally *and* vertically), the
walls on either leg of the path, and the camera's field of view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from mirrorsim.scene.model import (
    FRONT_OFFSET,
    MIRROR_FRAME,
    PENCIL_RADIUS,
    Beacon,
    Camera,
    Mirror,
    Point2,
    Scene,
    Target,
)
from mirrorsim.scene.projection import project
from solver.geometry import bearing_deg, unit
from solver.sltr import Observation, observe
from solver.sltr3d import MirrorPlane, Observation3, observe3


def mirror_image(observer: Point2, mirror: Mirror, point: ArrayLike) -> Observation:
    """Virtual image, α, d_total, d1, d2 and reflection point of a board point seen from
    ``observer`` (the camera's position): the solver's forward model, as plain floats."""
    obs = observe(observer, mirror.center, mirror.yaw, point=point, strict=False)
    return Observation(alpha_deg=float(obs.alpha_deg), d_total=float(obs.d_total),
                       d1=float(obs.d1), d2=float(obs.d2),
                       virtual=np.asarray(obs.virtual, float),
                       reflection_point=np.asarray(obs.reflection_point, float))


def mirror_plane(camera: Camera, mirror: Mirror) -> MirrorPlane:
    """The mirror's plane as the scene gives it (its lean and its raised bottom edge),
    its normal towards the camera: the 3-D truth's mirror (a bench's tilt is not
    part of it)."""
    return MirrorPlane.from_pose([*mirror.center, mirror.z], mirror.yaw, mirror.lean,
                                 toward=camera.center3)


def image3(camera: Camera, mirror: Mirror, point3: ArrayLike) -> Observation3:
    """What the camera sees of a 3-D point in the scene's mirror plane (its lean
    counted): :func:`solver.sltr3d.observe3`'s forward model, the point's image
    wherever it stands (the composer checks which side of the glass)."""
    return observe3(camera.center3, mirror_plane(camera, mirror), point3, strict=False)


def object_image(scene: Scene, obj: Target | Beacon) -> Observation | Observation3:
    """The image of an object the truth follows: in a planar scene its position's, in
    plan (:func:`mirror_image`); in a 3-D one its base's (:func:`image3`)."""
    if scene.is_3d:
        return image3(scene.camera, scene.mirror, obj.base3)
    return mirror_image(scene.camera.position, scene.mirror, obj.position)


def along_mirror(mirror: Mirror, point: ArrayLike) -> float:
    """A point's signed distance from the mirror's centre along its yaw (a reflection
    point's offset: beyond half the width, the glass does not reach it)."""
    return float((np.asarray(point, float) - np.asarray(mirror.center, float))
                 @ unit(mirror.yaw))


def target_facing(camera: Camera, mirror: Mirror, target_position: Point2) -> float:
    """Bearing of the panel's front normal: it faces its reflection point, i.e. the
    camera's virtual image, so the camera sees its face square-on in the mirror (in a
    leaning mirror, the camera's virtual image in plan)."""
    if mirror.lean or mirror.z:
        rp = mirror_plane(camera, mirror).reflect(camera.center3)
    else:
        rp = mirror_image(camera.position, mirror, target_position).reflection_point
    return math.degrees(math.atan2(rp[1] - target_position[1], rp[0] - target_position[0]))


def resolve_pan(camera: Camera, pan: float | str, mirror: Mirror, *, target: Target,
                beacon: Beacon) -> float:
    """The optical axis's bearing for a pan as written: degrees, or the bearing of the
    mirror's centre, or of the target's or the first beacon's virtual image."""
    if pan == "mirror":
        return float(bearing_deg(camera.position, mirror.center))
    if pan in ("target", "beacon"):
        obj = target if pan == "target" else beacon
        if mirror.lean or mirror.z or obj.z:
            return image3(camera, mirror, obj.base3).alpha_deg
        return mirror_image(camera.position, mirror, obj.position).alpha_deg
    return float(pan)


@dataclass(frozen=True)
class ImagePx:
    """Where an object's virtual image falls on the sensor: the exact pinhole projection
    of its upright axis (px)."""

    u_axis: float  # column of the upright axis
    v_top: float  # row of the axis's top end
    v_bottom: float  # row of its foot (board level)
    height: float  # v_bottom − v_top


def image_extent(scene: Scene, obj: Target | Beacon) -> ImagePx:
    """Projection of the virtual image of the object's upright axis (in a leaning mirror
    the image leans: the column is its foot's)."""
    if scene.is_3d:
        plane = mirror_plane(scene.camera, scene.mirror)
        base = obj.base3
        pts = plane.reflect(np.array([base + [0.0, 0.0, object_height(obj)], base]))
    else:
        v = mirror_image(scene.camera.position, scene.mirror, obj.position).virtual
        top = object_height(obj)
        pts = np.array([[v[0], v[1], top], [v[0], v[1], 0.0]])
    u, vv, _ = project(scene.camera, pts)
    return ImagePx(float(u[1]), float(vv[0]), float(vv[1]), float(vv[1] - vv[0]))


def object_height(obj: Target | Beacon) -> float:
    """The height of the target panel or of a pencil (cm)."""
    return obj.size[1] if isinstance(obj, Target) else obj.height


def mirror_box(scene: Scene, margin_px: int = 8) -> tuple[int, int, int, int] | None:
    """The film region (u0, v0, u1, v1), end-exclusive, that holds the mirror and its
    frame, ``margin_px`` wider all round and clipped to the film; None if part of the
    mirror lies behind the camera (no finite box).  The camera as it stands (the bench's
    pitch and roll); a tilted mirror's top is taken where it leans to (its corners in
    front and behind the upright plane by the lean)."""
    cam, m, bench = scene.camera, scene.mirror, scene.bench
    c, d = np.asarray(m.center, float), unit(m.yaw) * (m.size[0] / 2 + MIRROR_FRAME)
    top = m.size[1] + MIRROR_FRAME
    lean = unit(m.yaw + 90.0) * top * math.sin(math.radians(abs(bench.tilt) + abs(m.lean)))
    pts = np.array([[*(c + s * d + e * lean), m.z + z] for s in (-1, 1) for z in (0.0, top)
                    for e in (-1, 1)])
    u, v, depth = project(cam, pts, bench.pitch, roll=bench.roll)
    return film_box(cam, u, v, depth=depth, margin_px=margin_px)


def film_box(cam: Camera, u: np.ndarray, v: np.ndarray, *, depth: np.ndarray, margin_px: int
              ) -> tuple[int, int, int, int] | None:
    """The film region (end-exclusive) around projected points, ``margin_px`` wider and
    clipped to the film; None if a point lies behind the camera or none on the film."""
    if (depth <= 0).any():
        return None
    u0 = int(max(0, math.floor(u.min()) - margin_px))
    v0 = int(max(0, math.floor(v.min()) - margin_px))
    u1 = int(min(cam.width, math.ceil(u.max()) + margin_px + 1))
    v1 = int(min(cam.height_px, math.ceil(v.max()) + margin_px + 1))
    return (u0, v0, u1, v1) if u1 > u0 and v1 > v0 else None


def front_face(scene: Scene, obj: Target | Beacon, height: float, *, kind: str
               ) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows (u, v) of the foot and the top (in that order) of ``obj``'s
    front face in its mirror image: the virtual image's axis moved towards the camera by
    FRONT_OFFSET[kind] (``kind``: target or beacon), ``height`` cm high; what a measured
    edge is held to."""
    img = mirror_image(scene.camera.position, scene.mirror, obj.position)
    ray = (img.virtual - np.asarray(scene.camera.position)) / img.d_total
    front = img.virtual - ray * FRONT_OFFSET[kind]
    u, v, _ = project(scene.camera, np.array([[*front, 0.0], [*front, height]]))
    return u, v


# how far (px) a beacon's render box reaches past its image all round: the detector's
# edge levels reach 9 px past an edge
BEACON_BOX_MARGIN_PX = 16


def beacon_boxes(scene: Scene, margin_px: int = BEACON_BOX_MARGIN_PX
                 ) -> list[tuple[int, int, int, int] | None]:
    """Per beacon, the film region (u0, v0, u1, v1), end-exclusive, around its image in
    the mirror: its virtual image's outline (the pencil's circumscribed cylinder, board to
    tip) ``margin_px`` wider all round and clipped to the film; None if it lies behind
    the camera or off the film."""
    cam, bench = scene.camera, scene.bench
    out = []
    for b in scene.beacons:
        if scene.is_3d:  # the cylinder's corners reflected: a leaning image leans
            r = PENCIL_RADIUS
            pts = mirror_plane(cam, scene.mirror).reflect(np.array(
                [b.base3 + [dx, dy, z] for dx in (-r, r) for dy in (-r, r)
                 for z in (0.0, b.height)]))
        else:
            v = mirror_image(cam.position, scene.mirror, b.position).virtual
            pts = np.array([[v[0] + dx, v[1] + dy, z] for dx in (-PENCIL_RADIUS, PENCIL_RADIUS)
                            for dy in (-PENCIL_RADIUS, PENCIL_RADIUS) for z in (0.0, b.height)])
        u, w, depth = project(cam, pts, bench.pitch, roll=bench.roll)
        out.append(film_box(cam, u, w, depth=depth, margin_px=margin_px))
    return out



def upright_box(cam: Camera, point: ArrayLike, half_width: float, *, height: float,
                margin_px: float = 0.0, z0: float = 0.0
                ) -> tuple[float, float, float, float] | None:
    """The film box (u0, v0, u1, v1) of an upright object ``half_width`` cm either side of
    its axis at board ``point`` (2-D), ``height`` cm tall from ``z0`` up, square-on to the
    camera, as the level camera projects it, ``margin_px`` wider; None behind the
    camera."""
    p = np.asarray(point, float)
    ray = p - np.asarray(cam.position, float)
    side = np.array([-ray[1], ray[0]]) / max(float(np.hypot(*ray)), 1e-9) * half_width
    pts = np.array([[*(p + s * side), z0 + z] for s in (-1.0, 1.0) for z in (0.0, height)])
    u, v, depth = project(cam, pts)
    if (depth <= 0).any():
        return None
    return (float(u.min()) - margin_px, float(v.min()) - margin_px,
            float(u.max()) + margin_px, float(v.max()) + margin_px)


def boxes_overlap(a: tuple[float, ...] | None, b: tuple[float, ...] | None) -> bool:
    """Whether two film boxes (u0, v0, u1, v1) overlap (None: no box, no overlap)."""
    return (a is not None and b is not None and a[0] < b[2] and b[0] < a[2]
            and a[1] < b[3] and b[1] < a[3])
