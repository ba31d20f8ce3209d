"""Scores against the ground truth and the evaluation report, with their JSON.

Each class has one ``to_json`` (the documents of docs/files.md) and one ``from_json``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from mirrorsim.detection.board import CameraPose
from mirrorsim.detection.image_geometry import Calibration
from mirrorsim.errors import BadParameter
from mirrorsim.formats.error_model import ImageFeatures
from mirrorsim.formats.measurements import measurements_from_dict
from mirrorsim.scene.render_settings import AOVS
from mirrorsim.truth.groundtruth import GroundTruth, RenderInfo
from solver.errors import SolverError
from solver.geometry import line_normal, yaw_difference
from solver.lsq import crlb
from solver.measurements import Measurements
from solver.selfcal import NUISANCES, PLAIN, SelfCalibration
from solver.sltr import Solution


@dataclass(frozen=True)
class Score:
    """Errors of the measurements and of the estimate against the ground truth
    (``report.errors``; the ``errors`` block of docs/files.md).

    Attributes
    ----------
    target_cm : float
        The estimated target's distance from the true one (cm).
    mirror_yaw_deg : float
        The estimated mirror line's direction error (deg).
    mirror_offset_cm : float
        How far the estimated line passes from the true reflection point (cm).
    reflection_point_cm : float
        The target's reflection point's error (cm).
    target_alpha_deg, target_d_total_pct : float
        The target's measured α error (deg) and d_total error (% of d_total).
    beacon_alpha_deg, beacon_d_total_pct : tuple of float
        The same for each beacon.
    target_ellipse95_major_cm : float or None
        The semi-major axis of the solver's 95 % ellipse (cm; None without σ's).
    target_mahalanobis : float or None
        The true target's distance from the estimate in σ's of its covariance.
    target_inside95 : bool or None
        Whether the true target lies inside the solver's 95 % ellipse (drawn at the error
        model's tail's radius: :class:`~solver.measurements.Tail`).
    target_crlb_cm : float or None
        √trace of the Cramér–Rao bound of the estimator that ran, at the true geometry
        (cm): no unbiased estimate's RMS error is smaller.
    calibrated : tuple of str
        The nuisances the scored solution estimated (none: plain least squares).
    """

    target_cm: float
    mirror_yaw_deg: float
    mirror_offset_cm: float  # how far the estimated line passes from the true reflection point
    reflection_point_cm: float
    target_alpha_deg: float
    target_d_total_pct: float
    beacon_alpha_deg: tuple[float, ...]
    beacon_d_total_pct: tuple[float, ...]
    target_ellipse95_major_cm: float | None  # the solver's own bound: the ellipse's semi-major
    # the true target's distance from the estimate in σ's of its covariance (an honest
    # 95 % ellipse holds it below its edge, at the tail's 95 % radius, in 95 % of scenes)
    target_mahalanobis: float | None = None
    target_inside95: bool | None = None
    # √trace of the Cramér–Rao bound of the target at the true geometry for the
    # measurements' σ's: no unbiased estimate's RMS error is smaller
    target_crlb_cm: float | None = None
    # the nuisances the scored solution estimated (solver.selfcal.NUISANCES' names; none: plain)
    calibrated: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """docs/files.md's ``errors`` block."""
        return {"target_cm": self.target_cm, "mirror_yaw_deg": self.mirror_yaw_deg,
                "mirror_offset_cm": self.mirror_offset_cm,
                "reflection_point_cm": self.reflection_point_cm,
                "target_alpha_deg": self.target_alpha_deg,
                "target_d_total_pct": self.target_d_total_pct,
                "beacon_alpha_deg": list(self.beacon_alpha_deg),
                "beacon_d_total_pct": list(self.beacon_d_total_pct),
                "target_ellipse95_major_cm": self.target_ellipse95_major_cm,
                "target_mahalanobis": self.target_mahalanobis,
                "target_inside95": self.target_inside95,
                "target_crlb_cm": self.target_crlb_cm, "calibrated": list(self.calibrated)}

    @classmethod
    def from_json(cls, d: dict) -> Score:
        """Inverse of :meth:`to_json`."""
        return cls(**{**d, "beacon_alpha_deg": tuple(d["beacon_alpha_deg"]),
                      "beacon_d_total_pct": tuple(d["beacon_d_total_pct"]),
                      "calibrated": tuple(d.get("calibrated", ()))})


