"""A dataset's row: one scene's parameters, each object's truth, measurement and σ, the
solution and its errors, under the columns :mod:`mirrorsim.formats.dataset_table`
declares (each beacon's under its own prefix): of a planar solve (:func:`row_of`) or a
3-D one (:func:`row_of3`, each image's elevation beside its α and d_total)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.error_model import ImageFeatures
from mirrorsim.pipelines.score import Report
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import Scene
from mirrorsim.truth.groundtruth import ObjectTruth
from solver.geometry import yaw_difference
from solver.selfcal import KNOWN, NUISANCES, priors_text

if TYPE_CHECKING:  # (evaluate3d imports the renderer: a planar dataset's rows need none)
    from mirrorsim.pipelines.evaluate3d import Report3

# an image's (α deg, elevation deg or None in the plane, d_total cm), and its σ's (α deg,
# elevation deg or None, d_total relative)
Reading = tuple[float, float | None, float]


@dataclass(frozen=True)
class _Image:
    """One object's image as a row takes it: its column prefix, its truth, what an exact
    detector reads, what was measured, its σ's, whether it was clipped, what the frame
    showed of it, and (a beacon's) the position the solver was given."""

    kind: str
    truth: ObjectTruth
    exact: Reading
    measured: Reading
    sigma: Reading
    clipped: str
    seen: ImageFeatures
    known: tuple[float, ...] | None = None


def row_of(scene: Scene, rep: Report) -> dict:
    """The row's columns of a planar solve: scene parameters, truth, measurements,
    solution, errors (each beacon's under its own prefix,
    :func:`~mirrorsim.formats.dataset_table.beacon_kind`; the self-calibration the
    report solved with)."""
    t, meas, seen = rep.truth, rep.measurements, rep.image_features
    # the target as measured (its mean over the frames), clipped as in the first frame;
    # each beacon from its own frame
    (ta, td), st = meas.targets[0], meas.sigma.target
    images = [_Image("target", t.target, (t.target.alpha_deg, None, t.target.d_total),
                     (ta, None, td), (st.alpha_deg, None, st.d_total_rel),
                     rep.frames[0].target_clipped, seen[0])]
    for k, (b, frame) in enumerate(zip(meas.beacons, rep.frames, strict=True)):
        tb, s = t.beacons[k], meas.sigma.beacons[k]
        images.append(_Image(table.beacon_kind(k), tb, (tb.alpha_deg, None, tb.d_total),
                             (b.alpha_deg, None, b.d_total), (s.alpha_deg, None, s.d_total_rel),
                             frame.beacon_clipped, seen[1 + k], tuple(b.position)))
    row = {"geometry": "planar",
           **_scene_columns(scene, rep.self_calibration, rep.render,
                            (*meas.observer, meas.observer_pan_deg)),
           **_object_columns(scene, images), **_solution_columns(rep)}
    return row | {c: None for c in table.SOLUTION_3D}


def row_of3(scene: Scene, rep: Report3) -> dict:
    """The row's columns of a 3-D solve (:func:`row_of`'s, each image's elevation beside
    its α and d_total, read against what an exact detector reads of it, and the 3-D
    solution's)."""
    t, seen, exact = rep.truth, rep.seen, rep.errors.exact_readings
    n = len(seen.beacons)
    images = [_Image("target", t.target, exact[n], seen.target, seen.sigma[n],
                     rep.frames[0].target_clipped, rep.image_features[0])]
    for k, ((position, reading), frame) in enumerate(zip(seen.beacons, rep.frames,
                                                         strict=True)):
        images.append(_Image(table.beacon_kind(k), t.beacons[k], exact[k], reading,
                             seen.sigma[k], frame.beacon_clipped, rep.image_features[1 + k],
                             tuple(position[:2])))
    return {"geometry": "3d",
            **_scene_columns(scene, rep.self_calibration, rep.render,
                             (*seen.observer[:2], seen.pan_deg)),
            **_object_columns(scene, images), **_solution3_columns(rep)}


def _scene_columns(scene: Scene, calibration, render, observer: tuple[float, float, float]
                   ) -> dict:
    """The scene's parameters, its render, its bench and what the solve was given (the
    self-calibration, and ``observer``: the lens's plan position and the pan its mount
    reported)."""
    cam, mir = scene.camera, scene.mirror
    return {
        "camera_x": cam.position[0], "camera_y": cam.position[1], "camera_height": cam.height,
        "camera_pan_deg": cam.pan_deg, "hfov_deg": cam.hfov,
        "mirror_x": mir.center[0], "mirror_y": mir.center[1], "mirror_yaw_deg": mir.yaw % 180,
        "mirror_width": mir.size[0], "mirror_height": mir.size[1],
        "mirror_lean_deg": mir.lean,
        "target_x": scene.target.position[0], "target_y": scene.target.position[1],
        "target_z": scene.target.z,
        "beacons": len(scene.beacons), "pencil_height_cm": scene.beacons[0].height,
        "calibrate": ",".join(calibration.nuisances),
        "calibrate_priors": priors_text(calibration.priors),
        "variant": render.variant, "spp": render.spp, "sampler": render.sampler,
        "background_spp": scene.render.outside_spp(),
        "beacon_spp": scene.render.beacon_box_spp(),
        "render_seed": render.seed,
        **imperfections.row_values(scene),
        "observer_x": observer[0], "observer_y": observer[1],
        "observer_pan_deg": observer[2],  # the capture record's
        "fx_px": scene.camera.fx, "beacon_sigma": calibration.position_sigma,
    }


def _object_columns(scene: Scene, images: list[_Image]) -> dict:
    """The target's and each beacon's truth, measurement, features and σ's."""
    row = {}
    for im in images:
        if im.known is not None:
            row.update({table.object_column(im.kind, "known_x"): im.known[0],
                        table.object_column(im.kind, "known_y"): im.known[1]})
        (a_true, e_true, d_true), (alpha, elev, d) = im.exact, im.measured
        truth, f, s = im.truth, im.seen, im.sigma
        values = {
            "pos_x": truth.position[0], "pos_y": truth.position[1],
            "pos_z": truth.position[2] if len(truth.position) > 2 else 0.0,
            "alpha_true": a_true, "d_true": d_true,
            "d1": truth.d1, "d2": truth.d2,
            "off_axis_deg": (a_true - scene.camera.pan_deg + 180.0) % 360.0 - 180.0,
            "incidence_deg": _incidence_deg(scene, truth),
            "height_px_true": truth.image_px.height,
            "alpha_meas": alpha, "d_meas": d,
            "alpha_err": alpha - a_true,
            "d_rel_err": (d - d_true) / d_true,
            "elevation_true": e_true, "elevation_meas": elev,
            "elevation_err": None if elev is None else elev - e_true,
            "clipped": bool(im.clipped),
            "height_px_meas": f.height_px, "contrast": f.contrast, "noise": f.noise,
            "jpeg_quality": f.jpeg_quality,
            "sigma_alpha_deg": s[0], "sigma_elevation_deg": s[1], "sigma_d_rel": s[2],
        }
        row.update({table.object_column(im.kind, name): v for name, v in values.items()})
    return row


def _solution_columns(rep: Report) -> dict:
    """The solution, its errors against the truth and its covariance."""
    sol, err = rep.solution, rep.errors
    cov = sol.target_covariance
    return {
        "est_target_x": float(sol.target[0]), "est_target_y": float(sol.target[1]),
        "est_mirror_yaw_deg": sol.mirror.yaw_deg,
        "err_target_cm": err.target_cm, "err_mirror_yaw_deg": err.mirror_yaw_deg,
        "err_mirror_offset_cm": err.mirror_offset_cm,
        "err_reflection_point_cm": err.reflection_point_cm,
        "target_ellipse95_major_cm": (math.nan if err.target_ellipse95_major_cm is None
                                      else err.target_ellipse95_major_cm),
        "target_cov_xx": float(cov[0, 0]), "target_cov_xy": float(cov[0, 1]),
        "target_cov_yy": float(cov[1, 1]), "target_mahalanobis": err.target_mahalanobis,
        **{f"est_{key}": sol.nuisances.get(key, math.nan) for key, _ in NUISANCES.values()},
        **{f"est_{key}_sd": sol.nuisance_sd.get(key, math.nan)
           for key, _ in NUISANCES.values()},
    }


def _solution3_columns(rep: Report3) -> dict:
    """The 3-D solution, its errors against the truth and its 3×3 covariance (the planar
    solve's columns it has no value for: null)."""
    from mirrorsim.pipelines.evaluate3d import CHI2_3_R95

    fit, err = rep.fit, rep.errors
    cov = fit.target_covariance
    sd = fit.nuisance_sd or {}
    estimates = {f"est_{KNOWN[n][0]}": v for n, v in fit.nuisances.items()}
    estimates |= {f"est_{KNOWN[n][0]}_sd": v for n, v in sd.items()}
    return {
        "est_target_x": float(fit.target[0]), "est_target_y": float(fit.target[1]),
        "est_target_z": float(fit.target[2]),
        "est_mirror_yaw_deg": fit.plane.yaw_deg, "est_mirror_lean_deg": fit.plane.lean_deg,
        "err_target_cm": err.target_cm, "err_mirror_yaw_deg": err.mirror_yaw_deg,
        "err_target_height_cm": err.target_height_cm,
        "err_mirror_lean_deg": err.mirror_lean_deg,
        "err_mirror_offset_cm": None, "err_reflection_point_cm": None,
        "target_ellipse95_major_cm": CHI2_3_R95 * math.sqrt(float(np.linalg.eigvalsh(cov)[-1])),
        **{f"target_cov_{a}{b}": float(cov[i, j])
           for a, b, i, j in (("x", "x", 0, 0), ("x", "y", 0, 1), ("y", "y", 1, 1),
                              ("x", "z", 0, 2), ("y", "z", 1, 2), ("z", "z", 2, 2))},
        "target_mahalanobis": err.target_mahalanobis,
        "planar_err_target_cm": err.planar_target_cm,
        **{f"est_{key}{s}": None for key, _ in KNOWN.values() for s in ("", "_sd")},
        **estimates,
    }


def _incidence_deg(scene: Scene, truth: ObjectTruth) -> float:
    """Angle between the camera's ray to the mirror and the mirror's normal, in plan."""
    ray = np.asarray(truth.reflection_point[:2]) - np.asarray(scene.camera.position, float)
    ray_bearing = math.degrees(math.atan2(ray[1], ray[0]))
    return 90.0 - float(yaw_difference(ray_bearing, scene.mirror.yaw))
