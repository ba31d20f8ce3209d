"""What the frames of an evaluation measured: the frames a scene renders, each frame's
record, the measurements the solver sees and their σ's; shared by the planar and the
3-D evaluation (:mod:`mirrorsim.pipelines.evaluate`, :mod:`mirrorsim.pipelines.evaluate3d`)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mirrorsim.detection.board import (
    CameraPose,
    frame_pose,
    mean_pose,
    pose_pan_sigma,
)
from mirrorsim.detection.detector import Detection, annotate
from mirrorsim.detection.posed import corrected_image
from mirrorsim.errors import DetectionError
from mirrorsim.formats.error_model import ErrorModel, ImageFeatures
from mirrorsim.formats.files import write_png
from mirrorsim.pipelines.frame import MeasuredFrame
from mirrorsim.pipelines.score import FrameRecord
from mirrorsim.scene.model import Scene, beacon_frame_name, pencil_paint_height
from solver.geometry import wrap_bearing
from solver.measurements import BeaconMeasurement, ObjectSigmas
from solver.selfcal import SelfCalibration


@dataclass(frozen=True)
class Seen:
    """What the experimenter measured: each beacon, the target at its mean over the
    frames, the pan (the capture record's, or the board's) and the focal length; the
    camera's pose from the board, where measured."""

    beacons: list[BeaconMeasurement]
    target: tuple[float, float]
    pan: float
    fx: float
    pose: CameraPose | None
    detections: list[Detection]


def seen_of(scene: Scene, measured: list, *, board_pose: bool) -> Seen:
    """The measurements of the frames ``measured``: with ``board_pose``, each image again
    from its pixels, as the level camera at the board's pan would have measured it."""
    detections = [m.detection for m in measured]
    beacons = [b for det in detections for b in det.beacon_measurements()]
    targets = [(d.target.alpha_deg, d.target.d_total) for d in detections
               if d.target.d_total is not None]
    if not targets:
        why = "; ".join(dict.fromkeys(n for d in detections for n in d.target.notes))
        raise DetectionError(f"{scene.name}: the target's d_total could not be measured in "
                             f"any frame ({', '.join(str(m.files.image) for m in measured)}): "
                             f"{why or 'its image is clipped at the top'}")
    # what the experimenter knows: the measurements and the capture record's pan
    capture = measured[0].files.capture
    pan, fx = capture.camera.pan_deg, capture.camera.fx
    pose = None
    if board_pose:
        pose = mean_pose([frame_pose(m.image, m.files.capture, m.files.image)
                          for m in measured])
        pan = float(wrap_bearing(pan + pose.pan_offset_deg))  # the α's below are turned to it
        # (the detections' beacons in the order of beacon_measurements)
        beacons = [BeaconMeasurement(tuple(b.position), *corrected_image(
            pose, capture.camera, m, top=pencil_paint_height(b.height)))
            for det in detections for b, m in det.beacons]
        targets = [corrected_image(pose, capture.camera, d.target, top=capture.target_size[1])
                   for d in detections if d.target.d_total is not None]
    mean_target = tuple(float(v) for v in np.mean(targets, axis=0))
    return Seen(beacons, mean_target, pan, fx, pose, detections)


def after_board(pose: CameraPose, calibration: SelfCalibration, sigma: ObjectSigmas, *,
                fx: float) -> tuple[SelfCalibration, ObjectSigmas]:
    """What a solve knows once the board has measured the camera's pose: the pan is the
    board's to know now, to what is left of it after the board: a prior
    from the mount's reading (the user's or the bench model's) gives way, and where the
    pan is not a nuisance, it is every α's shared offset (``fx``: the frames' focal
    length, px)."""
    left = pose_pan_sigma(pose, fx)
    if "pan" in calibration.nuisances:
        return (replace(calibration, priors={**calibration.priors, "pan": left}),
                replace(sigma, shared_alpha_deg=0.0))
    return calibration, replace(sigma, shared_alpha_deg=left)


