"""The detector: α and d_total of the target and the beacons, from a rendered frame.

With :mod:`mirrorsim.detection.edges` and :mod:`mirrorsim.detection.regions`, the
detector.  What it may use: the image and its capture record
(:class:`~mirrorsim.formats.capture.CaptureRecord`: the camera as its mount reports it, the
beacons' believed positions and heights, the target's size), the objects' appearance,
and the calibration.  Never the target's or the mirror's pose, nor the ground truth.

Model
-----
* **Finding.** The target is a neutral mid-grey panel: pixels of low chroma and mid
  value, opened with a disc wider than the mirror's frame bars (so the frame and the
  pegboard's holes drop out), kept where the connected region is a filled upright
  rectangle; then re-grown around its own median colour so a neighbour of another grey
  does not merge into it.  The pencil is the only strongly saturated yellow (its paint):
  saturation > 0.55 and (R+G)/2 − B > 30.
* **Edges, sub-pixel.** Along a band of columns (or rows) an edge is located by the
  *area* method: with the inside and outside colours taken a few pixels either side,
  each pixel's coverage c = ((x − out)·(in − out))/|in − out|² is summed over a window
  spanning the edge; for a box-filtered render (area-weighted pixels) this is exact up to
  noise.  Bands give independent estimates; their median resists partial occlusion.
* **α** = pan − atan((u_axis − cx)/fx): the bearing of the image's upright axis
  (+u is to the right, i.e. clockwise).
* **d_total.** A level pinhole images an upright segment of height H at depth Z with
  fy·H/Z pixels, so s_px · Z = K (size constancy along the optical axis) and
  d_total = Z / cos φ with φ = atan((u_axis − cx)/fx).  K is calibrated per object and
  camera by :mod:`mirrorsim.pipelines.calibrate` with exactly this measurement; the target's s_px
  is its panel's height, the pencil's is its painted band (the sharpened tip is thinner
  than a pixel at its point and is not measured).
* **Clipping.** The panel is seen square-on, so its width is 9.9/15.25 of its height: a
  narrower image is clipped at a side (the side whose outside is darker: the mirror's
  frame), the axis then comes from the other edge and the known half-width; a shorter
  one is clipped at the top and its d_total is not reported.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np

from mirrorsim.camera.sensor import undistort
from mirrorsim.detection.area_edges import bands
from mirrorsim.detection.assign import assign_beacons
from mirrorsim.detection.edges import cut_by_frame, measure_region, panel_top_face, to_linear
from mirrorsim.detection.image_geometry import (
    Calibration,
    pencil_geometry,
    target_geometry,
)
from mirrorsim.detection.image_measurement import ImageMeasurement, TopFace
from mirrorsim.detection.regions import find_pencils, find_target, pencil_mask
from mirrorsim.detection.rolled import image_roll, measure_rolled
from mirrorsim.errors import DetectionError
from mirrorsim.formats.capture import CaptureRecord
from mirrorsim.formats.error_model import ImageFeatures
from mirrorsim.scene.model import (
    Beacon,
    Camera,
    Point2,
    pencil_cone_ratio,
    pencil_paint_height,
)
from solver.measurements import BeaconMeasurement, Measurements


@dataclass
class Detection:
    """What the detector measured in one frame."""

    observer: Point2
    target: ImageMeasurement
    beacons: list[tuple[Beacon, ImageMeasurement]]  # each beacon and its mirror image
    images: list[ImageMeasurement]  # every pencil image found (mirror and direct)
    pan_deg: float | None = None  # the optical axis's bearing, as the capture record says
    noise: float = float("nan")  # the frame's relative noise (:func:`frame_noise`)
    jpeg_quality: int = 0  # the frame's JPEG quality as its file says (0: lossless)

    def features(self, m: ImageMeasurement, alpha_deg: float | None = None,
                 d_total: float | None = None) -> ImageFeatures:
        """What the error model weighs an image of this frame by (``alpha_deg`` and
        ``d_total``: its measurement corrected since, where it was)."""
        return ImageFeatures(m.alpha_deg if alpha_deg is None else alpha_deg,
                             m.d_total if d_total is None else d_total,
                             float(m.height_px or float("nan")), image_contrast(m),
                             self.noise, self.jpeg_quality)

    def measurements(self) -> Measurements:
        """The solver's inputs (raises DetectionError if the target's d_total is missing)."""
        if self.target.d_total is None:
            raise DetectionError("the target's d_total could not be measured (its image is "
                                 "clipped at the top)")
        return Measurements(observer=self.observer,
                            targets=[(self.target.alpha_deg, self.target.d_total)],
                            beacons=self.beacon_measurements(), observer_pan_deg=self.pan_deg)

    def beacon_measurements(self) -> list[BeaconMeasurement]:
        """Each beacon's known position with its mirror image's α and d_total."""
        return [BeaconMeasurement(tuple(b.position), m.alpha_deg, m.d_total)
                for b, m in self.beacons]

    def to_json(self) -> dict:
        """The measurements of docs/files.md plus a ``detector`` block with each image's
        pixels (axis column, edges, bbox, clipping, direct or mirror)."""
        t = self.target
        out = Measurements(observer=self.observer, targets=[(t.alpha_deg, t.d_total)],
                           beacons=self.beacon_measurements(),
                           observer_pan_deg=self.pan_deg).to_json()
        out["target"]["clipped"] = bool(t.clipped)
        for entry, (_, m) in zip(out["beacons"], self.beacons, strict=True):
            entry.update(clipped=bool(m.clipped), source="mirror")
        out["detector"] = {"target": _public(t), "images": [_public(p) for p in self.images]}
        return out


def measure_object(img: np.ndarray, kind: str, target_ratio: float | None = None,
                   *, linear: np.ndarray | None = None, subsampled: bool = False,
                   cone_ratio: float | None = None, top_face: TopFace | None = None
                   ) -> ImageMeasurement:
    """Find and measure the largest image of the target (``kind="target"``, with its
    width/height ``target_ratio``) or of a pencil in an 8-bit RGB image, exactly as
    :func:`detect_frame` measures it (calibration uses this on its reference renders).
    ``linear``: the image already converted by :func:`to_linear`, if the caller has it.
    ``subsampled``: measured as a frame whose colour was stored at half resolution
    (:func:`~mirrorsim.detection.edges.measure_region`).  ``cone_ratio``: a pencil's
    cone height over its painted band's (:func:`~mirrorsim.scene.model.pencil_cone_ratio`).
    ``top_face``: what the camera sees of a panel's top face
    (:func:`~mirrorsim.detection.edges.panel_top_face`).

    Raises
    ------
    DetectionError
        If no such object is found.
    """
    img = np.asarray(img, dtype=np.float32)
    linear = to_linear(img) if linear is None else linear
    if kind == "target":
        box = find_target(img, target_ratio)
        if box is None:
            raise DetectionError("no target (grey upright panel) found in the frame")
        return measure_region(linear, box, "target", subsampled=subsampled,
                              top_face=top_face)
    boxes = find_pencils(img)
    if not boxes:
        raise DetectionError("no pencil (yellow upright band) found in the frame")
    box = max(boxes, key=lambda b: (b[2] - b[0]) * (b[3] - b[1]))
    return measure_region(linear, box, "beacon", subsampled=subsampled, stored=img,
                          cone_ratio=cone_ratio)


def detect_frame(image: np.ndarray, view: CaptureRecord, calibration: Calibration,
                 *, subsampled: bool = False, jpeg_quality: int = 0) -> Detection:
    """Measure the target and each beacon in an RGB uint8 frame (``subsampled``: one
    whose colour was stored at half resolution, a JPEG; ``calibration`` measured so;
    ``jpeg_quality``: the quality its file gives, for the error model).

    Raises
    ------
    DetectionError
        If the target or a beacon's mirror image cannot be found.
    """
    cam = view.camera
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[:2] != (cam.height_px, cam.width):
        raise DetectionError(f"the frame is {img.shape[1::-1] if img.ndim >= 2 else img.shape} "
                             f"px but the camera is {cam.width}×{cam.height_px}")
    if view.distortion != (0.0, 0.0):  # a calibrated lens: measure on the pinhole image
        img = undistort(img, cam, view.distortion)
    linear = to_linear(img)  # from the 8-bit codes: no float copy to read back
    img = img.astype(np.float32)
    ratio = view.target_size[0] / view.target_size[1]
    cone = min(pencil_cone_ratio(b.height) for b in view.beacons)  # (the tallest pencil's)
    raised = view.geometry == "3d"
    paint = pencil_mask(img)  # (the panel's search and the pencils' boxes both read it)
    box = find_target(img, ratio, posts=raised, paint=paint)
    if box is None:
        raise DetectionError("no target (grey upright panel) found in the frame")
    measured = _measure(linear, img, box, kind="target", subsampled=subsampled,
                        target_ratio=ratio, raised=raised,
                        top_face=None if raised else panel_top_face(cam, view.target_size))
    boxes = find_pencils(img, paint)
    measured = _sides_behind_pencils(measured, boxes)
    pencils = [_measure(linear, img, b, kind="beacon", subsampled=subsampled,
                        cone_ratio=cone, raised=raised)
               for b in boxes]
    target = target_geometry(cam, measured, view.target_size, k=calibration.target_k)
    paint = pencil_paint_height(view.beacons[0].height)
    pencils = [pencil_geometry(cam, p, paint, k=calibration.pencil_k, subsampled=subsampled)
               for p in pencils
               if p.height_px and (p.u_left, p.u_right) != (None, None)]
    pencils = [p for p in pencils if not p.clipped]  # partly hidden: no bearing to trust
    if view.geometry == "planar":  # (in 3-D an image's foot lies where its object stands)
        for m in (target, *pencils):
            _check_stands_on_board(cam, m, view)
    images, mirror_imgs = assign_beacons(pencils, view)
    det = Detection(observer=tuple(cam.position), pan_deg=cam.pan_deg, target=target,
                    beacons=list(zip(view.beacons, mirror_imgs, strict=True)), images=images,
                    noise=frame_noise(linear, target.bbox_px), jpeg_quality=jpeg_quality)
    _check_a_mirror_fits(det)
    return det


# the rolls (deg, from the one read) a lost panel is turned by in turn, nearest first
ROLL_TRIES = (0.5, -0.5, 1.0, -1.0)


def _measure(linear: np.ndarray, img: np.ndarray, box: tuple[int, int, int, int], *,
             kind: str, subsampled: bool, raised: bool, target_ratio: float | None = None,
             cone_ratio: float | None = None, top_face: TopFace | None = None
             ) -> ImageMeasurement:
    """One image's edges.  A 3-D scene's are measured where each stands upright (a
    leaning mirror rolls its images by twice its lean, at a slant:
    :func:`~mirrorsim.detection.rolled.measure_rolled`).  A planar scene's are measured
    as they stand, and turned upright only where that found no height or no side: a
    bench's camera roll and mirror tilt roll its images by up to 5° (of 120 drawn
    benches, 2 lost their target so), while an upright image's roll, read on its pixels,
    scatters by up to 2° (perspective slopes a panel's top off the axis; a small
    pencil's region is a few pixels wide), and turning it would move edges that hold."""
    if raised:
        return measure_rolled(linear, img, box, kind=kind, subsampled=subsampled,
                              target_ratio=target_ratio, cone_ratio=cone_ratio)
    m = measure_region(linear, box, kind, subsampled=subsampled, stored=img,
                       cone_ratio=cone_ratio, top_face=top_face)
    lost = m.height_px is None or (m.u_left is None and m.u_right is None)
    if not lost or cut_by_frame(box, img.shape[0]):  # (cut by the frame: turning is no use)
        return m
    read = image_roll(img, box, kind)
    # a panel's roll read on one boundary alone carries that edge's perspective slope (a
    # wall in the glass as grey as the panel hid the top: its foot sloped 1.2°, its top
    # 3.6°, the roll 2.4°; turned by 1.29° no side was found, bench0080 of seed
    # 61207082): where the roll read gives no height or no side, the nearest of
    # ROLL_TRIES that gives both; not where the panel as it stands has both sides (its
    # bearing holds without a height, and a roll tried took a false one: ideal0041 of
    # seed 61207081)
    both = m.u_left is not None and m.u_right is not None
    for step in (0.0, *ROLL_TRIES) if kind == "target" and not both else (0.0,):
        turned = measure_rolled(linear, img, box, kind=kind, subsampled=subsampled,
                                target_ratio=target_ratio, cone_ratio=cone_ratio,
                                raised=False, roll=read + step)
        if turned.height_px is not None and (turned.u_left, turned.u_right) != (None, None):
            return turned
    return m


# how near (px) a pencil's region may come to a panel's side before that side is taken
# as the pencil's edge: the region's blur reaches a pixel past the paint
BEHIND_PENCIL_PX = 1.5


def _sides_behind_pencils(m: ImageMeasurement, boxes: list[tuple[int, int, int, int]]
                          ) -> ImageMeasurement:
    """The panel's measurement without a side that a pencil's image stands in front of
    (the side's column within a pencil region's columns, over half the rows the side is
    measured on, the middle 60 %: a pencil over fewer leaves the bands' median the
    panel's): that side is the pencil's edge, not the panel's (a pencil's reflection at
    a panel's side put its bearing 0.12° off, 19 σ).  The axis then comes from the other
    side and the height (image_geometry.target_geometry); with no other side or no
    height the side is kept, and the frame is measured as before."""
    if m.height_px is None:
        return m
    _, v0, _, v1 = m.bbox_px
    rows = bands(v0, v1, band_px=3)  # those the sides are measured on (median_edges')
    lo, hi = float(rows[0][0]), float(rows[-1][-1])
    hidden = [side for side, u in (("left", m.u_left), ("right", m.u_right)) if u is not None
              and any(b[0] - BEHIND_PENCIL_PX <= u <= b[2] + BEHIND_PENCIL_PX
                      and min(b[3], hi) - max(b[1], lo) >= 0.5 * (hi - lo) for b in boxes)]
    if len(hidden) != 1 or (m.u_left is None or m.u_right is None):
        return m
    side = hidden[0]
    return replace(m, **{f"u_{side}": None}, width_px=None, notes=(
        *m.notes, f"a pencil's image stands in front of its {side} side: that edge is the "
        "pencil's, axis from the other"))


FOOT_TOLERANCE = (3.0, 0.05)  # px, and a fraction of the image's height: the larger
# plus what a camera pitched this much off level (a bench's mount) moves every row by
PITCH_ALLOWANCE_DEG = 3.0


def _check_stands_on_board(cam: Camera, m: ImageMeasurement, view: CaptureRecord) -> None:
    """An upright object on the board, seen by a level camera h cm high, has its foot
    h/H of its image height s below the principal row: v_foot = cy + s·h/H (for a mirror
    image too: a vertical mirror keeps heights).  A frame that is flipped, of another
    camera or of another scene breaks this."""
    if m.height_px is None or m.v_bottom is None:
        return
    height = (view.target_size[1] if m.kind == "target"
              else pencil_paint_height(view.beacons[0].height))
    expected = cam.cy + m.height_px * cam.height / height
    tol = (max(FOOT_TOLERANCE[0], FOOT_TOLERANCE[1] * m.height_px)
           + cam.fx * np.tan(np.radians(PITCH_ALLOWANCE_DEG)))
    if abs(m.v_bottom - expected) > tol:
        raise DetectionError(
            f"the {m.kind} image at column {m.u_axis:.0f} does not stand on the board as seen "
            f"from {cam.height:g} cm: its foot is at row {m.v_bottom:.1f}, its height puts it "
            f"at row {expected:.1f} (a flipped frame, or another camera's or scene's?)")


def _check_a_mirror_fits(det: Detection) -> None:
    """Each beacon's mirror image must imply a mirror (its image farther than the beacon
    stands) behind which the target's image leads to a point in front of it."""
    from solver.sltr import SolverError, solve_single

    for b, m in det.beacons:
        try:
            if det.target.d_total is not None:
                solve_single(det.observer, b.position, m.alpha_deg, beacon_d_total=m.d_total,
                             target_alpha_deg=det.target.alpha_deg,
                             target_d_total=det.target.d_total)
        except SolverError as exc:
            raise DetectionError(f"no mirror fits these images ({exc}): a frame of another "
                                 "scene, a mirrored frame, or a beacon not where it is "
                                 "believed?") from None


def _public(m: ImageMeasurement) -> dict:
    d = asdict(m)
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in d.items()}

