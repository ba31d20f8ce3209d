"""End to end in three dimensions: render → detect (α, elevation, d_total of each image)
→ the 3-D solve (:func:`solver.lsq3.solve_lsq3`: the mirror's plane, its lean, the
target in 3-D) → score against the exact ground truth, with the planar solve of the
same frames beside it.  ``evaluate --geometry 3d`` (the default for a scene with a
raised object or a leaning mirror, docs/method.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from mirrorsim.detection.board import CameraPose
from mirrorsim.detection.detector import Detection
from mirrorsim.detection.image_geometry import elevation_of
from mirrorsim.detection.image_measurement import ImageMeasurement
from mirrorsim.detection.posed import corrected_image3
from mirrorsim.errors import BadParameter, DetectionError
from mirrorsim.formats.capture import CaptureRecord
from mirrorsim.formats.error_model import ErrorModel, ImageFeatures
from mirrorsim.pipelines.frame import render_and_measure
from mirrorsim.pipelines.measured import (
    after_board,
    frame_record,
    frames_of,
    seen_of,
    sigmas_of,
)
from mirrorsim.pipelines.score import KEPT_BY_DEFAULT, FrameRecord
from mirrorsim.pipelines.solving import model_calibration, model_for
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import FRONT_OFFSET, Scene, pencil_paint_height
from mirrorsim.scene.render_settings import AOVS
from mirrorsim.truth import optics
from mirrorsim.truth.groundtruth import GroundTruth, RenderInfo
from solver.errors import SolverError
from solver.geometry import wrap_bearing, yaw_difference
from solver.lsq import solve_measurements
from solver.lsq3 import Fit3, Measurements3, crlb3
from solver.measurements import ObjectSigmas, Sigma
from solver.selfcal import PLAIN, SelfCalibration
from solver.sltr3d import measured3

GEOMETRIES = ("auto", "3d", "planar")
# What a 3-D frame's images measure against the planar error model's σ's taken as a
# Gaussian's (ErrorModel.gaussian; α, ε from σ_d, d_total), per kind: the factor that
# puts 97.5 % of the development scenes' errors within 1.96 σ, none below 1 (`python
# benchmarks/evaluate3d.py --residuals` on 127 scenes with the models of 03cd43a and a
# panel's roll read on its sides where its top and foot slope apart: 70 of seeds 7001
# and 7002 and 57 of the wider generator's seeds 7003 and 7004 (`--wide`), 219 pencil
# and 127 panel images; the registered results are other seeds').  The errors' tails
# are heavier than a Gaussian's (a foot before the room or a post, a side with no
# contrast, a small frame's pencil leaning twice the mirror's lean), so the σ's are
# widened for them, never narrowed, and most ellipsoids are wider than their errors.
SIGMA3_FACTORS = {"beacon": (1.65, 1.30, 1.28), "target": (6.35, 6.26, 3.41)}
# the Mahalanobis radius of a 3-D Gaussian's 95 % region: √(χ²₃'s 0.95 quantile)
CHI2_3_R95 = math.sqrt(7.814727903251178)


def geometry_of(scene: Scene, geometry: str) -> str:
    """The solve a scene gets: ``3d`` or ``planar`` as asked, or for ``auto`` 3d where an
    object is raised or the mirror leans (:attr:`Scene.is_3d`), planar otherwise.

    Raises
    ------
    BadParameter
        Anything but :data:`GEOMETRIES`.
    """
    if geometry not in GEOMETRIES:
        raise BadParameter("geometry", f"{geometry!r}: expected one of {', '.join(GEOMETRIES)}")
    if geometry == "auto":
        return "3d" if scene.is_3d else "planar"
    return geometry


def elevation_sigma_deg(sigma: Sigma, height_px: float, fx: float) -> float:
    """σ of an image's elevation (deg) from its d_total's: the elevation rests on one
    edge (the foot's row), d_total on two (the foot's and the top's), so an edge's σ is
    σ_d·s/√2 px and the elevation's that over f (radians)."""
    return math.degrees(sigma.d_total_rel * height_px / math.sqrt(2.0) / fx)


@dataclass(frozen=True)
class Score3:
    """The 3-D estimate against the truth: the target's 3-D, plan and height errors (cm),
    the mirror's yaw and lean errors (deg), the true target's Mahalanobis distance from
    the estimate in its 3×3 covariance (the 95 % ellipsoid holds it below
    :data:`CHI2_3_R95`), the Cramér–Rao bound's and the covariance's RMS (cm), and the
    planar solve's plan error on the same frames (None where it failed); and what an
    exact detector reads off each image ((α, ε, d_total) of
    :func:`~solver.sltr3d.measured3` at the true geometry: the beacons', then the
    target's), against which the measurements' own errors are taken (in a leaning
    mirror they differ from the base's image, :class:`ObjectTruth`'s)."""

    target_cm: float
    target_plan_cm: float
    target_height_cm: float
    mirror_yaw_deg: float
    mirror_lean_deg: float
    target_mahalanobis: float
    target_crlb_cm: float | None
    target_covariance_rms_cm: float
    planar_target_cm: float | None
    exact_readings: tuple[tuple[float, float, float], ...] = ()

    @property
    def inside95(self) -> bool:
        """Whether the truth lies inside the estimate's 95 % ellipsoid."""
        return self.target_mahalanobis <= CHI2_3_R95

    def to_json(self) -> dict:
        """The report's ``errors`` block."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out["exact_readings"] = [{"alpha_deg": a, "elevation_deg": e, "d_total": d}
                                 for a, e, d in self.exact_readings]
        return {**out, "inside95": self.inside95}


@dataclass(frozen=True)
class Report3:
    """What ``mirrorsim evaluate --geometry 3d`` makes of a scene (docs/files.md)."""

    scene: str
    truth: GroundTruth
    seen: Measurements3
    fit: Fit3
    planar_target: tuple[float, float] | None
    errors: Score3
    frames: tuple[FrameRecord, ...]
    render: RenderInfo
    error_model: str
    model_warnings: tuple[str, ...] = ()
    # the α error every image of a frame shares (the model's): the solve's pan prior
    # (:func:`with_shared_pan`), which a caller solving these measurements again adds
    shared_alpha_deg: float = 0.0
    camera_pose: CameraPose | None = None  # the board's, where measured
    # what the solve estimated of the bench's shared errors, with the priors it took
    self_calibration: SelfCalibration = PLAIN
    # what each frame showed of each image (the target's, then each beacon's)
    image_features: tuple[ImageFeatures, ...] = ()
    # a 3-D model's ellipsoid scale, which widened the covariance (None: a planar model,
    # its σ's widened by SIGMA3_FACTORS)
    ellipsoid_scale: float | None = None

    @property
    def reused(self) -> bool:
        """Whether every frame was a cached render."""
        return all(f.reused for f in self.frames)

    def to_json(self) -> dict:
        """The report document (``<name>.report.json``)."""
        return {"scene": self.scene, "geometry": "3d", "truth": self.truth.to_json(),
                "measurements": self.seen.to_json(), "solution": self.fit.to_json(),
                "planar_solution": {"target": None if self.planar_target is None
                                    else list(self.planar_target)},
                "errors": self.errors.to_json(),
                "frames": [vars(fr) for fr in self.frames],
                "render": self.render.to_json(), "error_model": self.error_model,
                "model_warnings": list(self.model_warnings),
                "camera_pose": (None if self.camera_pose is None
                                else self.camera_pose.to_json()),
                "self_calibration": self.self_calibration.to_json()}


def evaluate_into3(scene: Scene, out: Path, *, variant: str = "auto", progress: bool = True,
                   error_model: ErrorModel | None = None,
                   keep: tuple[str, ...] = KEPT_BY_DEFAULT,
                   calibration: SelfCalibration = PLAIN, model_priors: bool = True,
                   board_pose: bool = False) -> Report3:
    """Render (or reuse), detect in 3-D, solve in 3-D and score ``scene`` into ``out``, a
    folder its caller has claimed, its parameters checked
    (:func:`mirrorsim.pipelines.evaluate.evaluate_scene` with ``geometry``);
    ``calibration``: the pan, pitch, range scale and mirror's power to estimate, and what
    the user states of them, beside the bench model's own
    (``model_priors`` False: ``calibration``'s alone, as a budget compares its runs);
    ``board_pose``: every image read again through the camera's pose the board's holes
    give (:func:`~mirrorsim.detection.posed.corrected_image3`), the pan then the board's.

    Raises
    ------
    DetectionError
        An object not found, or the target's d_total in no frame.
    SolverError
        The measurements do not determine the mirror's plane and the target.
    """
    per_beacon = frames_of(scene)
    measured = [render_and_measure(sub, out, variant=variant, progress=progress, reuse=True,
                                   ids="ids" in keep, aov=tuple(k for k in keep if k in AOVS))
                for sub in per_beacon]
    frames = tuple(frame_record(m, out / f"{sub.name}.annotated.png", "annotated" in keep)
                   for sub, m in zip(per_beacon, measured, strict=True))
    truths = [m.files.truth for m in measured]
    truth = replace(truths[0], scene=scene.name, id_labels=None, render=None, annotations=None,
                    beacons=tuple(t.beacons[0] for t in truths))
    seen2, model = seen_of(scene, measured, board_pose=board_pose), model_for(scene, error_model)
    features, sigma = sigmas_of(model, seen2)
    cal, sigma = nuisances3(model, sigma, calibration, bench=model_priors,
                            board=None if seen2.pose is None else (seen2.pose, seen2.fx))
    # the 3-D solve draws a Gaussian's ellipsoid: the σ's as a Gaussian's (a 3-D model's
    # own, the elevation's too; a planar model's widened by the factors fitted on them)
    seen = _seen3(scene, measured, model.gaussian(sigma), fx=seen2.fx, pose=seen2.pose,
                  elevations=model.gaussian_elevations(features, seen2.pan, fx_px=seen2.fx))
    fit = solved3(seen, cal, model.ellipsoid_scale)
    try:  # the planar solve of the same frames, beside it
        planar = solve_measurements(scene.camera.position, seen2.beacons, [seen2.target],
                                    sigma=sigma).target
        planar_target = (float(planar[0]), float(planar[1]))
    except SolverError:
        planar_target = None
    errors = _score3(scene, truth, fit, seen, planar_target, calibration=cal)
    done = truths[0].render
    keys = {"fx_px": seen2.fx, "camera_height_cm": scene.camera.height,
            "pencil_height_cm": tuple(b.height for b in scene.beacons),
            "beacons": len(scene.beacons)}
    notes = model.domain_warnings(features[0], list(features[1:]), seen2.pan, scene=keys,
                                  bench=imperfections.judged_values(scene))
    return Report3(scene=scene.name, truth=truth, seen=seen, fit=fit,
                   planar_target=planar_target, errors=errors, frames=frames,
                   render=RenderInfo(done.variant, done.spp, done.seed, done.sampler),
                   error_model=model.name(), model_warnings=tuple(notes),
                   shared_alpha_deg=sigma.shared_alpha_deg, camera_pose=seen2.pose,
                   self_calibration=cal, image_features=features,
                   ellipsoid_scale=model.ellipsoid_scale if model.three_d else None)


def frame_measurements3(det: Detection, capture: CaptureRecord) -> Measurements3:
    """One frame's measurements in 3-D (what ``detect`` writes for a 3-D capture record):
    each beacon's believed base with its mirror image's (α, ε, d_total)
    (:func:`~mirrorsim.detection.image_geometry.elevation_of`), the target's, the heights
    measured and the measured faces' offsets; no σ's.

    Raises
    ------
    DetectionError
        The target's d_total was not measured.
    """
    if det.target.d_total is None:
        raise DetectionError("the target's d_total could not be measured (its image is "
                             "clipped at the top)")
    return _measurements3(capture, [(b, _reading(capture, im)) for b, im in det.beacons],
                          _reading(capture, det.target))


def _reading(capture: CaptureRecord, m: ImageMeasurement) -> tuple[float, float, float]:
    """An image's (α, ε, d_total) as the capture record's camera sees it."""
    return (m.alpha_deg, *elevation_of(capture.camera, m))


def _measurements3(capture: CaptureRecord, pencils: list, target: tuple[float, float, float],
                   sigma: tuple | None = None, pan: float | None = None) -> Measurements3:
    """Measurements3 of ``pencils`` (each beacon and its image's reading) and the
    target's reading, with what the capture record says: the lens, the pan (or ``pan``,
    the board's), the heights measured (each painted band, the panel's) and the faces'
    offsets."""
    return Measurements3(
        observer=tuple(float(c) for c in capture.camera.center3),
        beacons=tuple((tuple(float(c) for c in b.base3), seen) for b, seen in pencils),
        target=target,
        heights=(*(pencil_paint_height(b.height) for b, _ in pencils), capture.target_size[1]),
        fronts=(FRONT_OFFSET["beacon"],) * len(pencils) + (FRONT_OFFSET["target"],),
        sigma=sigma, pan_deg=capture.camera.pan_deg if pan is None else pan)


def _seen3(scene: Scene, measured: list, sigma: ObjectSigmas, *, fx: float,
           pose: CameraPose | None = None,
           elevations: tuple[float, ...] | None = None) -> Measurements3:
    """The frames' measurements together: every beacon's, the target's mean over the
    frames that measured it (each frame's view shares its errors), and each
    observation's σ's: ``sigma``'s with ``elevations`` (a 3-D model's: the target's, then
    each beacon's), or a planar model's widened by SIGMA3_FACTORS, the elevation's from
    the d_total's; with the board's ``pose``, each read through it."""
    with_target = [m for m in measured if m.detection.target.d_total is not None]
    if not with_target:
        raise DetectionError(f"{scene.name}: the target's d_total could not be measured")
    pencils = [(b, im, m.files.capture) for m in measured for b, im in m.detection.beacons]
    per_beacon = (sigma.beacons if len(sigma.beacons) == len(pencils)
                  else sigma.beacons[:1] * len(pencils))
    sig = sigma3([*per_beacon, sigma.target],
                 [im.height_px for _, im, _ in pencils]
                 + [with_target[0].detection.target.height_px], fx=fx,
                 elevations=None if elevations is None else (*elevations[1:], elevations[0]))
    def reading(c: CaptureRecord, im: ImageMeasurement, top: float) -> tuple:
        return (_reading(c, im) if pose is None
                else corrected_image3(pose, c.camera, im, top=top))

    target = tuple(float(v) for v in np.mean(
        [reading(m.files.capture, m.detection.target, m.files.capture.target_size[1])
         for m in with_target], axis=0))
    capture = with_target[0].files.capture
    return _measurements3(capture, [(b, reading(c, im, pencil_paint_height(b.height)))
                                    for b, im, c in pencils], target, sigma=tuple(sig),
                          pan=float(wrap_bearing(capture.camera.pan_deg + (
                              0.0 if pose is None else pose.pan_offset_deg))))


def solved3(seen: Measurements3, calibration: SelfCalibration, scale: float = 1.0) -> Fit3:
    """``seen`` solved in 3-D with ``calibration``'s nuisances, priors and position σ, its
    covariance widened by ``scale`` (a 3-D model's ellipsoid scale)."""
    fit = seen.solve(nuisances=calibration.nuisances, priors=calibration.priors,
                     position_sigma=calibration.position_sigma)
    if scale == 1.0 or fit.covariance is None:
        return fit
    return replace(fit, covariance=fit.covariance * scale**2)


def sigma3(sigmas: list[Sigma], heights: list[float], *, fx: float,
           elevations: tuple[float, ...] | None) -> list[tuple[float, float, float]]:
    """Each image's (σ_α, σ_ε, σ_d) as the 3-D solve weighs it (the beacons', then the
    target's): a 3-D model's, or a planar model's widened (:func:`_seen3`)."""
    if elevations is not None:
        return [(s.alpha_deg, e, s.d_total_rel)
                for s, e in zip(sigmas, elevations, strict=True)]
    kinds = ["beacon"] * (len(sigmas) - 1) + ["target"]
    return [(SIGMA3_FACTORS[k][0] * s.alpha_deg,
             SIGMA3_FACTORS[k][1] * elevation_sigma_deg(s, h, fx),
             SIGMA3_FACTORS[k][2] * s.d_total_rel)
            for k, s, h in zip(kinds, sigmas, heights, strict=True)]


def nuisances3(model: ErrorModel, sigma: ObjectSigmas, asked: SelfCalibration = PLAIN, *,
               bench: bool = True, board: tuple[CameraPose, float] | None = None
               ) -> tuple[SelfCalibration, ObjectSigmas]:
    """The bench's shared errors the 3-D solve estimates, with their priors and the
    beacons' position σ, and the σ's it weighs with: those ``asked`` (a prior or a
    position σ the user states wins over the model's), and (``bench``) the pan, range
    scale, power and beacons' positions a bench model's tolerances give; an α error every
    image of a frame shares widens the pan's prior (an ideal-bench model, asked nothing:
    none).  ``board``: the camera's pose the board gave and the frames' focal length:
    the pan is then the board's (:func:`~mirrorsim.pipelines.measured.after_board`)."""
    cal = model_calibration(model, asked) if bench else asked
    if board is not None:
        cal, sigma = after_board(board[0], cal, sigma, fx=board[1])
    nuisances, priors = with_shared_pan(cal, sigma.shared_alpha_deg)
    return SelfCalibration(nuisances, cal.position_sigma, priors), sigma


def with_shared_pan(calibration: SelfCalibration, shared_alpha_deg: float
                    ) -> tuple[tuple[str, ...], dict[str, float]]:
    """``calibration``'s nuisances (the 3-D solve estimates every one a SelfCalibration
    admits, :data:`solver.selfcal.KNOWN`), with their priors, and an α error every image
    of a frame shares as the pan's prior (widening the one it has; none where the pan is
    free)."""
    nuisances = calibration.nuisances
    priors = dict(calibration.priors)
    if shared_alpha_deg and ("pan" in priors or "pan" not in nuisances):
        priors["pan"] = math.hypot(priors.get("pan", 0.0), shared_alpha_deg)
        nuisances = tuple(dict.fromkeys((*nuisances, "pan")))
    return nuisances, priors


def _score3(scene: Scene, truth: GroundTruth, fit: Fit3, seen: Measurements3,
            planar_target: tuple[float, float] | None, *,
            calibration: SelfCalibration) -> Score3:
    """The 3-D estimate against the truth (:class:`Score3`)."""
    t_true = np.asarray(truth.target.position, float)
    if len(t_true) == 2:  # a planar scene solved in 3-D: its target stands on the board
        t_true = np.r_[t_true, scene.target.z]
    err = fit.target - t_true
    cov = fit.target_covariance
    plane = optics.mirror_plane(scene.camera, scene.mirror)
    try:
        bound = crlb3(seen.observer, [p for p, _ in seen.beacons], plane, target=t_true,
                      sigma=np.array(seen.sigma), heights=seen.heights, fronts=seen.fronts,
                      pan_deg=seen.pan_deg, nuisances=calibration.nuisances,
                      priors=calibration.priors, position_sigma=calibration.position_sigma)
        crlb = float(np.sqrt(np.trace(bound[3:6, 3:6])))
    except SolverError:
        crlb = None
    yaw_err = float(yaw_difference(fit.plane.yaw_deg, scene.mirror.yaw))
    bases = [b.base3 for b in scene.beacons] + [scene.target.base3]
    exact = tuple(measured3(seen.observer, plane, p, height=h, front=f, pan_deg=seen.pan_deg)
                  for p, h, f in zip(bases, seen.heights, seen.fronts, strict=True))
    return Score3(
        target_cm=float(np.linalg.norm(err)), target_plan_cm=float(np.hypot(*err[:2])),
        target_height_cm=float(err[2]), mirror_yaw_deg=yaw_err,
        mirror_lean_deg=float(fit.plane.lean_deg - scene.mirror.lean),
        target_mahalanobis=float(np.sqrt(err @ np.linalg.solve(cov, err))),
        target_crlb_cm=crlb, target_covariance_rms_cm=float(np.sqrt(np.trace(cov))),
        planar_target_cm=None if planar_target is None else float(
            np.hypot(planar_target[0] - t_true[0], planar_target[1] - t_true[1])),
        exact_readings=exact)