def sigmas_of(model: ErrorModel, seen: Seen
            ) -> tuple[tuple[ImageFeatures, ...], ObjectSigmas]:
    """What each frame showed of each image, at the measurements the solver sees, and
    the σ's the model gives them."""
    detections = seen.detections
    first = next(d for d in detections if d.target.d_total is not None)
    features = (first.features(first.target, *seen.target),
                *(det.features(m, b.alpha_deg, b.d_total) for (det, m), b in zip(
                    ((det, m) for det in detections for _, m in det.beacons), seen.beacons,
                    strict=True)))
    return features, model.sigmas(features[0], list(features[1:]), seen.pan, fx_px=seen.fx)


def frames_of(scene: Scene) -> list[Scene]:
    """The frames :func:`evaluate_scene` renders of ``scene``: the scene itself, or with
    several beacons one frame per beacon (``<name>_b<i>``, that beacon alone)."""
    if len(scene.beacons) == 1:
        return [scene]
    return [replace(scene, name=beacon_frame_name(scene.name, i), beacons=(b,))
            for i, b in enumerate(scene.beacons)]


def annotated_with_truth(m: MeasuredFrame) -> np.ndarray:
    """The detector's annotated frame (:func:`~mirrorsim.detection.detector.annotate`)
    with, from the frame's ground truth (the scorer's, never the detector's), each
    image's true axis and ends in magenta beside the measured ones, and a zoom on the
    mirror's glass pasted in the corner farthest from it (edges 1 px apart are seen
    there, not in the whole frame)."""
    import cv2

    out = np.ascontiguousarray(annotate(m.image, m.detection))
    truth = m.files.truth if m.files is not None else None
    if truth is None:
        return out
    magenta = (230, 40, 230)
    for obj in (truth.target, *truth.beacons):
        px = obj.image_px
        if px is None or not np.isfinite(px.u_axis):
            continue
        x, top, bottom = (int(round(v)) for v in (px.u_axis, px.v_top, px.v_bottom))
        for y in range(top - 14, bottom + 14, 6):  # dashed: the measured axis stays seen
            cv2.line(out, (x, y), (x, min(y + 3, bottom + 14)), magenta, 1)
        for y in (top, bottom):
            cv2.line(out, (x - 10, y), (x + 10, y), magenta, 1)
    box = truth.mirror_pixels.bbox_px if truth.mirror_pixels is not None else None
    if box is not None:
        paste_zoom(out, box)
    return out


def paste_zoom(out: np.ndarray, box: tuple[int, int, int, int]) -> None:
    """The region ``box`` (u0, v0, u1, v1) enlarged to a third of the frame's width, with
    a border and its factor, in the top corner farther from it."""
    import cv2

    h, w = out.shape[:2]
    u0, v0, u1, v1 = box
    pad = 6
    u0, v0, u1, v1 = max(0, u0 - pad), max(0, v0 - pad), min(w, u1 + pad), min(h, v1 + pad)
    crop = out[v0:v1, u0:u1].copy()
    if crop.size == 0:
        return
    k = min(w / 3 / crop.shape[1], h / 2 / crop.shape[0])
    if k <= 1.2:  # the glass fills the frame already
        return
    zoom = cv2.resize(crop, None, fx=k, fy=k, interpolation=cv2.INTER_NEAREST)
    zh, zw = zoom.shape[:2]
    x = 4 if (u0 + u1) / 2 > w / 2 else w - zw - 4
    out[4:4 + zh, x:x + zw] = zoom
    cv2.rectangle(out, (x - 1, 3), (x + zw, 4 + zh), (255, 255, 255), 1)
    cv2.putText(out, f"mirror x{k:.1f}", (x + 4, 4 + zh - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                (255, 255, 255), 1, cv2.LINE_AA)


def frame_record(m: MeasuredFrame, annotated_path: Path, annotate_it: bool) -> FrameRecord:
    """The report's entry for one frame (its annotated copy written where asked)."""
    det = m.detection
    annotated = str(write_png(annotated_path, annotated_with_truth(m))) if annotate_it else ""
    return FrameRecord(str(m.files.image), annotated, m.files.reused, det.target.clipped,
                       det.beacons[0][1].clipped)