# -------------------------------------------------------------------- drawing


def annotate(image: np.ndarray, detection: Detection) -> np.ndarray:
    """Draw the detections (boxes, axis columns, edges, α and d) on a copy of the frame;
    each label names its object (a beacon by its index) on a dark band, moved down
    where it would cover another label."""
    out = np.ascontiguousarray(image[..., ::-1].copy())  # OpenCV draws in BGR
    placed: list[tuple[int, int, int, int]] = []
    font, scale = cv2.FONT_HERSHEY_SIMPLEX, 0.5
    for m in [detection.target, *detection.images]:
        colour = (60, 60, 255) if m.kind == "target" else (
            (255, 160, 40) if m.source == "mirror" else (230, 230, 230))
        u0, v0, u1, v1 = m.bbox_px
        cv2.rectangle(out, (u0 - 2, v0 - 2), (u1 + 2, v1 + 2), colour, 1)
        if np.isfinite(m.u_axis):
            x = int(round(m.u_axis))
            cv2.line(out, (x, v0 - 12), (x, v1 + 12), colour, 1)
        for v in (m.v_top, m.v_bottom):
            if v is not None:
                y = int(round(v))
                cv2.line(out, (u0 - 8, y), (u1 + 8, y), (0, 255, 0), 1)
        name = m.kind if m.beacon_index is None else f"beacon {m.beacon_index}"
        d = "-" if m.d_total is None else f"{m.d_total:.2f} cm"
        label = f"{name} ({m.source}): a {m.alpha_deg:.3f} deg, d {d}"
        if m.clipped:
            label += f", clipped {m.clipped}"
        (w, h), base = cv2.getTextSize(label, font, scale, 1)
        x0, y0 = max(0, min(u0 - 40, out.shape[1] - w - 4)), max(h + 4, v0 - 10)
        while any(x0 < bx1 and bx0 < x0 + w + 4 and y0 - h - 3 < by1 and by0 < y0 + base + 2
                  for bx0, by0, bx1, by1 in placed):
            y0 += h + base + 4  # below the label it would cover
        box = (x0, y0 - h - 3, x0 + w + 4, y0 + base + 2)
        placed.append(box)
        cv2.rectangle(out, box[:2], box[2:], (20, 20, 20), -1)  # a dark band under the text
        cv2.putText(out, label, (x0 + 2, y0), font, scale, colour, 1, cv2.LINE_AA)
    return out[..., ::-1]


