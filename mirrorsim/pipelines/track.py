"""The moving beacon of the paper's Section 4 on rendered frames (`mirrorsim track`).

The scene's first beacon follows a path (eqs 19–21: ``linear``, ``rectangular`` or
``sawtooth``; steps of b along a heading, side a across it) from its start, or stands
still (``fixed``: the baseline of one fixed beacon seen in as many frames).  The start
pose is rendered and measured first: its beacon's (α, d_total) give a mirror line (the
perpendicular bisector of the beacon and its image), which centres the filter's prior
(yaw ± 15°, offset ± 8 cm) and lays out the path
(:func:`~mirrorsim.pipelines.track_paths.beacon_path`) — from what the
experimenter saw, never from the scene's mirror.  The experimenter commands each move;
the beacon's believed position is the start plus the commanded moves, its true position
also carries odometry noise (N(0, σ) per axis per move, seeded).  Each pose is rendered,
detected from its capture record (which holds the believed position), and fed to the
Rao-Blackwellized particle filter (:mod:`solver.particle`); a pose where the detector
finds no usable mirror image of the beacon is recorded as unseen and the filter only
predicts, as a real robot would.  The target, which does not move, is measured in every
frame; its estimate is its mean measurement reflected in the filter's mirror.  The
scene's other beacons stand still beside the moving one: each is rendered alone and
measured once, and its likelihood weighs every mirror hypothesis from the start.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from mirrorsim.detection.detector import Detection
from mirrorsim.detection.image_geometry import Calibration
from mirrorsim.errors import BadParameter, DetectionError
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.files import claim_run_folder
from mirrorsim.pipelines.frame import FrameNotMeasured, render_and_measure
from mirrorsim.pipelines.scenes import check_given_scene, refuse_3d
from mirrorsim.pipelines.solving import model_for
from mirrorsim.pipelines.track_paths import HEADINGS, PATHS, beacon_path
from mirrorsim.pipelines.track_report import TrackReport, TrackStep
from mirrorsim.rendering.backend import check_variant
from mirrorsim.scene.model import Scene
from mirrorsim.scene.render_settings import MAX_SEED, is_whole
from solver.beacon_kalman import PFParams
from solver.errors import SolverError
from solver.geometry import line_normal
from solver.measurements import BeaconMeasurement, Sigma
from solver.particle import DEFAULT_PARTICLES, MovingBeaconFilter
from solver.particle_runs import mirror_errors
from solver.selfcal import check_position_sigma
from solver.sltr import locate, mirror_from_beacon

PRIOR_YAW_DEG, PRIOR_OFFSET_CM = 15.0, 8.0
MAX_STEPS = 500
MAX_ODOMETRY_SIGMA = 10.0  # cm per move: a robot that errs more than this is not driving

# pose k renders with seed·1000 + k (a fixed beacon's frame with seed·1000 + 999 − i):
# the largest run seed whose render seeds stay within MAX_SEED
MAX_TRACK_SEED = (MAX_SEED - 999) // 1000


def check_options(kind: str, steps: int, sigma: float, *, side: float, step: float,
                  heading: str = "view", board: tuple[float, float] | None = None) -> None:
    """Refuse bad options as bad input (``board``: its size, which bounds side and step;
    whether a whole path fits is known once the start pose is measured)."""
    if kind not in PATHS:
        raise BadParameter("kind", f"{kind!r}: expected one of {', '.join(PATHS)}")
    if heading not in HEADINGS:
        raise BadParameter("heading", f"{heading!r}: expected one of {', '.join(HEADINGS)}")
    if not (is_whole(steps) and 1 <= steps <= MAX_STEPS):
        raise BadParameter("steps", f"{steps!r} must be a whole number within 1..{MAX_STEPS}")
    if not (np.isfinite(sigma) and 0 <= sigma <= MAX_ODOMETRY_SIGMA):
        raise BadParameter("odometry_sigma", f"{sigma:g} must be within 0..{MAX_ODOMETRY_SIGMA:g}"
                           " (cm per move)")
    longest = max(board) if board is not None else np.inf
    for name, v in (("side", side), ("step", step)):
        if not (np.isfinite(v) and 0 < v <= longest):
            raise BadParameter(name, f"{v:g} must be a positive length (cm)" + (
                f" within the board's {longest:g} cm" if board is not None else ""))


# the narrowest likelihood the filter is given: the σ's it was validated with before the
# error model (tests/test_track.py: the filter converges on rendered frames with them)
FILTER_SIGMA_FLOOR = Sigma(alpha_deg=0.005, d_total_rel=0.006)
# fewer particles than this cannot carry a posterior over the mirror's two parameters
MIN_PARTICLES = 10
# the most: each particle carries a Kalman filter replayed over the run at every move,
# and 10⁹ of them took 24 GiB before the kernel stopped the process
MAX_PARTICLES = 1_000_000


def check_fixed_beacons(scene: Scene, position_sigma: float) -> None:
    """Refuse a fixed beacons' position σ for a scene without fixed beacons: it would
    change nothing, silently (its one beacon is the moving one)."""
    if position_sigma and len(scene.beacons) < 2:
        raise BadParameter("position_sigma", f"scene {scene.name!r} has no fixed beacon (its "
                           "one beacon is the moving one, whose position is the odometry's)")


def run_track(scene: Scene, out: str | Path, *, kind: str = "rectangular", steps: int = 20,
              odometry_sigma: float = 0.1, seed: int = 0, side: float = 4.0,
              step: float = 1.0, heading: str = "view",
              variant: str = "auto", particles: int = DEFAULT_PARTICLES,
              on_pose: Callable[[int, int], None] | None = None,
              error_model: ErrorModel | None = None,
              position_sigma: float = 0.0) -> TrackReport:
    """Render, detect and filter every pose of the path; return the report.

    ``error_model``: the filter weighs each beacon observation with the model's typical
    beacon σ's (default: the model shipped for the ideal bench).

    The scene's first beacon moves; any others stand still beside it, each rendered and
    measured once (in a frame of its own, ``fixed<i>``) and weighed into the filter's
    prior on the mirror (:class:`solver.beacon_kalman.Prior`'s ``fixed``), its believed position
    known to ``position_sigma`` cm per axis (0: exactly).

    Raises
    ------
    BadParameter
        For bad options: ``kind``, ``heading``, ``steps``, ``odometry_sigma``, ``side``,
        ``step``, ``particles``, ``seed`` or ``position_sigma`` out of its range (a
        ``position_sigma`` without fixed beacons too).
    OutputError
        If ``out`` holds files mirrorsim did not write, or the scene's own file.
    DetectionError
        If the beacon or the target is not measured at the start pose (no prior, no path),
        or a fixed beacon's image is not measured.
    """
    check_given_scene(scene)  # edited by a script: held to what its file would make
    refuse_3d(scene, "track")
    check_options(kind, steps, odometry_sigma, side=side, step=step, heading=heading,
                  board=scene.board.size)
    _check_filter_options(scene, particles=particles, seed=seed, position_sigma=position_sigma,
                          variant=variant)
    model = model_for(scene, error_model)  # read and checked before anything is written
    out = claim_run_folder(out, "out", [("scene", scene.source)])
    rng = np.random.default_rng(seed)
    b0, cam = scene.beacons[0], scene.camera
    start = np.asarray(b0.believed, float)
    pose = _Poses(scene, out / "poses", seed, variant, on_pose, steps + 1)
    obs, target_obs, why = pose.start(start, np.asarray(b0.position, float))
    fixed = tuple(pose.fixed(i) for i in range(1, len(scene.beacons)))
    try:
        commanded = beacon_path(scene, obs, target_obs, kind=kind, steps=steps, side=side,
                                step=step, heading=heading)
        pf = _start_filter(cam.position, start, obs, n=particles, seed=seed, fixed=fixed,
                           fixed_sigma=position_sigma, params=_filter_params(
                               model, cam.fx, odometry_sigma if kind != "fixed" else 0.0))
    except SolverError as exc:
        raise DetectionError(f"{scene.name}: the start pose's measurements give no mirror "
                             f"({exc})") from None
    true = _true_path(np.asarray(b0.position, float), np.diff(commanded, axis=0),
                      odometry_sigma, rng)
    records, snapshots = _walk(scene, pf, pose, commanded, true, rng=rng,
                               start=(obs, target_obs, why))
    return TrackReport(scene=scene.name, path=kind, heading=heading,
                       odometry_sigma=odometry_sigma, seed=seed, steps=tuple(records),
                       snapshots=tuple(snapshots), fixed=fixed, fixed_sigma=position_sigma)


def _check_filter_options(scene: Scene, *, particles: int, seed: int,
                          position_sigma: float, variant: str) -> None:
    """The filter's options, each within its range, the scene's fixed beacons and the
    render's variant (:func:`run_track`'s ``BadParameter``)."""
    for name, v, lo in (("particles", particles, MIN_PARTICLES), ("seed", seed, 0)):
        if not (is_whole(v) and v >= lo):
            raise BadParameter(name, f"{v!r} must be a whole number ≥ {lo}")
    if seed > MAX_TRACK_SEED:
        raise BadParameter("seed", f"{seed} must be ≤ {MAX_TRACK_SEED} (pose k renders with "
                           "seed·1000 + k, a seed within 0..2⁶³−1)")
    if particles > MAX_PARTICLES:
        raise BadParameter("particles", f"{particles} must be ≤ {MAX_PARTICLES}")
    try:
        check_position_sigma(position_sigma)
    except SolverError as exc:
        raise BadParameter("position_sigma", str(exc)) from None
    check_fixed_beacons(scene, position_sigma)
    check_variant(variant)


def _filter_params(model: ErrorModel, fx: float, odometry_sigma: float) -> PFParams:
    """The filter's noise levels: each pose's error taken whole (its own part, the shared
    α offset and a bench model's pan and range-scale tolerances, which the filter does
    not model apart), and the odometry's (a fixed beacon's: none)."""
    typical = model.typical_whole(fx).beacons[0]
    # a particle filter cannot follow a likelihood much narrower than its particles'
    # spread (they all but one get weight 0): no narrower than FILTER_SIGMA_FLOOR
    return PFParams(sigma=Sigma(max(typical.alpha_deg, FILTER_SIGMA_FLOOR.alpha_deg),
                                max(typical.d_total_rel, FILTER_SIGMA_FLOOR.d_total_rel)),
                    sigma_trs=max(odometry_sigma, 1e-3))


def _walk(scene: Scene, pf: MovingBeaconFilter, pose: _Poses, commanded: np.ndarray,
          true: np.ndarray, *, rng: np.random.Generator,
          start: tuple[tuple[float, float] | None, tuple[float, float] | None, str]
          ) -> tuple[list[TrackStep], list[np.ndarray]]:
    """Each pose of the path measured (the start's given) and filtered: its record and
    a snapshot of the particles."""
    obs, target_obs, why = start
    moves = np.diff(commanded, axis=0)
    targets = [target_obs]
    records: list[TrackStep] = []
    snapshots: list[np.ndarray] = []
    for k in range(len(commanded)):
        if k:
            obs, target_obs, why = pose.measure(k, commanded[k], true[k])
            if target_obs is not None:
                targets.append(target_obs)
        pf.step(np.zeros(2) if k == 0 else moves[k - 1], obs)
        records.append(replace(
            _step_record(scene, k, pf.estimate(), np.mean(targets, axis=0), commanded[k],
                         moves[:k], true[k], obs is not None, why),
            mirror_nees=pf.nees(scene.mirror.center, scene.mirror.yaw)))
        snapshots.append(_snapshot(pf, rng))
    return records, snapshots


class _Poses:
    """Renders and measures the beacon's poses (one camera, one calibration: made at the
    first pose)."""

    def __init__(self, scene: Scene, out: Path, seed: int, variant: str,
                 on_pose: Callable[[int, int], None] | None, total: int):
        self.scene, self.out, self.seed, self.variant = scene, out, seed, variant
        self.on_pose, self.total = on_pose, total
        self.calibration: Calibration | None = None

    def measure(self, k: int, believed: np.ndarray, true: np.ndarray
                ) -> tuple[tuple[float, float] | None, tuple[float, float] | None, str]:
        """Pose k: the beacon's and the target's observations (or None) and why not."""
        if self.on_pose:
            self.on_pose(k, self.total)
        b0 = self.scene.beacons[0]
        posed = replace(self.scene, name=f"{self.scene.name}_pose{k:03d}",
                        beacons=(replace(b0, position=tuple(true),
                                         known_position=tuple(believed)),))
        posed = posed.with_render(seed=self.seed * 1000 + k)
        try:
            m = render_and_measure(posed, self.out, variant=self.variant,
                                   progress=False, reuse=True, ids=False,
                                   calibration=self.calibration)
        except FrameNotMeasured as exc:
            return None, None, exc.reason
        self.calibration = m.calibration
        return _observations(m.detection)

    def start(self, believed: np.ndarray, true: np.ndarray
              ) -> tuple[tuple[float, float], tuple[float, float], str]:
        """The start pose measured; it must see the beacon and the target (the filter's
        prior, the path's heading)."""
        obs, target_obs, why = self.measure(0, believed, true)
        if obs is None or target_obs is None:
            raise DetectionError(f"{self.scene.name}: the start pose gives the filter no "
                                 "prior and the path no heading: "
                                 f"{why or 'the target was not measured'}")
        return obs, target_obs, why

    def fixed(self, i: int) -> BeaconMeasurement:
        """The scene's beacon i, standing still: rendered alone once, its image measured
        (at its believed position for the filter); with the poses' calibration where its
        pencil is as tall, else its own.

        Raises
        ------
        DetectionError
            If its image is not measured: a beacon dropped silently would mislead.
        """
        b = self.scene.beacons[i]
        alone = replace(self.scene, name=f"{self.scene.name}_fixed{i}", beacons=(b,))
        # a calibration is of one pencil height (the moving beacon's, at the poses)
        same = b.height == self.scene.beacons[0].height
        try:
            m = render_and_measure(alone.with_render(seed=self.seed * 1000 + 999 - i),
                                   self.out, variant=self.variant, progress=False,
                                   reuse=True, ids=False,
                                   calibration=self.calibration if same else None)
        except FrameNotMeasured as exc:
            raise DetectionError(f"{self.scene.name}: fixed beacon {i}: {exc.reason}") from None
        obs, _, why = _observations(m.detection)
        if obs is None:
            raise DetectionError(f"{self.scene.name}: fixed beacon {i}: {why}")
        return BeaconMeasurement(tuple(map(float, b.believed)), *obs)


def _true_path(start: np.ndarray, moves: np.ndarray, sigma: float,
               rng: np.random.Generator) -> list[np.ndarray]:
    """Where the beacon really goes: each commanded move plus odometry noise (a beacon
    that stands still does not drift)."""
    true = [start]
    for mv in moves:
        true.append(true[-1] + mv + (rng.normal(0.0, sigma, 2) if mv.any() else 0.0))
    return true


def _step_record(scene: Scene, k: int, est, target_obs: np.ndarray, commanded: np.ndarray,
                 moves: np.ndarray, true: np.ndarray, seen: bool, why: str) -> TrackStep:
    """Step k scored against the scene: the filter's mirror, and the target located with
    it from the mean of the target's observations so far."""
    cam = scene.camera
    yaw_err, off_err = mirror_errors([est], np.asarray(scene.mirror.center, float),
                                     scene.mirror.yaw)
    target = locate(cam.position, est.point, est.yaw_deg, alpha_deg=target_obs[0],
                    d_total=target_obs[1])
    return TrackStep(
        step=k, commanded=tuple(map(float, commanded)),
        path_length_cm=float(np.sum(np.linalg.norm(moves, axis=1))),
        beacon_position=tuple(map(float, true)), seen=seen, why_unseen=why,
        mirror_yaw_error_deg=float(abs(yaw_err[0])), mirror_offset_error_cm=float(off_err[0]),
        target=tuple(map(float, target)),
        target_error_cm=float(np.linalg.norm(target - np.asarray(scene.target.position, float))),
        yaw_spread_deg=est.yaw_sd_deg, offset_spread_cm=est.rho_sd)


def _observations(det: Detection
                  ) -> tuple[tuple[float, float] | None, tuple[float, float] | None, str]:
    """One pose's detection as the filter takes it: the beacon's (α, d_total), or None
    and why; and the target's, or None where its d_total is not measured."""
    t = det.target
    target = (t.alpha_deg, t.d_total) if t.d_total is not None else None
    m = det.beacon_measurements()[0]
    if m.d_total is None:
        return None, target, "the beacon's mirror image is clipped"
    return (m.alpha_deg, m.d_total), target, ""


def _start_filter(observer, start, obs, *, params: PFParams, n: int, seed: int,
                  fixed: tuple[BeaconMeasurement, ...] = (), fixed_sigma: float = 0.0
                  ) -> MovingBeaconFilter:
    """The filter with its prior centred on the mirror the first pose's beacon gives
    (the perpendicular bisector of the beacon and its image), weighed by the fixed
    beacons."""
    yaw, mid, _ = mirror_from_beacon(observer, start, obs[0], d_total=obs[1])
    yaw = float(yaw)
    rho = float(line_normal(yaw) @ mid)
    return MovingBeaconFilter(observer, start, (yaw - PRIOR_YAW_DEG, yaw + PRIOR_YAW_DEG),
                              (rho - PRIOR_OFFSET_CM, rho + PRIOR_OFFSET_CM), n=n,
                              params=params, rng=seed, fixed=fixed, fixed_sigma=fixed_sigma)


def _snapshot(pf: MovingBeaconFilter, rng: np.random.Generator, keep: int = 400) -> np.ndarray:
    """A few hundred of the filter's mirror hypotheses (yaw, ρ), drawn by weight, for the
    animation (from the track's generator, after its odometry draws: the filter's own
    stream is untouched)."""
    idx = rng.choice(len(pf.weights), size=min(keep, len(pf.weights)), p=pf.weights)
    return pf.particles.mirror[idx].copy()
