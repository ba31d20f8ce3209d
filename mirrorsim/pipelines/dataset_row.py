"""A dataset's row: one scene's parameters, each object's truth, measurement and σ, the
solution and its errors, under the columns :mod:`mirrorsim.formats.dataset_table`
declares (each beacon's under its own prefix)."""

from __future__ import annotations

import math

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.pipelines.score import Report
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import Scene
from mirrorsim.truth.groundtruth import ObjectTruth
from solver.geometry import yaw_difference
from solver.selfcal import NUISANCES, priors_text


def row_of(scene: Scene, rep: Report) -> dict:
    """The row's columns: scene parameters, truth, measurements, solution, errors (each
    beacon's under its own prefix, :func:`~mirrorsim.formats.dataset_table.beacon_kind`;
    the self-calibration the report solved with)."""
    return {**_scene_columns(scene, rep), **_object_columns(scene, rep),
            **_solution_columns(rep)}


def _scene_columns(scene: Scene, rep: Report) -> dict:
    """The scene's parameters, its render, its bench and what the solve was given."""
    cam, mir, meas = scene.camera, scene.mirror, rep.measurements
    row = {
        "camera_x": cam.position[0], "camera_y": cam.position[1], "camera_height": cam.height,
        "camera_pan_deg": cam.pan_deg, "hfov_deg": cam.hfov,
        "mirror_x": mir.center[0], "mirror_y": mir.center[1], "mirror_yaw_deg": mir.yaw % 180,
        "mirror_width": mir.size[0], "mirror_height": mir.size[1],
        "target_x": scene.target.position[0], "target_y": scene.target.position[1],
        "beacons": len(scene.beacons), "pencil_height_cm": scene.beacons[0].height,
        "calibrate": ",".join(rep.self_calibration.nuisances),
        "calibrate_priors": priors_text(rep.self_calibration.priors),
        "variant": rep.render.variant, "spp": rep.render.spp, "sampler": rep.render.sampler,
        "background_spp": scene.render.outside_spp(),
        "beacon_spp": scene.render.beacon_box_spp(),
        "render_seed": rep.render.seed,
        **imperfections.row_values(scene),
    }
    row.update({"observer_x": meas.observer[0], "observer_y": meas.observer[1],
                "observer_pan_deg": meas.observer_pan_deg,  # the capture record's
                "fx_px": scene.camera.fx, "beacon_sigma": rep.self_calibration.position_sigma})
    return row


def _object_columns(scene: Scene, rep: Report) -> dict:
    """The target's and each beacon's truth, measurement, features and σ's."""
    cam, t, meas = scene.camera, rep.truth, rep.measurements
    row = {}
    sig = meas.sigma
    # the target as measured (its mean over the frames), clipped as in the first frame;
    # each beacon from its own frame
    seen = rep.image_features  # the target's, then each beacon's
    objects = [("target", t.target, meas.targets[0], rep.frames[0].target_clipped,
                sig.target, seen[0])]
    for k, (b, frame) in enumerate(zip(meas.beacons, rep.frames, strict=True)):
        kind = table.beacon_kind(k)
        row.update({table.object_column(kind, "known_x"): b.position[0],
                    table.object_column(kind, "known_y"): b.position[1]})
        objects.append((kind, t.beacons[k], (b.alpha_deg, b.d_total), frame.beacon_clipped,
                        sig.beacons[k], seen[1 + k]))
    for kind, truth, (alpha, d), clipped, s, f in objects:
        values = {
            "pos_x": truth.position[0], "pos_y": truth.position[1],
            "alpha_true": truth.alpha_deg, "d_true": truth.d_total,
            "d1": truth.d1, "d2": truth.d2,
            "off_axis_deg": (truth.alpha_deg - cam.pan_deg + 180.0) % 360.0 - 180.0,
            "incidence_deg": _incidence_deg(scene, truth),
            "height_px_true": truth.image_px.height,
            "alpha_meas": alpha, "d_meas": d,
            "alpha_err": alpha - truth.alpha_deg,
            "d_rel_err": (d - truth.d_total) / truth.d_total,
            "clipped": bool(clipped),
            "height_px_meas": f.height_px, "contrast": f.contrast, "noise": f.noise,
            "jpeg_quality": f.jpeg_quality,
            "sigma_alpha_deg": s.alpha_deg, "sigma_d_rel": s.d_total_rel,
        }
        row.update({table.object_column(kind, name): v for name, v in values.items()})
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


def _incidence_deg(scene: Scene, truth: ObjectTruth) -> float:
    """Angle between the camera's ray to the mirror and the mirror's normal."""
    ray = np.asarray(truth.reflection_point) - np.asarray(scene.camera.position, float)
    ray_bearing = math.degrees(math.atan2(ray[1], ray[0]))
    return 90.0 - float(yaw_difference(ray_bearing, scene.mirror.yaw))
