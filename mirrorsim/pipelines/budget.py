"""The error budget of a bench (``mirrorsim budget``): the scene ideal, with each
imperfection alone, and with all; each rendered, detected, solved and scored (a 3-D
scene, one with a raised object or a leaning mirror, in 3-D: each image's elevation
measured too, the target's error in 3-D).

Beside each measured contribution stands its first-order prediction: the solver's
Jacobian (the target estimate's derivatives with respect to every measurement and
every believed beacon position, by central differences at the ideal frame's
measurements) times the measured deltas.  Where the prediction and the measurement
part, the effect is not first order (or the solver's conditioning amplifies noise).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from mirrorsim.errors import BadParameter, DetectionError, SolverError
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.files import claim_run_folder
from mirrorsim.pipelines.evaluate import evaluate_into
from mirrorsim.pipelines.evaluate3d import (
    Report3,
    evaluate_into3,
    with_shared_pan,
)
from mirrorsim.pipelines.scenes import check_given_scene
from mirrorsim.pipelines.score import Report, check_keep
from mirrorsim.pipelines.solving import model_for
from mirrorsim.rendering.backend import check_variant
from mirrorsim.rendering.passes import reusing_renders
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import Scene
from solver.lsq import solve_measurements
from solver.lsq3 import Measurements3
from solver.measurements import BeaconMeasurement, Measurements
from solver.selfcal import (
    PLAIN,
    SelfCalibration,
    as_calibration,
    check_nuisances,
    check_planar,
)

# central-difference steps: α (deg), d_total (cm), beacon position (cm); the solver is
# smooth on these scales and far from them its rounding noise (1e-12) is negligible
STEPS = (1e-4, 1e-3, 1e-3)


@dataclass(frozen=True)
class Delta:
    """A source's measurements minus the ideal frame's (docs/files.md ``delta``)."""

    target_alpha_deg: float
    target_d_total_pct: float
    beacon_alpha_deg: tuple[float, ...]
    beacon_d_total_pct: tuple[float, ...]
    beacon_position_cm: tuple[float, ...]  # |believed − ideal| per beacon
    # a 3-D budget's: each image's elevation (deg); None and () in the plane
    target_elevation_deg: float | None = None
    beacon_elevation_deg: tuple[float, ...] = ()

    def to_json(self) -> dict:
        """The ``delta`` block."""
        out = {"target_alpha_deg": self.target_alpha_deg,
               "target_d_total_pct": self.target_d_total_pct,
               "beacon_alpha_deg": list(self.beacon_alpha_deg),
               "beacon_d_total_pct": list(self.beacon_d_total_pct),
               "beacon_position_cm": list(self.beacon_position_cm)}
        if self.target_elevation_deg is not None:
            out |= {"target_elevation_deg": self.target_elevation_deg,
                    "beacon_elevation_deg": list(self.beacon_elevation_deg)}
        return out


@dataclass(frozen=True)
class Contribution:
    """One imperfection alone (or all of them: ``source`` 'all'), measured and predicted;
    or, where its frames could not be measured or solved, why (``failed``; the numbers
    are then None)."""

    source: str
    value: Any
    target_cm: float | None  # the estimate's error against the truth
    shift_cm: float | None  # how far the estimate moved from the ideal frame's
    predicted_cm: float | None  # first order: |ideal error + J·delta|
    predicted_shift_cm: float | None  # first order: |J·delta|
    delta: Delta | None
    failed: str = ""
    # the same frames self-calibrated (the budget's nuisances; None: not asked, or the
    # geometry cannot carry them)
    calibrated_cm: float | None = None

    def to_json(self) -> dict:
        """One entry of ``sources``."""
        out = {"source": self.source, "value": self.value, "target_cm": self.target_cm,
               "predicted_cm": self.predicted_cm, "shift_cm": self.shift_cm,
               "predicted_shift_cm": self.predicted_shift_cm,
               "delta": None if self.delta is None else self.delta.to_json()}
        if self.calibrated_cm is not None:
            out["calibrated_target_cm"] = self.calibrated_cm
        return out | ({"failed": self.failed} if self.failed else {})


@dataclass(frozen=True)
class Budget:
    """``mirrorsim budget``'s result (docs/files.md *Error budget*)."""

    scene: str
    ideal_cm: float
    all: Contribution | None  # None when the scene has a single source (or none)
    sources: tuple[Contribution, ...]
    calibration: SelfCalibration = PLAIN  # the self-calibrated column's, where asked
    ideal_calibrated_cm: float | None = None
    geometry: str = "planar"  # "3d": solved in 3-D, each error the 3-D distance

    def to_json(self) -> dict:
        """The budget document."""
        ideal = {"target_cm": self.ideal_cm}
        if self.calibration.nuisances:
            ideal["calibrated_target_cm"] = self.ideal_calibrated_cm
        out = {"scene": self.scene, "geometry": self.geometry, "ideal": ideal,
               "sources": [c.to_json() for c in self.sources]}
        if self.calibration.nuisances:
            out["self_calibration"] = self.calibration.to_json()
        if self.all is not None:
            out["all"] = {k: v for k, v in self.all.to_json().items()
                          if k not in ("source", "value", "delta")}
        return out


