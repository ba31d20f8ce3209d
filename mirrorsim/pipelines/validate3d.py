"""A 3-D model's training rows solved again: each usable row of a 3-D dataset (its
measurements file), weighed with the model's σ's and solved in 3-D as ``evaluate``
solves it, and the truth's Mahalanobis distance from each estimate.  The 95th
percentile of those distances over χ₃'s 95 % radius is the model's ellipsoid scale
(:attr:`~mirrorsim.formats.error_model.ErrorModel.ellipsoid_scale`): the detector's
errors are heavier-tailed than a Gaussian's, and a frame's readings are not
independent, so a covariance of each reading's σ's alone holds fewer truths than it
says (measured: 0.82–0.85 of the acceptance sets' at 95 %), as the planar model's
target tail widens its ellipses.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.dataset_rows import read_description
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.measurements import load_measurements
from mirrorsim.pipelines.evaluate3d import CHI2_3_R95, nuisances3, sigma3, solved3
from mirrorsim.pipelines.uncertainty import image_features_of
from solver.errors import SolverError
from solver.lsq3 import Measurements3
from solver.selfcal import SelfCalibration

SCALE_LEVEL = 0.95  # the share of the training rows' truths the 95 % ellipsoid holds


def distances3(model: ErrorModel, dataset_dir: str | Path, cols: dict) -> np.ndarray:
    """The truth's Mahalanobis distance from each usable 3-D row's estimate, its
    measurements (``frames/<scene>/<scene>.measurements.json``) weighed with ``model``'s
    σ's (a planar model's widened as ``evaluate`` widens them) and solved with the
    self-calibration the dataset's run was asked for and the model's priors (a row the
    geometry cannot solve is left out).  The table ``cols`` is the folder's, verified
    (its scene files' checksums: :func:`~mirrorsim.formats.dataset_folder.read_table`)."""
    folder = Path(dataset_dir)
    # what the user asked of the dataset's solves (the rows hold what the solves took:
    # the pan's prior widened by the shared α already, and the making model's priors)
    asked = read_description(folder).get("calibrate") or {}
    asked = SelfCalibration(tuple(asked.get("nuisances", ())),
                            float(asked.get("position_sigma", 0.0)), asked.get("priors", {}))
    ok = table.usable_rows(cols)
    images, _, scene_of = table.image_rows(cols)
    targets, beacons = image_features_of(cols, "target"), image_features_of(images, "beacon")
    out = []
    for i in np.flatnonzero(ok):
        name = cols["scene"][i]
        m = load_measurements(folder / "frames" / name / f"{name}.measurements.json")
        if not isinstance(m, Measurements3):
            raise ValueError(f"{name}: its measurements are planar: not a 3-D dataset's row")
        seen = (targets[i], *(beacons[j] for j in np.flatnonzero(scene_of == i)))
        pan, fx = float(cols["observer_pan_deg"][i]), float(cols["fx_px"][i])
        cal, sigma = nuisances3(model, model.sigmas(seen[0], list(seen[1:]), pan, fx_px=fx),
                                asked)
        wide = model.gaussian(sigma)
        elevations = model.gaussian_elevations(seen, pan, fx_px=fx)
        sig = sigma3([*wide.beacons, wide.target], [f.height_px for f in (*seen[1:], seen[0])],
                     fx=fx, elevations=None if elevations is None
                     else (*elevations[1:], elevations[0]))
        try:
            fit = solved3(replace(m, sigma=tuple(sig)), cal)
        except (SolverError, np.linalg.LinAlgError):
            continue
        err = fit.target - np.array([cols[f"target_{a}"][i] for a in "xyz"], float)
        out.append(float(np.sqrt(err @ np.linalg.solve(fit.target_covariance, err))))
    return np.asarray(out, float)


def with_ellipsoid_scale(model: ErrorModel, dataset_dir: str | Path, cols: dict
                         ) -> ErrorModel:
    """``model`` (a :attr:`~ErrorModel.three_d` one) with the ellipsoid scale its own
    rows give (:func:`distances3`): SCALE_LEVEL of their truths within the widened 95 %
    ellipsoid, never narrowed below the σ's own."""
    d = distances3(model, dataset_dir, cols)
    if not d.size:
        raise ValueError("no row could be solved again in 3-D to fit the ellipsoid's scale")
    return replace(model, ellipsoid_scale=max(1.0, float(np.quantile(d, SCALE_LEVEL))
                                              / CHI2_3_R95))
