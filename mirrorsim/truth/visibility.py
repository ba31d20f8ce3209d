"""What of an object's image reaches the camera: the mirror's finite rectangle (and its
frame's lip, its tilt and curvature), the walls on either leg of the path, and direct view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mirrorsim.scene.model import (
    MIRROR_LIP,
    OCCLUDER_THICKNESS,
    PENCIL_RADIUS,
    TARGET_THICKNESS,
    Beacon,
    Camera,
    Scene,
    Target,
)
from mirrorsim.truth.optics import along_mirror, mirror_image, object_height, project
from solver.geometry import bearing_deg, segment_crossing, signed_distance, unit

AXIS_SAMPLES = 41  # heights sampled along an object's upright axis


@dataclass(frozen=True)
class Visibility:
    """How much of an object's image reaches the camera through the mirror."""

    axis_fraction: float  # fraction of the upright axis (sampled heights) that is seen
    fraction: float  # fraction over the axis and the object's two side edges
    reason: str  # why samples are lost ('' when the whole object is seen)

    @property
    def clipped(self) -> bool:
        """Whether any sampled point is lost."""
        return self.fraction < 1.0


def _walls(scene: Scene, obj) -> list[tuple[str, np.ndarray, np.ndarray, float, float]]:
    """Upright blockers as (name, start, end, top, bottom) segments; the target blocks
    beacons (a raised panel from its bottom edge up: under it stands only its post).

    Walls and the panel are boxes: each contributes the four sides of its footprint.
    """
    walls = []
    for i, o in enumerate(scene.occluders):
        walls += _box_sides(f"occluders[{i}]", o.start, o.end, OCCLUDER_THICKNESS, o.height)
    if not isinstance(obj, Target):
        t = scene.target
        walls += _box_sides("the target panel", *t.ends(), TARGET_THICKNESS, t.z + t.height,
                            bottom=t.z)
    return walls


def _own_panel(obj) -> list[tuple[str, np.ndarray, np.ndarray, float, float]]:
    """The target's own panel, a blocker of the camera's leg to the glass only: a panel
    standing between the camera and the mirror hides part of its own image there (a
    scene's wall that left the panel's end in the camera's view of the glass cut the
    image, and the detector read its bearing 2.3° off)."""
    if not isinstance(obj, Target):
        return []
    return _box_sides("the target panel itself", *obj.ends(), TARGET_THICKNESS,
                      obj.z + obj.height, bottom=obj.z)


def _box_sides(name: str, start, end, thickness: float, height: float, bottom: float = 0.0):
    a, b = np.asarray(start, float), np.asarray(end, float)
    d = (b - a) / np.linalg.norm(b - a)
    n = np.array([-d[1], d[0]]) * thickness / 2.0
    c = [a - n, b - n, b + n, a + n]
    return [(name, c[k], c[(k + 1) % 4], height, bottom) for k in range(4)]


def _blocked(walls, a3: np.ndarray, b3: np.ndarray) -> str:
    """Name of the first wall that the 3-D segment a3→b3 passes through, or ''."""
    for name, w0, w1, h, bottom in walls:
        u = segment_crossing(a3[:2], b3[:2], w0, q1=w1)
        if u is not None and bottom <= a3[2] + u * (b3[2] - a3[2]) < h:
            return name
    return ""


def _sample_columns(scene: Scene, obj) -> list[np.ndarray]:
    """Board points of the object's central axis and its two side edges."""
    p = np.asarray(obj.position, float)
    if isinstance(obj, Target):
        e0, e1 = obj.ends()
        return [p, e0, e1]
    # a pencil: its silhouette edges across the line of sight
    r = mirror_image(scene.camera.position, scene.mirror, p).reflection_point
    side = unit(bearing_deg(p, r) + 90.0) * PENCIL_RADIUS * math.cos(math.pi / 6)
    return [p, p - side, p + side]