def _vector(m: Measurements | Measurements3) -> np.ndarray:
    """The solver's inputs as one vector: target α, d; per beacon α, d, x, y (in 3-D:
    target α, ε, d; per beacon α, ε, d, x, y, z).  Not the pan the mount reports, which a
    3-D reading is modelled at: a pan error's α's alone predict its shift (1.12 cm on
    scenes/raised.yaml's 0.5°; with the reported pan moved too, 1.115 cm)."""
    if isinstance(m, Measurements3):
        return np.array([*m.target, *(v for p, seen in m.beacons for v in (*seen, *p))], float)
    v = list(np.mean(m.targets, axis=0))
    for b in m.beacons:
        v += [b.alpha_deg, b.d_total, *b.position]
    return np.array(v, float)


def _estimate(m: Measurements | Measurements3, v: np.ndarray, shared_alpha_deg: float = 0.0
              ) -> np.ndarray:
    """The target the budget's solve makes of ``m`` with its inputs ``v`` (:func:`_vector`'s;
    in 3-D, the α error a frame's images share as the pan's prior, as the runs solve)."""
    f = [float(x) for x in v]
    if isinstance(m, Measurements3):
        beacons = tuple((tuple(f[k + 3:k + 6]), tuple(f[k:k + 3])) for k in range(3, len(f), 6))
        nuisances, priors = with_shared_pan(PLAIN, shared_alpha_deg)
        return replace(m, target=tuple(f[:3]), beacons=beacons).solve(
            nuisances=nuisances, priors=priors).target
    beacons = [BeaconMeasurement((f[k + 2], f[k + 3]), f[k], f[k + 1])
               for k in range(2, len(f), 4)]
    return solve_measurements(m.observer, beacons, [(f[0], f[1])], sigma=m.sigma).target


def jacobian(m: Measurements | Measurements3, shared_alpha_deg: float = 0.0) -> np.ndarray:
    """∂(target estimate)/∂(measurement vector) at ``m``, (2, n) by central differences
    ((3, n) in 3-D, an elevation stepped as an α; ``shared_alpha_deg``: :func:`_estimate`'s)."""
    v0 = _vector(m)
    a, d, p = STEPS
    n, stride = _layout(m)
    image = [a] * (n - 1) + [d]  # (α[, ε], d)
    steps = np.array(image + (image + [p] * (stride - n)) * len(m.beacons))
    cols = []
    for k, h in enumerate(steps):
        e = np.zeros_like(v0)
        e[k] = h
        cols.append((_estimate(m, v0 + e, shared_alpha_deg)
                     - _estimate(m, v0 - e, shared_alpha_deg)) / (2 * h))
    return np.column_stack(cols)


def _layout(m: Measurements | Measurements3) -> tuple[int, int]:
    """How many of :func:`_vector`'s numbers each image takes (α, d; α, ε, d in 3-D) and
    each beacon (its image's and its position's)."""
    return (3, 6) if isinstance(m, Measurements3) else (2, 4)


def _measured(report: Report | Report3) -> Measurements | Measurements3:
    return report.seen if isinstance(report, Report3) else report.measurements


