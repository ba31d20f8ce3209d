"""An image measured again through the camera's pose the pegboard gives
(:func:`~mirrorsim.detection.board.measure_camera_pose`): as a level camera at the
board's pan would have measured it, in the plane (α, d_total) or in 3-D (α, ε, d_total)
(``evaluate --board-pose``, docs/method.md).
"""

from __future__ import annotations

import math

import numpy as np

from mirrorsim.detection.board import CameraPose, turned
from mirrorsim.detection.image_geometry import require_foot, rise_reading
from mirrorsim.detection.image_measurement import ImageMeasurement
from mirrorsim.scene.model import FRONT_OFFSET, Camera
from mirrorsim.scene.projection import camera_axes, project
from solver.geometry import unit, wrap_bearing


def corrected_image(pose: CameraPose, camera: Camera, image: ImageMeasurement, *, top: float,
                    base: float = 0.0) -> tuple[float, float]:
    """An image's (α, d_total) as a level camera at the board's pan would have measured
    them (``camera`` as the mount reports it; ``top``: how high the measured upright
    object is, the band of a pencil, the panel's height; ``base``: the height its foot's
    image stands at, 0 on the board).

    α is the bearing of the ray through the image's axis column and the middle of its band,
    the camera turned, pitched and rolled as the board says: a roll moves the bearing of an
    image below the camera's height by about roll·tan(elevation), the pencils' all alike.
    d_total is multiplied by how much taller that pose makes the object look than a level
    camera does, where it stands (:func:`~mirrorsim.detection.board.pitch_factor` on the
    optical axis).
    """
    cam = turned(camera, pose.pan_offset_deg)
    v_mid = (cam.cy if image.v_top is None or image.v_bottom is None
             else (image.v_top + image.v_bottom) / 2)
    ray = _posed_ray(cam, pose, image.u_axis, v_mid)
    alpha = math.degrees(math.atan2(ray[1], ray[0]))
    d = float(image.d_total)
    foot = np.asarray(camera.position, float) + d * unit(alpha)
    upright = np.array([[*foot, base + top], [*foot, base]])
    _, posed, _ = project(cam, upright, pose.pitch_deg, roll=pose.roll_deg)
    _, level, _ = project(cam, upright)
    return float(wrap_bearing(alpha)), d * float((posed[1] - posed[0]) / (level[1] - level[0]))


def corrected_image3(pose: CameraPose, camera: Camera, image: ImageMeasurement, *,
                     top: float) -> tuple[float, float, float]:
    """An image's (α, ε, 3-D d_total) as a level camera at the board's pan would have
    measured them, for the 3-D solve: α and the horizontal d_total as
    :func:`corrected_image` gives them, the image standing where its foot's ray puts it,
    and ε from the ray through the foot's row at the axis column, the camera posed as the
    board says (:func:`~mirrorsim.detection.image_geometry.rise_reading`).

    Raises
    ------
    DetectionError
        The image has no measured foot or distance.
    """
    require_foot(image)
    ray = _posed_ray(turned(camera, pose.pan_offset_deg), pose, image.u_axis, image.v_bottom)
    tan_face = float(ray[2] / math.hypot(ray[0], ray[1]))
    # where the foot's image stands (its rise above the lens, from the uncorrected
    # d_total: the correction is a fraction of a per cent of it)
    base = camera.height + tan_face * (image.d_total - FRONT_OFFSET[image.kind])
    alpha, d = corrected_image(pose, camera, image, top=top, base=base)
    return (alpha, *rise_reading(tan_face, d, image.kind))


def _posed_ray(cam: Camera, pose: CameraPose, u: float, v: float) -> np.ndarray:
    """The direction (world) of pixel (u, v)'s ray, ``cam`` pitched and rolled as ``pose``."""
    forward, right, down = camera_axes(cam, pose.pitch_deg, pose.roll_deg)
    return forward + (u - cam.cx) / cam.fx * right + (v - cam.cy) / cam.fx * down