def glass_frame(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The glass as the bench stands it: its centre, and unit vectors along its width,
    up its face and its normal towards the camera (3-D).  A leaning mirror (the scene's
    ``lean``, and on top of it a bench's ``tilt``) turns about its bottom edge, ``z``
    above the board, its top away from the camera (``up`` turns towards −normal)."""
    m = scene.mirror
    n0 = np.r_[m.normal_towards(scene.camera.position), 0.0]
    along = np.array([-n0[1], n0[0], 0.0])  # so that along × z = n (right-handed)
    t = math.radians(scene.bench.tilt + m.lean)
    z = np.array([0.0, 0.0, 1.0])
    up, n = math.cos(t) * z - math.sin(t) * n0, math.cos(t) * n0 + math.sin(t) * z
    return np.r_[m.center, m.z] + up * m.size[1] / 2, along, up, n


def sag(a: np.ndarray, b: np.ndarray, radius: float | None) -> np.ndarray:
    """How far a spherical glass of ``radius`` (> 0: concave) stands before its tangent
    plane at (a, b) from the centre (cm; 0 for a flat one)."""
    if radius is None:
        return np.zeros_like(np.asarray(a, float) + np.asarray(b, float))
    return radius - math.copysign(1.0, radius) * np.sqrt(radius**2 - np.square(a)
                                                         - np.square(b))


def frame_front(scene: Scene) -> float:
    """How far the mirror frame's front stands before the glass's tangent plane at its
    centre (cm): MIRROR_LIP before the glass's corners (the renderer's frame and the
    visibility checks' lip)."""
    w, h = scene.mirror.size
    return MIRROR_LIP + float(sag(w / 2, h / 2, scene.bench.curvature_radius))


def _frame_lip(scene: Scene, frame, a: np.ndarray, b: np.ndarray, p3: np.ndarray
               ) -> np.ndarray:
    """For each path camera → glass point (``a`` along, ``b`` up from the centre of the
    glass ``frame``, :func:`glass_frame`) → object point ``p3``: which of its two legs
    runs into the frame's inner side before clearing the frame's front
    (:func:`frame_front`), as 'camera side' or 'object top' (the leg and the frame's
    part), '' where neither does."""
    g, along, up, n = frame
    w, h = scene.mirror.size
    depth = sag(a, b, scene.bench.curvature_radius)
    x3 = g + np.outer(a, along) + np.outer(b, up) + np.outer(depth, n)
    rise = frame_front(scene) - depth  # glass point → frame front
    out = np.full(len(x3), "", dtype=object)
    for leg, d in (("camera", scene.camera.center3 - x3), ("object", p3 - x3)):
        dn = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            a_f, b_f = a + rise * (d @ along) / dn, b + rise * (d @ up) / dn
        for part, hit in (("side", np.abs(a_f) > w / 2), ("top", b_f > h / 2)):
            hit &= (dn > 0) & (out == "")
            out[hit] = f"{leg} {part}"
    return out


def glass_hits(scene: Scene, points3: np.ndarray, iterations: int = 6
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the camera sees each 3-D point in the bench's real mirror (tilted, curved).

    Returns (a, b, apparent): the reflection point's coordinates on the glass from its
    centre (along its width, up its face; the glass spans |a| ≤ w/2, |b| ≤ h/2), and the
    point's apparent position (along the camera's ray, at the path's length).  A curved
    glass is solved by reflecting in the tangent plane at the current estimate and
    returning to the sphere; for radii beyond the mirror's diagonal the normal turns by
    under a degree over the glass and six rounds agree to 1e-9 cm.
    """
    g, along, up, n = glass_frame(scene)
    cam = scene.camera.center3
    P = np.atleast_2d(np.asarray(points3, float))
    R = scene.bench.curvature_radius

    def meet(origin, normals):  # reflect the camera in each point's plane, meet it there
        c_img = cam - 2.0 * np.einsum("ij,ij->i", cam - origin, normals)[:, None] * normals
        s = (np.einsum("ij,ij->i", origin - c_img, normals)
             / np.einsum("ij,ij->i", P - c_img, normals))
        return c_img + s[:, None] * (P - c_img)

    X = meet(np.broadcast_to(g, P.shape), np.broadcast_to(n, P.shape))
    if R is not None:
        centre = g + R * n

        def on_sphere(Y):
            return centre + (Y - centre) * (abs(R) / np.linalg.norm(Y - centre, axis=1))[:, None]

        X = on_sphere(X)
        for _ in range(iterations):  # the tangent plane there, back onto the sphere
            X = on_sphere(meet(X, (centre - X) / R))
    ray = X - cam
    d1 = np.linalg.norm(ray, axis=1)
    apparent = cam + ray * ((d1 + np.linalg.norm(P - X, axis=1)) / d1)[:, None]
    return (X - g) @ along, (X - g) @ up, apparent


def _past_end(offset: float, half_w: float) -> str:
    return (f"its reflection point falls {abs(offset) - half_w:.2f} cm beyond the mirror's "
            f"{'end at +yaw' if offset > 0 else 'end at -yaw'}")


def _flat_upright(scene: Scene) -> bool:
    """A flat glass standing upright on the board: what it shows is decided in plan."""
    return (scene.bench.tilt == 0.0 and scene.bench.curvature_radius is None
            and not scene.mirror.lean and not scene.mirror.z)


def _column_failures(scene: Scene, walls, point, heights: np.ndarray, *, camera_walls=()
                     ) -> list[str]:
    """Why the image of each 3-D point (point, z), z in ``heights``, does not reach the
    camera ('' where it does).  What depends on the board point alone (the mirror's
    side, the reflection point, where each wall crosses the paths in plan) is computed
    once per column; the heights are vectorized (the dataset sampler's hot loop)."""
    cam, mir = scene.camera, scene.mirror
    heights = np.asarray(heights, float)
    n = len(heights)
    side = signed_distance(point, mir.center, mir.yaw)
    if side * signed_distance(cam.position, mir.center, mir.yaw) <= 0:
        return ["it stands behind the mirror's line"] * n
    img = mirror_image(cam.position, mir, point)
    half_w = mir.size[0] / 2.0
    t = img.d1 / img.d_total
    zc = cam.height + t * (heights - cam.height)  # in plan, for the walls
    pts = np.column_stack([np.full(n, float(point[0])), np.full(n, float(point[1])),
                           heights])
    frame = glass_frame(scene)
    # the mirror line's +yaw direction against the glass's `along`
    sign = 1.0 if frame[1][:2] @ unit(mir.yaw) > 0 else -1.0
    if _flat_upright(scene):
        along = along_mirror(mir, img.reflection_point)
        if abs(along) > half_w:  # the whole column: no need to look further
            return [_past_end(along, half_w)] * n
        offset, up_glass = np.full(n, along), zc
        apparent = np.column_stack([np.full(n, img.virtual[0]), np.full(n, img.virtual[1]),
                                    heights])
        a, b = sign * offset, zc - mir.size[1] / 2
    else:  # the bench's tilted or curved glass decides what it shows
        a, b, apparent = glass_hits(scene, pts)
        offset, up_glass = sign * a, b + mir.size[1] / 2
    lip = _frame_lip(scene, frame, a, b, pts)
    u, v, depth = project(cam, apparent, scene.bench.pitch, roll=scene.bench.roll)
    outside = (depth <= 0) | (u < -0.5) | (u > cam.width - 0.5) | (v < -0.5) | (
        v > cam.height_px - 0.5)
    blocker = _first_blockers(walls, cam, np.asarray(img.reflection_point, float),
                              np.asarray(point, float), zc, heights,
                              camera_walls=camera_walls)
    return [_why_lost(scene, offset[k], up_glass[k], lip[k], outside[k], blocker[k],
                      (float(u[k]), float(v[k]))) for k in range(n)]


def axis_rows(scene: Scene, obj: Target | Beacon) -> tuple[float, float]:
    """The frame rows (px) of the object's image's foot and top, through the mirror as
    :func:`visibility` sees them (the bench's tilt, curvature, pitch and roll; the lens's
    distortion apart, a pixel or two at a frame's edge)."""
    pts = np.array([[*obj.position, z] for z in (obj.z, obj.z + object_height(obj))])
    if _flat_upright(scene):
        virtual = mirror_image(scene.camera.position, scene.mirror, obj.position).virtual
        apparent = np.column_stack([np.full(2, virtual[0]), np.full(2, virtual[1]), pts[:, 2]])
    else:
        apparent = glass_hits(scene, pts)[2]
    _, v, _ = project(scene.camera, apparent, scene.bench.pitch, roll=scene.bench.roll)
    return float(v[0]), float(v[1])


def _first_blockers(walls, cam: Camera, r2: np.ndarray, point: np.ndarray, zc: np.ndarray,
                    heights: np.ndarray, *, camera_walls=()) -> np.ndarray:
    """The first wall (in the walls' order) under each height's path: camera → mirror,
    then mirror → object ('' where none); in plan both paths are the same for every
    height.  ``camera_walls`` block the first path only (the object's own panel)."""
    n = len(heights)
    blocker = np.full(n, "", dtype=object)
    for a2, b2, za, zb, blockers in (
            (np.asarray(cam.position, float), r2, np.full(n, cam.height), zc,
             [*walls, *camera_walls]),
            (r2, point, zc, heights, walls)):
        for name, w0, w1, h, bottom in blockers:
            cross = segment_crossing(a2, b2, w0, q1=w1)
            if cross is not None:
                z = za + cross * (zb - za)
                hit = (z < h) & (z >= bottom) & (blocker == "")
                blocker[hit] = name
    return blocker


def _why_lost(scene: Scene, offset: float, up_glass: float, lip: str, outside: bool,
              blocker: str, pixel: tuple[float, float]) -> str:
    """Why one point's image does not reach the camera, in the order the path meets the
    causes ('' where it does)."""
    mir, cam = scene.mirror, scene.camera
    half_w = mir.size[0] / 2.0
    if abs(offset) > half_w:
        return _past_end(offset, half_w)
    if up_glass > mir.size[1]:
        return f"the ray meets the mirror plane {up_glass - mir.size[1]:.2f} cm above its top edge"
    if up_glass < 0.0:
        return (f"the ray meets the mirror plane {-up_glass:.2f} cm below "
                + ("its bottom edge" if mir.z else "the board"))
    if lip:
        leg, part = lip.split()
        gap = half_w - abs(offset) if part == "side" else mir.size[1] - up_glass
        return (f"its path to the {leg} leaves the glass {gap:.2f} cm from its {part} edge "
                f"and meets the frame there ({MIRROR_LIP} cm proud of the glass)")
    if outside:
        return (f"it lies outside the camera's field of view (pan {cam.pan_deg:.2f}°, "
                f"pixel ({pixel[0]:.0f}, {pixel[1]:.0f}))")
    if blocker:
        return f"the path through the mirror is blocked by {blocker}"
    return ""


def visibility(scene: Scene, obj: Target | Beacon) -> Visibility:
    """Sample the object's axis and side edges; say how much reaches the camera and why not."""
    walls = _walls(scene, obj)
    heights = obj.z + np.linspace(0.0, object_height(obj), AXIS_SAMPLES)
    cols = _sample_columns(scene, obj)
    own = _own_panel(obj)
    why = [_column_failures(scene, walls, col, heights, camera_walls=own) for col in cols]
    seen = np.array([[not w for w in col] for col in why])
    axis = float(seen[0].mean())
    reason = ""
    if not seen.all():
        # the axis sample nearest mid-height that fails says most about the set-up
        tall = heights[-1] - heights[0]
        lost = [j for j in np.argsort(np.abs(heights - heights[0] - tall / 2))
                if not seen[0, j]]
        if lost:
            hidden = (1.0 - axis) * tall
            reason = (f"{hidden:.2f} of its {tall:.2f} cm height lost: "
                      f"{why[0][lost[0]]}")
        else:
            first = next(w for col in why[1:] for w in col if w)
            reason = f"a side edge is lost: {first}"
    return Visibility(axis_fraction=axis, fraction=float(seen.mean()), reason=reason)


def direct_view_fraction(scene: Scene, obj: Target | Beacon) -> float:
    """Fraction of the object's axis the camera could see directly (panning to it).

    The mirror's back counts as a wall, as do the occluders.
    """
    m0, m1 = scene.mirror.ends()
    walls = _walls(scene, obj) + [("the mirror", m0, m1, scene.mirror.z + scene.mirror.size[1],
                                   0.0)]
    p = np.asarray(obj.position, float)
    heights = obj.z + np.linspace(0.0, object_height(obj), AXIS_SAMPLES)
    free = [not _blocked(walls, scene.camera.center3, np.array([p[0], p[1], z])) for z in heights]
    return float(np.mean(free))