def _truth(report: Report | Report3) -> np.ndarray:
    """The true target (its base in 3-D)."""
    t = np.asarray(report.truth.target.position, float)
    return np.r_[t, 0.0] if isinstance(report, Report3) and len(t) == 2 else t


def _shared_alpha(report: Report | Report3) -> float:
    """The α error a 3-D report's frames share, which its solve takes as the pan's prior
    (a planar report's σ's carry it)."""
    return report.shared_alpha_deg if isinstance(report, Report3) else 0.0


def _target(report: Report | Report3) -> np.ndarray:
    return report.fit.target if isinstance(report, Report3) else report.solution.target


def calibrated_error(report: Report | Report3, calibration: SelfCalibration) -> float | None:
    """The target error of the report's measurements solved self-calibrated (None where
    not asked, or where the geometry cannot carry the nuisances)."""
    if not calibration.nuisances:
        return None
    m = _measured(report)
    try:
        if isinstance(m, Measurements3):  # (the runs' shared α as their pan's prior)
            nuisances, priors = with_shared_pan(calibration, report.shared_alpha_deg)
            target = m.solve(nuisances=nuisances, priors=priors,
                             position_sigma=calibration.position_sigma).target
        else:
            target = solve_measurements(m.observer, m.beacons, m.targets, sigma=m.sigma,
                                        calibration=calibration).target
    except SolverError:
        return None
    return float(np.linalg.norm(target - _truth(report)))


def contribution(source: str, value: Any, ideal: Report | Report3, *,
                 report: Report | Report3, J: np.ndarray,
                 calibration: SelfCalibration = PLAIN) -> Contribution:
    """Compare a source's report with the ideal one; predict its effect to first order;
    with ``calibration``'s nuisances, also solve its frames self-calibrated."""
    v0, v1 = _vector(_measured(ideal)), _vector(_measured(report))
    dv = v1 - v0
    truth = _truth(ideal)
    est0, est1 = _target(ideal), _target(report)
    pred = J @ dv
    pct = lambda k: float(100 * dv[k] / v0[k])  # noqa: E731
    n, stride = _layout(_measured(report))  # (α[, ε], d | α[, ε], d, position)
    b = range(n, len(dv), stride)  # each beacon's first
    three = n == 3
    delta = Delta(target_alpha_deg=float(dv[0]), target_d_total_pct=pct(n - 1),
                  beacon_alpha_deg=tuple(float(dv[k]) for k in b),
                  beacon_d_total_pct=tuple(pct(k + n - 1) for k in b),
                  beacon_position_cm=tuple(math.hypot(*dv[k + n:k + stride]) for k in b),
                  target_elevation_deg=float(dv[1]) if three else None,
                  beacon_elevation_deg=tuple(float(dv[k + 1]) for k in b) if three else ())
    return Contribution(source=source, value=value,
                        target_cm=float(np.linalg.norm(est1 - truth)),
                        shift_cm=float(np.linalg.norm(est1 - est0)),
                        predicted_cm=float(np.linalg.norm(est0 - truth + pred)),
                        predicted_shift_cm=float(np.linalg.norm(pred)), delta=delta,
                        calibrated_cm=calibrated_error(report, calibration))


def check_budget_calibration(scene: Scene, calibration: SelfCalibration) -> SelfCalibration:
    """``calibration`` for a budget of ``scene``, refused before anything is rendered or
    written where its self-calibrated column would be empty: nuisances the scene's
    beacons cannot carry, or a beacons' position σ without nuisances."""
    calibration = as_calibration(calibration)
    if calibration.position_sigma and not calibration.nuisances:
        raise BadParameter("nuisances", "none given, yet a beacons' position σ is: the "
                           "budget uses that σ in its self-calibrated column only, which "
                           "needs nuisances to self-calibrate")
    try:
        if not scene.is_3d:
            check_planar(calibration)
        check_nuisances(calibration.nuisances, len(scene.beacons), 1, priors=calibration.priors,
                        readings=3 if scene.is_3d else 2)
    except SolverError as exc:
        raise BadParameter("nuisances", str(exc)) from None
    return calibration


