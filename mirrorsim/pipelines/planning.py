"""Beacon-placement analysis of a scene: the solver's placement tools applied to the
scene's camera, board, walls and mirror size (``mirrorsim plan``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from mirrorsim.errors import BadParameter
from mirrorsim.pipelines.planning3d import HeightChoice, height_choices
from mirrorsim.pipelines.scenes import check_given_scene
from mirrorsim.scene.model import (
    MIRROR_DEPTH,
    OCCLUDER_THICKNESS,
    PENCIL_RADIUS,
    REFLECTION_EXCESS,
    TARGET_THICKNESS,
    Beacon,
    Scene,
)
from mirrorsim.scene.render_settings import is_whole
from mirrorsim.truth import optics, visibility
from solver.beacon_set import BeaconSet, best_beacon_set
from solver.measurements import (
    SIGMA_ALPHA_MAX_DEG,
    SIGMA_ALPHA_MIN_DEG,
    SIGMA_D_REL_MAX,
    SIGMA_D_REL_MIN,
    ObjectSigmas,
    Sigma,
    as_object_sigmas,
    sigma_json,
)
from solver.placement import (
    BeaconSearch,
    MirrorPrior,
    PlacementGeometry,
    best_beacon,
    expected_target_error,
    paper_placement,
    path_lengths,
    path_points,
    polyline_length,
    region_area,
    visible_region,
)
from solver.selfcal import PLAIN, SelfCalibration, as_calibration, check_planar

AREA_DISTANCES = (25.0, 50.0, 100.0, 200.0, 400.0, 1000.0)
# cm: finer grids take long without news (exp1 here: 1 cm 7 s, 0.5 cm 11 s, 0.25 cm 26 s)
MIN_STEP = 0.5
# how much farther than its beacon a planned beacon's reflection must lie: twice what
# the detector needs to tell it from a direct view, as a bench's errors move d_total by a
# few per cent (a calibration error, JPEG, a curved mirror)
PLACEMENT_EXCESS = 2 * REFLECTION_EXCESS
# the most beacons plan places (each a greedy step over the whole grid)
MAX_PLANNED_BEACONS = 8
# mirror poses the expected error averages over (each a full placement solve)
MAX_POSES = 50


@dataclass(frozen=True)
class Region:
    """The exact region seen under every mirror orientation: a mask on ``xs`` × ``ys``."""

    xs: np.ndarray
    ys: np.ndarray
    mask: np.ndarray
    area: float  # cm²


@dataclass(frozen=True)
class Plan:
    """:func:`plan_scene`'s answer: the paper's placement numbers beside the exact ones,
    the paths, and the best beacon position with its expected target error."""

    target_alpha_deg: float
    target_d_total: float
    eps_deg: float
    sigma: ObjectSigmas  # the target's and the beacon's
    geometry: PlacementGeometry  # the paper's eqs 9–18 as printed
    geometry_corrected: PlacementGeometry  # eq 15 with the line perpendicular
    n_steps: int
    paths: dict[str, np.ndarray]
    path_lengths: dict[str, float]
    path_polyline_lengths: dict[str, float]
    region: Region
    area_vs_d: tuple[list[float], list[float], list[float]]  # d_total, paper, exact
    n_poses: int
    best: BeaconSearch
    scene_beacon_rmse: float
    scene_beacon_seen: float
    # every scene beacon's (rmse, seen fraction), alone
    scene_beacons: tuple[tuple[float, float], ...] = ()
    beacon_set: BeaconSet | None = None  # plan --beacons N (with --calibrate's nuisances)
    # a 3-D scene's: the post for a beacon at each scene beacon's position, the best
    # one's and each planned one's (planning3d)
    heights: tuple[HeightChoice, ...] = ()

    def to_json(self) -> dict:
        """The plan's JSON (``plan --json``): its numbers, not its maps."""
        g, gc = self.geometry, self.geometry_corrected
        ds, lit, exact = self.area_vs_d
        return {
            "target": {"alpha_deg": self.target_alpha_deg, "d_total": self.target_d_total},
            "eps_deg": self.eps_deg,
            "paper": {"b": g.b, "half_a": g.half_a, "n_beacons": g.n_beacons, "area": g.area},
            "paper_eq15_perpendicular": {"b": gc.b, "half_a": gc.half_a, "area": gc.area},
            "n_steps": self.n_steps,
            "path_lengths": self.path_lengths,
            "path_polyline_lengths": self.path_polyline_lengths,
            "exact_region_area": self.region.area,
            "area_vs_d_total": [{"d_total": d, "paper": a, "exact": e}
                                for d, a, e in zip(ds, lit, exact, strict=True)],
            "sigma": sigma_json(self.sigma), "sigma_text": self.sigma.describe(),
            "mirror_poses": self.n_poses,
            "scene_beacon": {"rmse": self.scene_beacon_rmse,
                             "seen_fraction": self.scene_beacon_seen},
            "best_beacon": {"position": self.best.position.tolist(),
                            "rmse": self.best.rmse,
                            "seen_fraction": self.best.seen_fraction},
            "scene_beacons": [{"rmse": r, "seen_fraction": f} for r, f in self.scene_beacons],
            **({"beacon_set": _set_json(self.beacon_set)} if self.beacon_set else {}),
            **({"beacon_heights": [h.to_json() for h in self.heights]} if self.heights else {}),
        }


