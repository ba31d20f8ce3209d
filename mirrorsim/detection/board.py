"""The camera's pose from the pegboard it stands on: the bench calibrates its own mount.

The holes of the board lie on a known grid (:meth:`mirrorsim.scene.model.Board.hole_centres`)
and the camera's position and height are measured, so the holes seen directly in a frame
fix the camera's orientation: its pan (which the mount reports to some tenths of a degree,
and which shifts every α alike), its pitch and its roll.  Each hole is a dark blob on the
beige board; its centroid is matched to the grid projected with the pose the mount
reports, then the pose is fitted to the matched holes by robust least squares.  How
close it comes on the bench spec's rendered JPEG frames: ``benchmarks/selfcal.py``'s
line on the board's camera pose (the registered selfcal results).

A pitched camera also changes how tall an upright object looks: :func:`pitch_factor`.
Pure numpy, SciPy and OpenCV; no truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from mirrorsim.camera.sensor import undistort
from mirrorsim.errors import DetectionError
from mirrorsim.formats.capture import CaptureRecord
from mirrorsim.scene.model import Board, Camera
from mirrorsim.scene.projection import project

# a hand-built bench's mount is good to this (deg) in pan, pitch and roll: the search
# spans it, a correlation of the holes' image with the grid's under each roll first
SEARCH_DEG = 3.2
ROLL_STEP_DEG = 0.2
# the correlation's maps are at this share of the frame's resolution, each point a
# Gaussian of this σ (px of the map)
MAP_SCALE = 0.5
MAP_SIGMA_PX = 1.2
# around each roll's correlated pose, the finer search: ±LOCAL_DEG in pan and pitch in
# steps of COARSE_STEP_DEG, the pose that puts most holes on blobs kept
LOCAL_DEG = 0.2
COARSE_STEP_DEG = 0.1
# a pose is a match only if it puts at least this share of the holes it projects onto
# the frame on blobs, and their median residual is within the holes' image noise
# (0.2-0.3 px on the project's renders at any size): else the grid is locked onto the
# wrong holes (a pitch off, or on another dark pattern).  The residual tells: wrong poses
# left 1.0-1.3 px; a JPEG bench's frames find 13-25 % of the holes its pose projects
MATCH_SHARE = 0.1
RESIDUAL_MAX_PX = 0.6
# a blob within this of a projected hole (px) counts in the coarse search
COARSE_GATE_PX = 4.0
# the matching gate narrows from FIRST_GATE_PX to LAST_GATE_PX as the pose converges
FIRST_GATE_PX, LAST_GATE_PX = 8.0, 2.0
MIN_HOLES = 20  # fewer matched holes than this: no pose
# a hole is darker than this share of the board around it
DARK_SHARE = 0.55
BACKGROUND_PX = 31  # the median filter that gives the board's level around each hole
MIN_BLOB_AREA = 4  # px: a smaller dark spot is noise, not a hole


@dataclass(frozen=True)
class CameraPose:
    """The camera's orientation as the board's holes give it: the pan's offset from the
    mount's reading (deg, add it to every α), the pitch (deg, optical axis raised) and the
    roll (deg); how many holes were matched, their median residual (px) and the pan's
    standard deviation from the fit (deg)."""

    pan_offset_deg: float
    pitch_deg: float
    roll_deg: float
    holes: int
    residual_px: float
    pan_sd_deg: float

    def to_json(self) -> dict:
        """The pose as ``evaluate --json`` reports it."""
        return {"pan_offset_deg": self.pan_offset_deg, "pitch_deg": self.pitch_deg,
                "roll_deg": self.roll_deg, "holes": self.holes,
                "residual_px": self.residual_px, "pan_sd_deg": self.pan_sd_deg}


def hole_blobs(image: np.ndarray) -> np.ndarray:
    """(k, 2) sub-pixel centroids (u, v) of dark blobs on a lighter surround in an 8-bit
    RGB frame: each weighed by how much darker than its surround each pixel is."""
    grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    level = cv2.medianBlur(grey, BACKGROUND_PX).astype(np.float32)
    g = grey.astype(np.float32)
    mask = ((g < DARK_SHARE * level) & (level > 60)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    out = []
    for i in range(1, n):
        x0, y0, w, h, area = (int(v) for v in stats[i])
        if not (MIN_BLOB_AREA <= area <= 3000 and w >= 3 and h >= 2):
            continue
        box = np.s_[y0:y0 + h, x0:x0 + w]
        weight = np.clip(level[box] - g[box], 0, None) * (labels[box] == i)
        total = float(weight.sum())
        if total <= 0:
            continue
        yy, xx = np.mgrid[y0:y0 + h, x0:x0 + w]
        out.append(((weight * xx).sum() / total, (weight * yy).sum() / total))
    return np.asarray(out, float).reshape(-1, 2)


def project_holes(camera: Camera, holes: np.ndarray, pan_offset: float = 0.0,
                  *, pitch: float = 0.0, roll: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Pixel positions (k, 2) of board points (k, 2) at z = 0 for the camera turned by
    ``pan_offset`` and pitched and rolled; and their depth along the optical axis."""
    u, v, z = project(turned(camera, pan_offset),
                      np.column_stack([holes, np.zeros(len(holes))]), pitch, roll=roll)
    return np.column_stack([u, v]), z


