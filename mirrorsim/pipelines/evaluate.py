"""End to end: render → detect → solve → score against the exact ground truth.

One frame per beacon (a scene with ``beacons:`` renders each beacon alone, as a moving
beacon would be photographed at each pose); the target is measured in every frame.
The solver sees only the measurements; the score compares its estimate with the
ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mirrorsim.detection.board import (
    CameraPose,
    corrected_image,
    frame_pose,
    mean_pose,
    pose_pan_sigma,
)
from mirrorsim.detection.detector import Detection, annotate
from mirrorsim.errors import BadParameter, DetectionError
from mirrorsim.formats.error_model import ErrorModel, ImageFeatures
from mirrorsim.formats.files import claim_run_folder, default_out, write_png
from mirrorsim.pipelines.frame import MeasuredFrame, render_and_measure
from mirrorsim.pipelines.scenes import check_given_scene
from mirrorsim.pipelines.score import (
    EXTRA_FILES,
    FrameRecord,
    Report,
    Score,
    check_keep,
    score,
)
from mirrorsim.pipelines.solving import (
    as_error_model,
    model_calibration,
    model_for,
    solve_separated,
)
from mirrorsim.rendering.backend import check_variant
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import Scene, pencil_paint_height
from mirrorsim.truth.groundtruth import GroundTruth, RenderInfo
from solver.errors import SolverError
from solver.geometry import wrap_bearing
from solver.lsq import solve_measurements
from solver.measurements import BeaconMeasurement, Measurements, ObjectSigmas
from solver.selfcal import PLAIN, SelfCalibration, as_calibration


def evaluate_scene(scene: Scene, out_dir: str | Path | None = None, *, variant: str = "auto",
                   progress: bool = True, error_model: ErrorModel | None = None,
                   keep: tuple[str, ...] = EXTRA_FILES,
                   calibration: SelfCalibration = PLAIN, board_pose: bool = False) -> Report:
    """Render (or reuse) with the scene's render settings, detect, solve and score
    ``scene``; return the report.

    ``error_model``: gives each measurement its σ's, which weight the solver and make
    its error ellipse (default: the model shipped for the ideal bench at the default
    render settings).  ``keep``: which of EXTRA_FILES to write beside each frame (the id
    labels, the annotated frame; both by default, where the command line keeps none).
    The report is returned, not written: ``report.to_json()`` is the document the
    command line writes as ``<name>.report.json``; the top view is the command line's
    (``--keep plot``).  ``calibration``: the bench errors to estimate with
    the mirror (self-calibration, :class:`solver.selfcal.SelfCalibration`; needs two
    beacons or more, three for pan, scale and power together), how well the beacons'
    positions are known and what the bench knows of the nuisances.  ``board_pose``: the
    camera's pan, pitch and roll measured on the pegboard's holes in each frame
    (:func:`mirrorsim.detection.board.measure_camera_pose`), every α and d_total
    corrected by them, and the pan then known to the board's precision (a pan prior of
    ``calibration`` gives way to it); the pose is in the report.

    Raises
    ------
    DetectionError
        If an object is not found, or the target's d_total in no frame; with
        ``board_pose``, too few of the board's holes in a frame.
    OutputError
        If ``out_dir`` holds files mirrorsim did not write, or the scene's own file.
    BadParameter
        A ``keep`` that names no extra file; ``board_pose`` on a plain board.
    SolverError
        If the measurements do not determine the mirror and the target, or
        ``calibration`` is not a :class:`~solver.selfcal.SelfCalibration`.
    BackendError
        If no Mitsuba variant can render here.
    """
    check_given_scene(scene)  # edited by a script: held to what its file would make
    check_keep(keep)
    calibration = as_calibration(calibration)  # before anything renders
    error_model = as_error_model(error_model)
    check_board_pose(scene, board_pose)
    check_variant(variant)
    out = claim_run_folder(out_dir if out_dir is not None else default_out(scene.name),
                           "out_dir", [("scene", scene.source)])
    return evaluate_into(scene, out, variant=variant, progress=progress,
                         error_model=error_model, keep=keep, calibration=calibration,
                         board_pose=board_pose)


def check_board_pose(scene: Scene, board_pose: bool) -> None:
    """Refuse ``board_pose`` on a plain board (before a run claims its folder)."""
    if board_pose and scene.board.hole_pitch <= 0:
        raise BadParameter("board_pose", f"{scene.name}: its board is plain (board.hole_pitch "
                           "0): no holes to measure the camera's pose on")


def evaluate_into(scene: Scene, out: Path, *, variant: str = "auto", progress: bool = True,
                  error_model: ErrorModel | None = None, keep: tuple[str, ...] = EXTRA_FILES,
                  calibration: SelfCalibration = PLAIN, board_pose: bool = False,
                  model_priors: bool = True) -> Report:
    """:func:`evaluate_scene` into ``out``, a folder inside one its caller has claimed
    (a dataset's, a budget's): its parameters already checked.  ``model_priors``: the
    model's bench tolerances estimated with their priors (:func:`model_calibration`);
    False solves with ``calibration`` alone (a budget compares runs solved alike)."""
    cam = scene.camera
    per_beacon = frames_of(scene)
    measured = [render_and_measure(sub, out, variant=variant, progress=progress, reuse=True,
                                   ids="ids" in keep)
                for sub in per_beacon]
    frames = [_frame_record(m, out / f"{sub.name}.annotated.png", "annotated" in keep)
              for sub, m in zip(per_beacon, measured, strict=True)]
    truths = [m.files.truth for m in measured]
    # the scene's truth, computed once per frame: the target from the first, each beacon
    # from its own
    truth = replace(truths[0], scene=scene.name, id_labels=None, render=None,
                    beacons=tuple(t.beacons[0] for t in truths))
    seen = _seen(scene, measured, board_pose=board_pose)
    model = model_for(scene, error_model)
    features, sigma = _sigmas(model, seen)
    if model_priors:
        calibration = model_calibration(model, calibration)
    if seen.pose is not None:
        calibration, sigma = _after_board(seen.pose, seen.fx, calibration, sigma)
    capture = measured[0].files.capture
    notes = model.domain_warnings(
        features[0], list(features[1:]), seen.pan,
        scene={"fx_px": seen.fx, "camera_height_cm": capture.camera.height,
               "pencil_height_cm": tuple(b.height for b in scene.beacons),
               "beacons": len(scene.beacons)},
        bench=imperfections.judged_values(scene))
    measurements = Measurements(observer=cam.position, targets=[seen.target],
                                beacons=seen.beacons, sigma=sigma, observer_pan_deg=seen.pan)
    # the target once, at its mean over the frames: each frame's detection of the same
    # image shares its errors (bias included), so several would shrink its σ by √frames
    sol, calibration, said = solve_separated(cam.position, seen.beacons, [seen.target],
                                             sigma=sigma, calibration=calibration, model=model)
    errors = score(truth, measurements, sol, calibration=calibration)
    by_count = _error_vs_beacons(truth, measurements, calibration) + (errors,)
    done = truths[0].render  # how the frames were rendered, read back from the first
    return Report(scene=scene.name, truth=truth, measurements=measurements, solution=sol,
                  errors=errors, frames=tuple(frames),
                  render=RenderInfo(done.variant, done.spp, done.seed, done.sampler),
                  calibration=measured[-1].calibration,
                  error_vs_beacons=by_count if len(seen.beacons) > 1 else (),
                  camera_pose=seen.pose, error_model=model.name(),
                  model_warnings=tuple(notes), image_features=features,
                  self_calibration=calibration, calibration_notes=tuple(said))


@dataclass(frozen=True)
class _Seen:
    """What the experimenter measured: each beacon, the target at its mean over the
    frames, the pan (the capture record's, or the board's) and the focal length; the
    camera's pose from the board, where measured."""

    beacons: list[BeaconMeasurement]
    target: tuple[float, float]
    pan: float
    fx: float
    pose: CameraPose | None
    detections: list[Detection]