def _set_json(bs: BeaconSet) -> dict:
    """The planned set: positions in the order chosen, the expected RMSE after each."""
    inf = lambda x: None if not np.isfinite(x) else x  # noqa: E731  (strict JSON)
    return {"self_calibration": list(bs.calibration.nuisances),
            **({"priors": dict(bs.calibration.priors)} if bs.calibration.priors else {}),
            "beacons": [{"position": p.tolist(), "rmse_after": inf(r), "rmse_after_plain": q}
                        for p, r, q in zip(bs.positions, bs.rmse, bs.rmse_plain, strict=True)]}


def plan_scene(scene: Scene, sigma: Sigma | ObjectSigmas | None = None, eps_deg: float = 5.0,
               *, yaw_spread_deg: float = 3.0, d1_spread: float = 2.0, step: float = 1.0,
               n_poses: int = 5, n_beacons: int = 1,
               calibration: SelfCalibration = PLAIN) -> Plan:
    """Placement numbers, paths, the exact beacon region and the best beacon position.

    The target's α and d_total are taken as measured without error; the mirror prior is
    centred on the scene's mirror (its reflection point along the target's ray, its yaw)
    with the given spreads.  With ``n_beacons`` > 1 or ``calibration``'s nuisances: the
    best set of that many beacons, chosen one at a time, with the nuisances estimated
    alongside and known to its priors (:func:`solver.beacon_set.best_beacon_set`), each
    beacon's position known to its position σ.  A 3-D scene is placed in plan, each
    position with its post (:func:`~mirrorsim.pipelines.planning3d.height_choices`).

    Raises
    ------
    BadParameter
        A σ, ε or step not > 0, ε ≥ 45°, a negative spread, ``n_beacons`` or ``n_poses``
        not a whole number within its range.
    SolverError
        A ``calibration`` that is not a :class:`~solver.selfcal.SelfCalibration`.
    """
    check_given_scene(scene)  # edited by a script: held to what its file would make
    # independent errors: a shared α offset enters each α whole (docs/limitations.md)
    sigma = as_object_sigmas(sigma or Sigma()).independent()
    if len(sigma.beacons) > 1:  # it was silently taken for the first beacon's
        raise BadParameter("sigma", f"{len(sigma.beacons)} beacon σ pairs: give one (every "
                           "position the plan tries is a pencil like the others)")
    _check_parameters(sigma, eps_deg, step, yaw_spread_deg, d1_spread)
    calibration = check_planar(as_calibration(calibration))  # a planar solve's: no pitch
    for name, v, hi in (("n_beacons", n_beacons, MAX_PLANNED_BEACONS),
                        ("n_poses", n_poses, MAX_POSES)):
        if not (is_whole(v) and 1 <= v <= hi):
            raise BadParameter(name, f"{v!r} must be a whole number within 1..{hi}")
    cam, mir = scene.camera, scene.mirror
    img = optics.mirror_image(cam.position, mir, scene.target.position)
    o = np.asarray(cam.position, float)
    s = mir.size[0]
    prior = MirrorPrior(d1=img.d1, yaw_deg=mir.yaw, d1_spread=d1_spread,
                        yaw_spread_deg=yaw_spread_deg, n=n_poses)
    poses = prior.poses(o, img.alpha_deg)
    best = _best_position(scene, o, img.alpha_deg, img.d_total, poses, sigma, step)
    chosen = None
    if n_beacons > 1 or calibration.nuisances or calibration.position_sigma:
        keep_out, accept = _placement_rules(scene)
        chosen = best_beacon_set(o, img.alpha_deg, img.d_total, poses=poses, sigma=sigma,
                                 mirror_size=s, board=scene.board.size, n=n_beacons,
                                 calibration=calibration, step=step, keep_out=keep_out,
                                 accept=accept)
    scene_err, scene_seen = expected_target_error(
        o, img.alpha_deg, img.d_total, beacons=np.array([b.position for b in scene.beacons]),
        poses=poses, sigma=sigma, mirror_size=s, min_depth=0.0)
    return Plan(
        target_alpha_deg=img.alpha_deg, target_d_total=img.d_total, eps_deg=eps_deg,
        sigma=sigma, **_paper_fields(o, img.alpha_deg, img.d_total, s=s, eps_deg=eps_deg),
        n_poses=len(poses), best=best, scene_beacon_rmse=float(scene_err[0]),
        scene_beacon_seen=float(scene_seen[0]),
        scene_beacons=tuple((float(e), float(f)) for e, f in zip(scene_err, scene_seen,
                                                                  strict=True)),
        beacon_set=chosen, heights=_posts(scene, sigma, best, chosen))