def budget_runs(scene: Scene) -> int:
    """How many runs :func:`run_budget` makes of ``scene``: the ideal bench, each of its
    imperfections alone and (where it has several) all of them."""
    found = imperfections.sources(scene)
    return 1 + len(found) + (len(found) > 1)


def run_budget(scene: Scene, out: str | Path, *, variant: str = "auto", progress: bool = True,
               on_step: Callable[[str, int, int], None] | None = None,
               error_model: ErrorModel | None = None,
               calibration: SelfCalibration = PLAIN, keep: tuple[str, ...] = ()) -> Budget:
    """Evaluate ``scene`` ideal, with each imperfection alone and with all; frames and
    reports go to ``out/<ideal|source key|all>/`` (with the extra files ``keep`` names,
    as :func:`~mirrorsim.pipelines.evaluate.evaluate_scene`'s).  ``on_step(label, k,
    runs)`` is called before run k of ``runs``.

    Raises
    ------
    DetectionError
        If a frame cannot be measured (the message names the source).
    BadParameter
        A ``calibration`` whose nuisances the scene's beacons cannot carry (its column
        would be empty), a position σ without nuisances, or a bad ``keep``.
    OutputError
        If ``out`` holds files mirrorsim did not write, or the scene's own file.
    """
    calibration, model = _checked(scene, keep=keep, calibration=calibration,
                                  error_model=error_model, variant=variant)
    out = claim_run_folder(out, "out", [("scene", scene.source)])
    found, runs = imperfections.sources(scene), budget_runs(scene)
    done = iter(range(1, runs + 1))

    def run(label: str, sub: Scene) -> Report | Report3:
        if on_step is not None:
            on_step(label, next(done), runs)
        # every run weighed by the model the whole scene's bench calls for, and solved
        # as the budget solves (its own calibration, not the model's bench priors): the
        # runs differ by their imperfections alone (a 3-D scene's, solved in 3-D)
        return (evaluate_into3 if scene.is_3d else evaluate_into)(
            sub, out / _folder(label), variant=variant, progress=progress, keep=keep,
            error_model=model, model_priors=False)

    def measured(label: str, value: Any, sub: Scene) -> Contribution:
        # a bench error can make a frame unmeasurable (an image taken for the wrong one
        # is refused) or unsolvable (no mirror fits): that is its effect, recorded
        try:
            return contribution(label, value, ideal, report=run(label, sub), J=J,
                                calibration=calibration)
        except (DetectionError, SolverError) as exc:
            return Contribution(label, value, None, None, None, None, None, failed=str(exc))

    # the ideal bench's frames (one per beacon) stay in memory: a source that acts after
    # the render or only on beliefs (noise, JPEG, pan reading, calibration, a beacon's
    # believed position) takes its render from them instead of rendering it again
    with reusing_renders(len(scene.beacons)):
        try:
            ideal = run("ideal", imperfections.ideal(scene))
        except DetectionError as exc:
            raise DetectionError(f"the ideal bench: {exc}") from None
        J = jacobian(_measured(ideal), _shared_alpha(ideal))
        contributions = tuple(measured(s.key, s.value, imperfections.only(scene, s.key))
                              for s in found)
        everything = measured("all", None, scene) if len(found) > 1 else None
    return Budget(scene=scene.name, ideal_cm=ideal.errors.target_cm, all=everything,
                  sources=contributions, calibration=calibration,
                  ideal_calibrated_cm=calibrated_error(ideal, calibration),
                  geometry="3d" if scene.is_3d else "planar")


def _checked(scene: Scene, *, keep: tuple[str, ...], calibration: SelfCalibration,
             error_model: ErrorModel | None, variant: str
             ) -> tuple[SelfCalibration, ErrorModel]:
    """:func:`run_budget`'s arguments checked, and its error model read, before anything
    is written: the calibration it solves with and the model that weighs every run."""
    check_given_scene(scene)  # edited by a script: held to what its file would make
    check_keep(keep)
    calibration = check_budget_calibration(scene, calibration)
    model = model_for(scene, error_model)
    check_variant(variant)
    return calibration, model


def _folder(label: str) -> str:
    """A source's key as a folder name: ``beacons[0].known_position`` →
    ``beacons0.known_position``."""
    return label.replace("[", "").replace("]", "")