def _seen(scene: Scene, measured: list, *, board_pose: bool) -> _Seen:
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
    return _Seen(beacons, mean_target, pan, fx, pose, detections)


def _sigmas(model: ErrorModel, seen: _Seen
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


def _after_board(pose: CameraPose, fx: float, calibration: SelfCalibration,
                 sigma: ObjectSigmas) -> tuple[SelfCalibration, ObjectSigmas]:
    """The pan is the board's to know now, to what is left of it after the board: a prior
    from the mount's reading (the user's or the bench model's) gives way, and where the
    pan is not a nuisance, it is every α's shared offset."""
    left = pose_pan_sigma(pose, fx)
    if "pan" in calibration.nuisances:
        return (replace(calibration, priors={**calibration.priors, "pan": left}),
                replace(sigma, shared_alpha_deg=0.0))
    return calibration, replace(sigma, shared_alpha_deg=left)


def _error_vs_beacons(truth: GroundTruth, measurements: Measurements,
                      calibration: SelfCalibration) -> tuple[Score, ...]:
    """The score from the first k beacons, for each k short of all of them: solved
    self-calibrated with as many of the nuisances (in their order) as they can carry and
    separate, plain at the least, and scored against those k alone (their errors, and the
    bound k beacons give)."""
    m0 = measurements

    def first(k: int) -> Score:
        sig_k = replace(m0.sigma, beacons=m0.sigma.beacons[:k])
        meas_k = replace(m0, beacons=m0.beacons[:k], sigma=sig_k)
        truth_k = replace(truth, beacons=truth.beacons[:k])

        def scored(cal_k: SelfCalibration) -> Score:
            return score(truth_k, meas_k, solve_measurements(
                m0.observer, m0.beacons[:k], m0.targets, sigma=sig_k, calibration=cal_k),
                calibration=cal_k)

        for m in range(len(calibration.nuisances), 0, -1):
            try:
                return scored(calibration.first(m))
            except SolverError:
                continue
        return scored(calibration.first(0))

    return tuple(first(k) for k in range(1, len(m0.beacons)))


def frames_of(scene: Scene) -> list[Scene]:
    """The frames :func:`evaluate_scene` renders of ``scene``: the scene itself, or with
    several beacons one frame per beacon (``<name>_b<i>``, that beacon alone)."""
    if len(scene.beacons) == 1:
        return [scene]
    return [replace(scene, name=f"{scene.name}_b{i}", beacons=(b,))
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
        _paste_zoom(out, box)
    return out


def _paste_zoom(out: np.ndarray, box: tuple[int, int, int, int]) -> None:
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


def _frame_record(m: MeasuredFrame, annotated_path: Path, annotate_it: bool) -> FrameRecord:
    """The report's entry for one frame (its annotated copy written where asked)."""
    det = m.detection
    annotated = str(write_png(annotated_path, annotated_with_truth(m))) if annotate_it else ""
    return FrameRecord(str(m.files.image), annotated, m.files.reused, det.target.clipped,
                       det.beacons[0][1].clipped)