def _posts(scene: Scene, sigma: ObjectSigmas, best: BeaconSearch, chosen: BeaconSet | None
           ) -> tuple[HeightChoice, ...]:
    """A 3-D scene's posts at the scene's beacons, the best position and the set's."""
    if not scene.is_3d:
        return ()
    return height_choices(scene, sigma, [*(tuple(b.position) for b in scene.beacons),
                                         tuple(best.position),
                                         *(tuple(q) for q in (chosen.positions if chosen
                                                              else ()))])


def _paper_fields(o: np.ndarray, alpha_deg: float, d_total: float, *, s: float,
                  eps_deg: float) -> dict:
    """The paper's placement for the target's image (α, d_total): its numbers, literal
    and corrected, the paths and their lengths, the exact beacon region and the area
    against d_total beside the literal one (the :class:`Plan` fields of those names)."""
    geo = paper_placement(alpha_deg, d_total, s, eps_deg=eps_deg)
    n_steps = max(1, math.ceil(d_total / geo.b))
    R = o + geo.R
    paths = {k: path_points(k, R, alpha_deg, a=2 * geo.half_a, b=geo.b, n=n_steps)
             for k in ("linear", "rectangular", "sawtooth")}
    area_lit = [paper_placement(alpha_deg, d, s, eps_deg=eps_deg).area for d in AREA_DISTANCES]
    area_exact = [region_area(o, alpha_deg, d, s=s, eps_deg=eps_deg) for d in AREA_DISTANCES]
    return {"geometry": geo,
            "geometry_corrected": paper_placement(alpha_deg, d_total, s, eps_deg=eps_deg,
                                                  literal=False),
            "n_steps": n_steps, "paths": paths,
            "path_lengths": path_lengths(2 * geo.half_a, geo.b, n_steps),
            "path_polyline_lengths": {k: polyline_length(v) for k, v in paths.items()},
            "region": _exact_region(o, R, alpha_deg, d_total, s, eps_deg),
            "area_vs_d": (list(AREA_DISTANCES), area_lit, area_exact)}


# the least orientation range: the region seen under every orientation spans
# ~ (s/2)/tan(2ε), so its grid grows as 1/ε² (0.01° asked for 182 GiB, 0.5° ran minutes)
MIN_EPS_DEG = 1.0


