"""End to end: render → detect → solve → score against the exact ground truth.

One frame per beacon (a scene with ``beacons:`` renders each beacon alone, as a moving
beacon would be photographed at each pose); the target is measured in every frame.
The solver sees only the measurements; the score compares its estimate with the
ground truth.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from mirrorsim.errors import BadParameter
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.files import claim_run_folder, default_out
from mirrorsim.pipelines.evaluate3d import (
    Report3,
    evaluate_into3,
    geometry_of,
)
from mirrorsim.pipelines.frame import render_and_measure
from mirrorsim.pipelines.measured import (
    after_board,
    frame_record,
    frames_of,
    seen_of,
    sigmas_of,
)
from mirrorsim.pipelines.scenes import check_given_scene
from mirrorsim.pipelines.score import (
    KEPT_BY_DEFAULT,
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
from mirrorsim.scene.model import Scene
from mirrorsim.scene.render_settings import AOVS
from mirrorsim.truth.groundtruth import GroundTruth, RenderInfo
from solver.errors import SolverError
from solver.lsq import solve_measurements
from solver.measurements import Measurements
from solver.selfcal import PLAIN, SelfCalibration, as_calibration, check_planar


def evaluate_scene(scene: Scene, out_dir: str | Path | None = None, *, variant: str = "auto",
                   progress: bool = True, error_model: ErrorModel | None = None,
                   keep: tuple[str, ...] = KEPT_BY_DEFAULT,
                   calibration: SelfCalibration = PLAIN, board_pose: bool = False,
                   geometry: str = "auto") -> Report | Report3:
    """Render (or reuse) with the scene's render settings, detect, solve and score
    ``scene``; return the report.

    ``error_model``: gives each measurement its σ's, which weight the solver and make
    its error ellipse (default: the model shipped for the ideal bench at the default
    render settings).  ``keep``: which of EXTRA_FILES to write beside each frame (the id
    labels, the annotated frame, the frame's depth and normals; the first two by
    default, where the command line keeps none).
    The report is returned, not written: ``report.to_json()`` is the document the
    command line writes as ``<name>.report.json``; the top view is the command line's
    (``--keep plot``).  ``calibration``: the bench errors to estimate with
    the mirror (self-calibration, :class:`solver.selfcal.SelfCalibration`; needs two
    beacons or more, three for pan, scale and power together), how well the beacons'
    positions are known and what the bench knows of the nuisances.  ``board_pose``: the
    camera's pan, pitch and roll measured on the pegboard's holes in each frame
    (:func:`mirrorsim.detection.board.measure_camera_pose`), every α and d_total
    corrected by them (in 3-D each elevation too), and the pan then known to the board's
    precision (a pan prior of
    ``calibration`` gives way to it); the pose is in the report.  ``geometry``: 3d
    solves in 3-D (a :class:`~mirrorsim.pipelines.evaluate3d.Report3`), planar in the
    board's plane, auto 3d for a scene with a raised object or a leaning mirror.

    Raises
    ------
    DetectionError
        If an object is not found, or the target's d_total in no frame; with
        ``board_pose``, too few of the board's holes in a frame.
    OutputError
        If ``out_dir`` holds files mirrorsim did not write, or the scene's own file.
    BadParameter
        A ``keep`` that names no extra file; ``board_pose`` on a plain board; a bad
        ``geometry``; with 3d, a calibration of the beacons' positions (the 3-D solve
        estimates pan, pitch, range scale and the mirror's power).
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
    check_board_pose(scene, board_pose, calibration)
    check_variant(variant)
    three_d = check_geometry(scene, geometry, calibration=calibration) == "3d"
    out = claim_run_folder(out_dir if out_dir is not None else default_out(scene.name),
                           "out_dir", [("scene", scene.source)])
    if three_d:
        return evaluate_into3(scene, out, variant=variant, progress=progress,
                              error_model=error_model, keep=keep, calibration=calibration,
                              board_pose=board_pose)
    return evaluate_into(scene, out, variant=variant, progress=progress,
                         error_model=error_model, keep=keep, calibration=calibration,
                         board_pose=board_pose)


def check_geometry(scene: Scene, geometry: str, *,
                   calibration: SelfCalibration = PLAIN) -> str:
    """The solve ``scene`` gets (:func:`~mirrorsim.pipelines.evaluate3d.geometry_of`),
    refusing a planar solve's pitch before a run claims its folder (a 3-D solve takes
    every nuisance a SelfCalibration admits)."""
    chosen = geometry_of(scene, geometry)
    if chosen == "planar":
        try:
            check_planar(calibration)
        except SolverError as exc:
            raise BadParameter("calibration", f"{scene.name}: {exc}") from None
    return chosen


def check_board_pose(scene: Scene, board_pose: bool,
                     calibration: SelfCalibration = PLAIN) -> None:
    """Refuse ``board_pose`` on a plain board, and with it a pitch to estimate (the board
    measures it, every elevation read through it), before a run claims its folder."""
    if board_pose and scene.board.hole_pitch <= 0:
        raise BadParameter("board_pose", f"{scene.name}: its board is plain (board.hole_pitch "
                           "0): no holes to measure the camera's pose on")
    if board_pose and "pitch" in calibration.nuisances:
        raise BadParameter("nuisances", f"{scene.name}: pitch, with the board's pose: the "
                           "board measures the camera's pitch, and every elevation is read "
                           "through it")


def evaluate_into(scene: Scene, out: Path, *, variant: str = "auto", progress: bool = True,
                  error_model: ErrorModel | None = None, keep: tuple[str, ...] = KEPT_BY_DEFAULT,
                  calibration: SelfCalibration = PLAIN, board_pose: bool = False,
                  model_priors: bool = True) -> Report:
    """:func:`evaluate_scene` into ``out``, a folder inside one its caller has claimed
    (a dataset's, a budget's): its parameters already checked.  ``model_priors``: the
    model's bench tolerances estimated with their priors (:func:`model_calibration`);
    False solves with ``calibration`` alone (a budget compares runs solved alike)."""
    cam = scene.camera
    per_beacon = frames_of(scene)
    measured = [render_and_measure(sub, out, variant=variant, progress=progress, reuse=True,
                                   ids="ids" in keep,
                                   aov=tuple(k for k in keep if k in AOVS))
                for sub in per_beacon]
    frames = [frame_record(m, out / f"{sub.name}.annotated.png", "annotated" in keep)
              for sub, m in zip(per_beacon, measured, strict=True)]
    truths = [m.files.truth for m in measured]
    # the scene's truth, computed once per frame: the target from the first, each beacon
    # from its own
    # (a 3-D scene solved in the plane is scored against its truth in plan)
    truth = replace(truths[0], scene=scene.name, id_labels=None, render=None, annotations=None,
                    beacons=tuple(t.beacons[0] for t in truths)).in_plan()
    seen = seen_of(scene, measured, board_pose=board_pose)
    model = model_for(scene, error_model)
    features, sigma = sigmas_of(model, seen)
    if model_priors:
        calibration = model_calibration(model, calibration)
    if seen.pose is not None:
        calibration, sigma = after_board(seen.pose, calibration, sigma, fx=seen.fx)
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


