"""The moving beacon's path on the board (`mirrorsim track`): laid out from what the
experimenter knows at the start pose, never from the scene's mirror or target."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mirrorsim.errors import BadParameter
from mirrorsim.scene.model import PENCIL_RADIUS, Bench, Scene, footprints
from mirrorsim.truth.compose import with_facing
from mirrorsim.truth.visibility import visibility
from solver.errors import SolverError
from solver.geometry import bearing_deg, line_normal, segment_distance, wrap_bearing
from solver.placement import path_points
from solver.sltr import locate, mirror_from_beacon, observe, ray_hits_line

PATHS = ("rectangular", "linear", "sawtooth", "fixed")  # fixed: the baseline, standing still
HEADINGS = ("view", "camera")
CLEARANCE_CM = 1.0  # the path's least distance in front of the start's mirror line
# the path's least distance from a fixed beacon's believed position: two pencils apart,
# with half a centimetre between them
FIXED_CLEARANCE_CM = 2 * PENCIL_RADIUS + 0.5
# a pencil's least gap to the target panel and the walls, as the start pose shows them
OBJECT_CLEARANCE_CM = 0.5


def beacon_path(scene: Scene, first_obs: tuple[float, float],
                target_obs: tuple[float, float], *, kind: str, steps: int, side: float,
                step: float, heading: str = "view") -> np.ndarray:
    """The commanded positions, start first: ``steps`` moves along the path ``kind``.

    The path is laid out from what the experimenter knows at the start pose, never from
    the scene's mirror or target: the bench (board, occluders, camera, the mirror's and
    the target's sizes) and the start pose's measurements.  The beacon's (α, d_total)
    give a mirror line (the perpendicular bisector of the beacon and its image); the
    glass is placed on it between the beacon's and the target's reflection points, and
    the target panel (a wall for the beacon's image) where that mirror puts it.
    ``heading`` sets the line the steps of b run on: ``view``, the beacon's reflected
    line of sight (its image stays on the same part of the glass); ``camera``, the
    camera's line to the beacon.  Of the four ways to walk it (b forwards or back, side a
    left or right), the path kept is the first by: on the board, ``CLEARANCE_CM`` in
    front of the mirror line, its moves ``OBJECT_CLEARANCE_CM`` clear of the target panel
    and the walls and ``FIXED_CLEARANCE_CM`` from fixed beacons (no robot drives off the
    board or into the glass or a wall); most poses predicted seen in that glass; b
    forwards (``view``: away from the glass; ``camera``: towards the camera); images
    nearest the target's in α.  The clearances hold for the commanded poses: odometry
    noise moves the true ones.

    Raises
    ------
    SolverError
        If the start pose's measurement gives no mirror.
    BadParameter
        ``side``: if no way to walk the path keeps every clearance.
    """
    b0 = scene.beacons[0]
    o = np.asarray(scene.camera.position, float)
    s0 = np.asarray(b0.believed, float)
    if kind == "fixed":
        return np.tile(s0, (steps + 1, 1))
    yaw, mid, hit = mirror_from_beacon(o, s0, first_obs[0], d_total=first_obs[1])
    yaw = float(yaw)
    front = line_normal(yaw)
    front = front if front @ (s0 - mid) > 0 else -front
    believed = _believed_scene(scene, o, yaw, mid, hit, target_obs)
    h = float(bearing_deg(hit, s0) if heading == "view" else bearing_deg(s0, o))
    best: tuple[tuple, np.ndarray] | None = None
    for forwards in (True, False):
        for a in (side, -side):
            # path_points steps towards its ``alpha`` origin: alpha = heading + 180°
            pts = path_points(kind, s0, h + (180.0 if forwards else 0.0), a=a, b=step,
                              n=steps // 2 + 2)
            pts = (pts - pts[0] + s0)[: steps + 1]
            score = _ranked(pts, believed, (mid, yaw, front), target_alpha_deg=target_obs[0],
                            forwards=forwards)
            if best is None or score > best[0]:
                best = (score, pts)
    if not best[0][0]:
        raise BadParameter("side", f"{side:g} cm (with a step of {step:g} cm, {steps} steps): "
                           "every way to walk this path leaves the board, comes within "
                           f"{CLEARANCE_CM:g} cm of the mirror, within {OBJECT_CLEARANCE_CM:g} "
                           f"cm of the target or a wall, or within {FIXED_CLEARANCE_CM:g} cm "
                           "of a fixed beacon; make the path smaller, or start the beacon "
                           "farther from what it would meet")
    return best[1]


def _ranked(pts: np.ndarray, believed: Scene, line: tuple[np.ndarray, float, np.ndarray], *,
            target_alpha_deg: float, forwards: bool) -> tuple[bool, int, bool, float]:
    """How :func:`beacon_path` ranks a way to walk it (``line``: the believed mirror's
    point, yaw and front): whether it keeps every clearance, how many of its poses are
    predicted seen in the glass, b forwards, and how near its images are to the
    target's in α."""
    mid, yaw, front = line
    o = np.asarray(believed.camera.position, float)
    size = np.asarray(believed.board.size, float)
    b0 = believed.beacons[0]
    allowed = (bool(np.all((pts >= 0) & (pts <= size)))
               and float(np.min((pts - mid) @ front)) >= CLEARANCE_CM
               and all(np.min(np.linalg.norm(pts - np.asarray(b.believed), axis=1))
                       >= FIXED_CLEARANCE_CM for b in believed.beacons[1:])
               and _clear_of_objects(believed, pts))
    seen = sum(_seen_in(believed, replace(b0, position=tuple(p))) for p in pts)
    alphas = observe(o, mid, yaw, point=pts, strict=False).alpha_deg
    spread = float(np.mean(np.abs(wrap_bearing(alphas - target_alpha_deg))))
    return allowed, seen, forwards, -spread