def frame_noise(linear: np.ndarray, box: list[int]) -> float:
    """The frame's relative noise, measured where it is flat: in the middle half of the
    target panel's image (mid-grey, square-on), the robust σ of neighbouring pixels'
    differences over √2, over the panel's level.  Render noise, sensor noise and JPEG's
    blocks all show there; NaN where the panel's image is too small to hold a sample."""
    u0, v0, u1, v1 = box
    du, dv = (u1 - u0) // 4, (v1 - v0) // 4
    core = np.asarray(linear[v0 + dv:v1 - dv, u0 + du:u1 - du], float).mean(axis=-1)
    if core.shape[0] < 2 or core.shape[1] < 3:
        return float("nan")
    diff = np.diff(core, axis=1).ravel()
    sd = 1.4826 * float(np.median(np.abs(diff - np.median(diff)))) / math.sqrt(2.0)
    level = float(np.median(core))
    return sd / level if level > 0 else float("nan")


def image_contrast(m: ImageMeasurement) -> float:
    """The relative contrast of an image's edges: the smallest, over its measured sides,
    of |inside − outside| over the larger of the two (mean linear radiance)."""
    sides = [x for x in (m.outside.left, m.outside.right, m.outside.top, m.outside.bottom)
             if np.isfinite(x)]
    if not sides or not np.isfinite(m.inside):
        return float("nan")
    return min(abs(m.inside - x) / max(m.inside, x, 1e-9) for x in sides)