def score(truth: GroundTruth, measurements: Measurements, sol: Solution,
          *, calibration: SelfCalibration = PLAIN) -> Score:
    """Errors of measurements and estimate against the ground truth (docs/files.md);
    ``calibration``: how ``sol`` was solved, so that its Cramér–Rao bound is that
    estimator's (its nuisances, their priors, the beacons' position σ)."""
    t_true = np.asarray(truth.target.position, float)
    rp_true = np.asarray(truth.target.reflection_point, float)
    n = line_normal(sol.mirror.yaw_deg)
    alpha_t, d_t = measurements.targets[0] if len(measurements.targets) == 1 else np.mean(
        measurements.targets, axis=0)
    ellipse = sol.ellipse95()

    def pct(d: float, true: float) -> float:
        return float(100 * abs(d - true) / true)

    return Score(
        target_cm=float(np.linalg.norm(sol.target - t_true)),
        mirror_yaw_deg=float(yaw_difference(sol.mirror.yaw_deg, truth.mirror_yaw_deg)),
        mirror_offset_cm=float(abs(n @ (rp_true - sol.mirror.point))),
        reflection_point_cm=float(np.linalg.norm(sol.target_reflection_point - rp_true)),
        target_alpha_deg=float(abs(alpha_t - truth.target.alpha_deg)),
        target_d_total_pct=pct(d_t, truth.target.d_total),
        beacon_alpha_deg=tuple(float(abs(m.alpha_deg - t.alpha_deg)) for m, t in
                               zip(measurements.beacons, truth.beacons, strict=True)),
        beacon_d_total_pct=tuple(pct(m.d_total, t.d_total) for m, t in
                                 zip(measurements.beacons, truth.beacons, strict=True)),
        target_ellipse95_major_cm=None if ellipse is None else float(ellipse[0]),
        target_mahalanobis=sol.mahalanobis(t_true),
        target_inside95=sol.inside95(t_true),
        target_crlb_cm=_crlb_cm(truth, measurements, calibration),
        calibrated=calibrated_of(sol),
    )


def calibrated_of(sol: Solution) -> tuple[str, ...]:
    """The nuisances (NUISANCES' names) a solution estimated."""
    return tuple(n for n, (key, _) in NUISANCES.items() if key in sol.nuisances)


def _crlb_cm(truth: GroundTruth, m: Measurements, calibration: SelfCalibration
             ) -> float | None:
    """√trace of the target's CRLB at the truth for ``m``'s σ's and the estimator solved
    with ``calibration`` (None without σ's, or where the geometry determines nothing)."""
    if m.sigma is None:
        return None
    yaw = truth.mirror_yaw_deg
    rho = float(line_normal(yaw) @ np.asarray(truth.target.reflection_point, float))
    try:
        bound = crlb(m.observer, [b.position for b in m.beacons], yaw, mirror_rho=rho,
                     target=truth.target.position, sigma=m.sigma, n_targets=len(m.targets),
                     calibration=calibration)
    except SolverError:
        return None
    return float(np.sqrt(np.trace(bound[2:4, 2:4])))


# the report's render block: how its frames were rendered (the truth files hold the rest)
REPORT_RENDER_KEYS = ("spp", "seed", "sampler", "variant")
# optional files beside each frame (its PNG, truth and capture record are always written)
# (depth and normals: Mitsuba's aov integrator's, ``<frame>.depth.npy``…); the API's
# evaluate keeps the first two unless told otherwise (the arrays cost a render each)
KEPT_BY_DEFAULT = ("ids", "annotated")
EXTRA_FILES = (*KEPT_BY_DEFAULT, *AOVS)


def check_keep(keep: object) -> None:
    """Refuse a ``keep`` that is not a collection of :data:`EXTRA_FILES` names (a typo
    kept nothing, silently; a bare string matched by its substrings)."""
    if isinstance(keep, str):
        raise BadParameter("keep", f"{keep!r}: give a tuple of names, e.g. ({keep!r},)")
    unknown = set(keep) - set(EXTRA_FILES)
    if unknown:
        raise BadParameter("keep", f"{sorted(unknown)}: choose from {list(EXTRA_FILES)}")


@dataclass(frozen=True)
class FrameRecord:
    """One frame of an evaluation: its files, whether it was reused, and where the
    detector found an image clipped ('' if not; else 'top', 'left' or 'right')."""

    png: str
    annotated: str
    reused: bool
    target_clipped: str = ""
    beacon_clipped: str = ""