def _check_parameters(sigma: ObjectSigmas, eps_deg: float, step: float,
                      yaw_spread_deg: float, d1_spread: float) -> None:
    pairs = (sigma.target, *sigma.beacons)
    for name, v, lo, hi in (
            *(("sigma.alpha_deg", s.alpha_deg, SIGMA_ALPHA_MIN_DEG, SIGMA_ALPHA_MAX_DEG)
              for s in pairs),
            *(("sigma.d_total_rel", s.d_total_rel, SIGMA_D_REL_MIN, SIGMA_D_REL_MAX)
              for s in pairs)):
        if not lo <= v <= hi:
            raise BadParameter(name, f"{v} must be within [{lo:g}, {hi:g}]")
    if not MIN_EPS_DEG <= eps_deg < 45:
        raise BadParameter("eps_deg", f"{eps_deg} must be ≥ {MIN_EPS_DEG:g} and < 45")
    if not MIN_STEP <= step <= 20:
        raise BadParameter("step", f"{step} must be within [{MIN_STEP:g}, 20] cm")
    for name, v in (("yaw_spread_deg", yaw_spread_deg), ("d1_spread", d1_spread)):
        if not 0 <= v <= 30:
            raise BadParameter(name, f"{v} must be within [0, 30]")


def _exact_region(o: np.ndarray, R: np.ndarray, alpha_deg: float, d_total: float, s: float,
                  eps_deg: float) -> Region:
    """Where a beacon is seen for every mirror orientation within ±ε, on a grid around R."""
    span = 1.5 * (s / 2) / math.tan(math.radians(2 * eps_deg)) + s
    xs = np.linspace(R[0] - span, R[0] + span, 241)
    ys = np.linspace(R[1] - span, R[1] + span, 241)
    gx, gy = np.meshgrid(xs, ys)
    mask = visible_region(o, alpha_deg, d_total, s=s, eps_deg=eps_deg,
                          grid=np.column_stack([gx.ravel(), gy.ravel()])).reshape(gx.shape)
    return Region(xs, ys, mask, float(mask.sum() * (xs[1] - xs[0]) * (ys[1] - ys[0])))


def _best_position(scene: Scene, o: np.ndarray, alpha_deg: float, d_total: float, poses,
                   sigma: Sigma, step: float) -> BeaconSearch:
    """The board's best beacon position: clear of walls, the mirror and the panel, and
    its image unobstructed through the scene's own mirror."""
    keep_out, unobstructed = _placement_rules(scene)
    return best_beacon(o, alpha_deg, d_total, poses=poses, sigma=sigma,
                       mirror_size=scene.mirror.size[0],
                       board=scene.board.size, step=step, keep_out=keep_out, accept=unobstructed)


def _placement_rules(scene: Scene):
    """Where a beacon may stand: clear of walls, the mirror and the panel (segments with
    clearances), and its image unobstructed through the scene's own mirror (a test)."""
    mir = scene.mirror
    keep_out = [(occ.start, occ.end, OCCLUDER_THICKNESS / 2 + PENCIL_RADIUS)
                for occ in scene.occluders]
    keep_out.append((*mir.ends(), MIRROR_DEPTH + PENCIL_RADIUS))
    keep_out.append((*scene.target.ends(), TARGET_THICKNESS / 2 + PENCIL_RADIUS))
    height = scene.beacons[0].height

    def unobstructed(p) -> bool:
        # the true mirror's rectangle, walls and the target panel must let its image
        # through, and the image must lie far enough beyond the beacon itself for the
        # detector to tell it from a direct view
        moved = replace(scene, beacons=(Beacon((float(p[0]), float(p[1])), height),))
        img = optics.mirror_image(scene.camera.position, mir, moved.beacons[0].position)
        direct = float(np.hypot(*(np.asarray(p, float) - scene.camera.position)))
        return (img.d_total >= (1 + PLACEMENT_EXCESS) * direct
                and visibility.visibility(moved, moved.beacons[0]).fraction == 1.0)

    return keep_out, unobstructed