def turned(camera: Camera, pan_offset: float) -> Camera:
    """``camera`` with its pan turned by ``pan_offset`` (deg)."""
    return replace(camera, pan_deg=camera.pan_deg + pan_offset)


def _on_film(camera: Camera, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    return ((z > 1.0) & (uv[:, 0] > 0) & (uv[:, 0] < camera.width - 1)
            & (uv[:, 1] > 0) & (uv[:, 1] < camera.height_px - 1))


def measure_camera_pose(image: np.ndarray, camera: Camera, board: Board,
                        *, start: tuple[float, float, float] | None = None) -> CameraPose:
    """The camera's pan offset, pitch and roll from the board's holes in ``image`` (8-bit
    RGB, the pinhole image: undistorted where the lens is calibrated), ``camera`` as the
    mount reports it.  ``start``: fit from this pose (pan offset, pitch, roll; deg)
    instead of searching ±SEARCH_DEG for one (what a test locks a pitch off with).

    Raises
    ------
    DetectionError
        A plain board, fewer than MIN_HOLES holes matched, or a pose that does not fit
        the holes (too few of those it projects on blobs, or a residual beyond their
        image noise: the grid locked onto the wrong holes).
    """
    from scipy.spatial import cKDTree

    holes = board.hole_centres()
    if not len(holes):
        raise DetectionError("the board has no holes to measure the camera's pose on")
    blobs = hole_blobs(image)
    if len(blobs) < MIN_HOLES:
        raise DetectionError(f"{len(blobs)} hole-like blobs in the frame: too few to measure "
                             f"the camera's pose on (need {MIN_HOLES})")
    tree = cKDTree(blobs)

    x = np.asarray(start, float) if start is not None else _coarse_pose(
        camera, holes, blobs, tree, hole_diameter=board.hole_diameter)
    x, pairs, fit = _fit_pose(camera, holes, blobs, tree, x)
    r = _residuals(camera, holes, blobs, pairs, x).reshape(-1, 2)
    residual = float(np.median(np.hypot(*r.T)))
    uv, z = project_holes(camera, holes, x[0], pitch=x[1], roll=x[2])
    # the holes the pose puts on the frame large enough to be found (some are behind
    # the mirror, the target, a wall: a share of them)
    on_film = int((_on_film(camera, uv, z)
                   & (_blob_area(camera, z, board.hole_diameter) >= MIN_BLOB_AREA)).sum())
    if len(pairs[0]) < MATCH_SHARE * on_film or residual > RESIDUAL_MAX_PX:
        raise DetectionError(
            f"the board's holes do not fit one pose: the best puts {len(pairs[0])} of the "
            f"{on_film} holes large enough to see on blobs, their median residual "
            f"{residual:.2f} px (a match needs {MATCH_SHARE:.0%} and at most "
            f"{RESIDUAL_MAX_PX:g} px); the grid would be locked onto the wrong holes (the "
            f"search covers a mount off by up to ±{SEARCH_DEG:g}° in pan, pitch and roll)")
    # the pan's σ from the fit: the residuals' robust spread through the Jacobian
    spread = 1.4826 * float(np.median(np.abs(r - np.median(r, axis=0))))
    J = fit.jac
    cov = np.linalg.pinv(J.T @ J) * max(spread, 1e-3) ** 2
    return CameraPose(pan_offset_deg=float(x[0]), pitch_deg=float(x[1]), roll_deg=float(x[2]),
                      holes=len(pairs[0]), residual_px=residual,
                      pan_sd_deg=float(math.sqrt(max(cov[0, 0], 0.0))))


def _coarse_pose(camera: Camera, holes: np.ndarray, blobs: np.ndarray, tree: Any, *,
                 hole_diameter: float) -> np.ndarray:
    """The pose (pan offset, pitch, roll; deg) the fit starts from: of the poses within
    the mount's tolerance the correlation finds, and the pan and pitch near each, the one
    that puts most holes on blobs."""
    def matched(x: np.ndarray, gate: float) -> int:
        uv, z = project_holes(camera, holes, x[0], pitch=x[1], roll=x[2])
        uv = uv[_on_film(camera, uv, z)]
        if not len(uv):
            return 0
        return int(np.sum(tree.query(uv, distance_upper_bound=gate)[0] < gate))

    best, x = -1, np.zeros(3)
    for near in _correlated_poses(blobs, camera, holes, hole_diameter):
        for dp in _grid(LOCAL_DEG):
            for pt in _grid(LOCAL_DEG):
                cand = near + np.array([dp, pt, 0.0])
                count = matched(cand, COARSE_GATE_PX)
                if count > best:
                    best, x = count, cand
    return x


def _residuals(camera: Camera, holes: np.ndarray, blobs: np.ndarray,
               pairs: tuple[np.ndarray, np.ndarray], x: np.ndarray) -> np.ndarray:
    uv, _ = project_holes(camera, holes[pairs[0]], x[0], pitch=x[1], roll=x[2])
    return (uv - blobs[pairs[1]]).ravel()


def _fit_pose(camera: Camera, holes: np.ndarray, blobs: np.ndarray, tree, x: np.ndarray):
    """The pose fitted to the holes matched near ``x``, the gate narrowing from
    FIRST_GATE_PX to LAST_GATE_PX as it converges; the pose, the matched pairs (hole
    indices, blob indices) and the last fit.

    Raises
    ------
    DetectionError
        Fewer than MIN_HOLES holes matched.
    """
    from scipy.optimize import least_squares

    gate = FIRST_GATE_PX
    while True:
        uv, z = project_holes(camera, holes, x[0], pitch=x[1], roll=x[2])
        seen = np.flatnonzero(_on_film(camera, uv, z))
        dist, which = tree.query(uv[seen], distance_upper_bound=gate)
        near = dist < gate
        pairs = (seen[near], which[near])
        if len(pairs[0]) < MIN_HOLES:
            raise DetectionError(
                f"{len(pairs[0])} of the board's holes matched in the frame: too few to "
                f"measure the camera's pose on (need {MIN_HOLES}; the search covers a mount "
                f"off by up to ±{SEARCH_DEG:g}° in pan, pitch and roll)")

        # the step from the current pose, from exactly zero: least squares sizes its first
        # trust region by the start's norm, and a start of 1e-16 never moved
        fit = least_squares(lambda step, x=x, pairs=pairs: _residuals(
            camera, holes, blobs, pairs, x + step), np.zeros(3), loss="soft_l1", f_scale=0.5)
        x = x + fit.x
        if gate <= LAST_GATE_PX:
            return x, pairs, fit
        gate = max(LAST_GATE_PX, gate / 1.5)


def _blob_area(camera: Camera, depth: np.ndarray, diameter: float) -> np.ndarray:
    """The image area (px) of a hole of ``diameter`` cm on the board at ``depth`` cm
    along the optical axis: its width fx·D/z by its foreshortened height fx·D·h/z² (the
    camera ``h`` cm above the board)."""
    z = np.maximum(depth, 1e-6)
    return math.pi / 4 * (camera.fx * diameter / z) * (camera.fx * diameter * camera.height
                                                        / z**2)


def _correlated_poses(blobs: np.ndarray, camera: Camera, holes: np.ndarray,
                      hole_diameter: float) -> list[np.ndarray]:
    """Candidate poses (pan offset, pitch, roll), deg: for each roll within ±SEARCH_DEG,
    the shift that best lays the grid's projected holes over the blobs (the peak of the
    two point maps' cross-correlation, by FFT), read as a pan (a shift across, fx·tan)
    and a pitch (a shift down).  A roll moves the holes below the frame's middle much as
    a pan does, so the candidates are judged by the holes each puts on blobs."""
    s = MAP_SCALE
    pad = int(math.ceil(camera.fx * math.tan(math.radians(SEARCH_DEG)) * s)) + 4
    shape = (int(camera.height_px * s) + 2 * pad, int(camera.width * s) + 2 * pad)

    def point_map(uv: np.ndarray) -> np.ndarray:
        m = np.zeros(shape, np.float32)
        rc = np.round(uv[:, ::-1] * s).astype(int) + pad
        ok = (rc[:, 0] >= 0) & (rc[:, 0] < shape[0]) & (rc[:, 1] >= 0) & (rc[:, 1] < shape[1])
        m[rc[ok, 0], rc[ok, 1]] = 1.0
        return cv2.GaussianBlur(m, (0, 0), MAP_SIGMA_PX)

    seen = np.fft.rfft2(point_map(blobs))
    out = []
    k = round(SEARCH_DEG / ROLL_STEP_DEG)
    for roll in np.arange(-k, k + 1) * ROLL_STEP_DEG:
        uv, z = project_holes(camera, holes, 0.0, pitch=0.0, roll=roll)
        # the holes a shift within the search could bring onto the frame, and large
        # enough to be found as blobs: the far rows' holes, packed closely, would lay
        # themselves over any blobs and drown the near ones' peak
        m = ((z > 1.0) & (uv[:, 0] > -pad / s) & (uv[:, 0] < camera.width + pad / s)
             & (uv[:, 1] > -pad / s) & (uv[:, 1] < camera.height_px + pad / s)
             & (_blob_area(camera, z, hole_diameter) >= MIN_BLOB_AREA))
        corr = np.fft.irfft2(seen * np.conj(np.fft.rfft2(point_map(uv[m]))), s=shape)
        peak = np.unravel_index(int(np.argmax(corr)), shape)
        dv, du = ((p + n // 2) % n - n // 2 for p, n in zip(peak, shape, strict=True))
        out.append(np.array([math.degrees(math.atan(du / s / camera.fx)),
                             math.degrees(math.atan(dv / s / camera.fx)), roll]))
    return out


def _grid(half: float) -> np.ndarray:
    """The coarse search's values within ±half: whole multiples of its step, so that its
    middle one is exactly 0."""
    k = round(half / COARSE_STEP_DEG)
    return np.arange(-k, k + 1) * COARSE_STEP_DEG


def pitch_factor(pitch_deg: float, top: float, camera_height: float, *, distance: float
                 ) -> float:
    """How much taller an upright object ``top`` cm high, standing ``distance`` cm away
    (horizontally), looks to a camera ``camera_height`` cm up pitched by ``pitch_deg``
    than to a level one (its rows, on the optical axis's column): multiply a d_total
    measured by size constancy with the level camera's K by this factor."""
    p = math.radians(pitch_deg)
    above, below = math.atan2(top - camera_height, distance), math.atan2(-camera_height,
                                                                        distance)
    return ((math.tan(above - p) - math.tan(below - p))
            / (math.tan(above) - math.tan(below)))


# the pan's σ after the board, at the least: on the bench spec's frames the board's pan
# errs by about 0.001° RMS (benchmarks/selfcal.py prints it), where its fit's own σ says
# a few ten-thousandths (the holes' centroids share small biases the fit does not see)
PAN_SD_FLOOR_DEG = 0.002  # at the bench's focal length, FLOOR_FX_PX; ∝ 1/fx (pixel errors)
FLOOR_FX_PX = 1500.0


def frame_pose(pixels: np.ndarray, capture: CaptureRecord, where: str | Path = "the frame"
               ) -> CameraPose:
    """:func:`measure_camera_pose` on a frame's stored pixels, as the detector sees them
    (the lens's distortion taken out where it was calibrated); the board from the capture
    record; ``where``: the frame's name, for the messages.

    Raises
    ------
    DetectionError
        A capture record without a board (made before it recorded one), or as
        :func:`measure_camera_pose`.
    """
    if capture.board is None:
        raise DetectionError(f"{where}: its capture record names no board (made by an "
                             "older mirrorsim: render the frame again)")
    if capture.distortion != (0.0, 0.0):
        pixels = undistort(pixels, capture.camera, capture.distortion)
    try:
        return measure_camera_pose(pixels, capture.camera, capture.board)
    except DetectionError as exc:
        raise DetectionError(f"{where}: {exc}") from None


def mean_pose(poses: list[CameraPose]) -> CameraPose:
    """The pose of one camera measured in several of its frames: their mean (the pan's σ
    their mean σ, not that of a mean of independent errors)."""
    return CameraPose(
        pan_offset_deg=float(np.mean([p.pan_offset_deg for p in poses])),
        pitch_deg=float(np.mean([p.pitch_deg for p in poses])),
        roll_deg=float(np.mean([p.roll_deg for p in poses])),
        holes=int(sum(p.holes for p in poses)),
        residual_px=float(np.median([p.residual_px for p in poses])),
        # the frames see one board from one pose: their errors are not independent
        pan_sd_deg=float(np.mean([p.pan_sd_deg for p in poses])))


def pose_pan_sigma(pose: CameraPose, fx_px: float = FLOOR_FX_PX) -> float:
    """The σ (deg) of what is left of the pan once the board has measured it, on frames of
    focal length ``fx_px`` (a smaller frame sees the holes in fewer pixels)."""
    floor = PAN_SD_FLOOR_DEG * max(1.0, FLOOR_FX_PX / fx_px)
    return float(math.hypot(pose.pan_sd_deg, floor))