@dataclass(frozen=True)
class Report:
    """What ``mirrorsim evaluate`` makes of a scene (``evaluate --json``).

    Attributes
    ----------
    scene : str
        The scene's name.
    truth : GroundTruth
        The exact geometry the frames were rendered from (``ms.check``'s).
    measurements : Measurements
        What the detector measured, as the solver took it (with its σ's).
    solution : Solution
        The mirror and the target found (``solution.target``, ``.ellipse95()``,
        ``.target_covariance``).
    errors : Score
        The solution and the measurements against the truth (``errors.target_cm``).
    frames : tuple of FrameRecord
        Each frame's files, whether it was reused, and where an image was clipped.
    render : RenderInfo
        The render's settings and timing.
    calibration : Calibration
        The size-constancy constants K the detector used.
    error_vs_beacons : tuple of Score
        With several beacons, the errors as beacons are added (the first k each).
    camera_pose : CameraPose or None
        The camera's pan, pitch and roll measured on the board (``board_pose``).
    error_model : str
        The name of the error model that gave the σ's.
    model_warnings : tuple of str
        Every way the scene lies outside what that model was fitted on.
    image_features : tuple of ImageFeatures
        What each frame showed of each image (the target's, then each beacon's).
    self_calibration : SelfCalibration
        What the solve estimated with the mirror, with its priors.
    calibration_notes : tuple of str
        What the solve says of its nuisances (held by their priors, not separated, far
        outside what the bench allows).
    """

    scene: str
    truth: GroundTruth
    measurements: Measurements
    solution: Solution
    errors: Score
    frames: tuple[FrameRecord, ...]
    render: RenderInfo
    calibration: Calibration
    error_vs_beacons: tuple[Score, ...] = field(default=())
    # the camera's pose measured on the board (``evaluate --board-pose``), else None
    camera_pose: CameraPose | None = None
    # the error model that gave the σ's (its name) and every way the scene lies outside
    # what it was fitted on (one line each)
    error_model: str = ""
    model_warnings: tuple[str, ...] = ()
    # what each frame showed of each image: the target's, then each beacon's
    image_features: tuple[ImageFeatures, ...] = ()
    # what the solve estimated with the mirror: the nuisances, their priors, the
    # beacons' position σ (the model's bench and the caller's wishes together)
    self_calibration: SelfCalibration = PLAIN
    # what the solve says of its nuisances: held by their priors, not separated from
    # the mirror, or far outside what the bench allows (one line each)
    calibration_notes: tuple[str, ...] = ()

    @property
    def reused(self) -> bool:
        """Whether every frame was a reused render."""
        return all(f.reused for f in self.frames)

    def to_json(self) -> dict:
        """The evaluation report of docs/files.md (plus frames, render, calibration)."""
        out = {"scene": self.scene, "truth": self.truth.to_json(),
               "measurements": self.measurements.to_json(),
               "solution": self.solution.to_json(), "errors": self.errors.to_json(),
               "frames": [asdict(f) for f in self.frames],
               "render": {k: self.render.to_json()[k] for k in REPORT_RENDER_KEYS},
               "calibration": self.calibration.constants()}
        if self.camera_pose is not None:
            out["camera_pose"] = self.camera_pose.to_json()
        out["error_model"] = {"name": self.error_model, "warnings": list(self.model_warnings),
                              "images": [f.to_json() for f in self.image_features]}
        out["self_calibration"] = {**self.self_calibration.to_json(),
                                   "notes": list(self.calibration_notes)}
        if self.error_vs_beacons:
            out["error_vs_beacons"] = [{"beacons": k + 1, **s.to_json()}
                                       for k, s in enumerate(self.error_vs_beacons)]
        return out

    @classmethod
    def from_json(cls, d: dict) -> Report:
        """Inverse of :meth:`to_json`."""
        return cls(scene=d["scene"], truth=GroundTruth.from_json(d["truth"]),
                   measurements=measurements_from_dict(d["measurements"]),
                   solution=Solution.from_json(d["solution"]),
                   errors=Score.from_json(d["errors"]),
                   frames=tuple(FrameRecord(**f) for f in d["frames"]),
                   render=RenderInfo.from_json(d["render"]),
                   calibration=Calibration(**d["calibration"]),
                   error_vs_beacons=tuple(
                       Score.from_json({k: v for k, v in e.items() if k != "beacons"})
                       for e in d.get("error_vs_beacons", [])),
                   camera_pose=CameraPose(**d["camera_pose"]) if "camera_pose" in d else None,
                   error_model=d["error_model"]["name"],
                   model_warnings=tuple(d["error_model"]["warnings"]),
                   image_features=tuple(ImageFeatures.from_json(f)
                                        for f in d["error_model"]["images"]),
                   self_calibration=SelfCalibration.from_json(d["self_calibration"]),
                   calibration_notes=tuple(d["self_calibration"]["notes"]))