def _clear_of_objects(believed: Scene, pts: np.ndarray) -> bool:
    """Whether a pencil moved along the poses ``pts`` (start first) stays clear of the
    target panel (where the start pose puts it) and the walls: a path once walked the
    beacon into the panel, rendering a scene that `check` refuses.  Each pose after the
    start and each move between two of them keep ``OBJECT_CLEARANCE_CM``; the first move
    leaves the start, which stands where the scene puts it, and must not pass through.
    """
    for key, a, b, radius in footprints(believed):
        if not key.startswith(("target", "occluders")):
            continue
        least = radius + PENCIL_RADIUS
        for k in range(len(pts) - 1):
            margin = OBJECT_CLEARANCE_CM if k else 0.0
            if segment_distance(pts[k], pts[k + 1], a, q1=b) < least + margin:
                return False
    return True


def _believed_scene(scene: Scene, o: np.ndarray, yaw: float, mid: np.ndarray,
                    hit: np.ndarray, target_obs: tuple[float, float]) -> Scene:
    """The scene as the start pose's measurements make it: the mirror on the beacon's
    mirror line, between the beacon's and the target's reflection points, and the
    target where that mirror puts it, on an ideal bench."""
    try:
        centre = (hit + ray_hits_line(o, target_obs[0], mid, yaw_deg=yaw)) / 2
    except SolverError:  # the target's ray misses the line (parallel, or behind)
        centre = hit
    mirror = replace(scene.mirror, yaw=yaw, center=tuple(map(float, centre)))
    target = tuple(map(float, locate(o, mid, yaw, alpha_deg=target_obs[0],
                                      d_total=target_obs[1])))
    # the panel's facing follows the believed mirror (a believed scene is never checked:
    # it is what was measured)
    return with_facing(replace(scene, mirror=mirror, bench=Bench(), target=replace(
        scene.target, position=target)))


def _seen_in(scene: Scene, beacon) -> bool:
    """Whether ``beacon``, standing alone in ``scene``, is seen whole in its mirror."""
    return visibility(replace(scene, beacons=(beacon,)), beacon).fraction == 1.0
