"""The id pass: which object each pixel centre sees, directly and in the mirror, as
label images (and the one image ``<name>.ids.png`` of both).

Mitsuba's ``aov`` integrator's ``shape_index`` records the first hit only, which for
every pixel of the mirror is the mirror itself; so the id pass casts the camera ray,
and where it meets the glass, the specularly reflected ray.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mirrorsim.rendering.mitsuba_scene import BACKGROUND_LABEL, MIRROR_LABEL, label_of
from mirrorsim.scene.model import Scene

IN_MIRROR = 100  # ids.png: label + IN_MIRROR where the pixel sees it in the mirror


def id_pass(mi_scene: mi.Scene, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Object ids at pixel centres: the first surface hit, and what the mirror shows.

    Returns
    -------
    first, in_mirror : ndarray of uint8, shape (H, W)
        Labels (MIRROR_LABEL, TARGET_LABEL, BEACON_LABEL + i, …; 0 for anything else).
        ``in_mirror`` is 0 off the glass.
    """
    cam = scene.camera
    shapes = [(s, label_of(s.id(), len(scene.beacons))) for s in mi_scene.shapes()]
    sensor = {s.id(): s for s in mi_scene.sensors()}["sensor"]  # the full film
    cast = _id_pass_jit if dr.is_jit_v(mi.Float) else _id_pass_scalar
    return cast(mi_scene, sensor, shapes, cam.width, cam.height_px)


def _reflected_ray(ray, si):
    n = si.sh_frame.n  # the shading normal: a curved mirror's (its mesh's vertex normals)
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
    dr.eval(first, second)  # one kernel for both: evaluated apart, the second recasts the first ray
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

