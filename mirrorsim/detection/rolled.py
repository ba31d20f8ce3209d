"""Images that lean in the frame: a leaning mirror (a 3-D scene) leans each virtual
image by twice its lean, and seen at a slant that lean shows as a roll of the image in
the frame (4° and more at a 4° lean).  The edge measurement of
:mod:`mirrorsim.detection.edges` takes an image's edges across bands of rows or
columns, which holds for an upright image: on one rolled by a few degrees its top and
foot read 1–1.5 px outwards (a 150 px panel's height 1.6 % long, on a frame rendered at
a 3° lean).

So an image is measured where it stands upright: its roll is found on its own pixels
(the pencil's painted region's long axis, the panel's top and bottom boundaries, or its
sides where perspective slopes its top and bottom apart: :func:`image_roll`), the
frame's neighbourhood turned by it, the object found and measured there as an upright
one, and its foot and top taken back to the frame.  The measurement's height is then
the image's length along its axis, its axis column and foot row those of its foot and
top as they stand in the frame (what :func:`solver.sltr3d.measured3` predicts).  A
planar scene's image is measured so only where, as it stands, it gave no height or no
side (a bench's camera roll and mirror tilt: ``detector._measure``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np

from mirrorsim.detection.edges import measure_region
from mirrorsim.detection.image_measurement import ImageMeasurement
from mirrorsim.detection.regions import find_pencils, find_target, pencil_mask, within

# an image rolled by less than this (deg) is measured as it stands: turning the frame
# would only blur it (across a 200 px panel, 0.25° moves an edge 0.4 px end to end,
# symmetric about its middle; an upright mirror's images read within ±0.1°)
MIN_ROLL_DEG = 0.25
# how far (deg) a panel's top and foot may slope apart and still give its roll (beyond
# it perspective has sloped them, image_roll); its two sides must agree as closely
SLOPES_AGREE_DEG = 1.0
MARGIN_PX = 28  # around the object: the edges' windows and levels reach 8 px past it
ROLL_MARGIN_PX = 6  # around a panel's box, where its boundaries are sought for its roll


def image_roll(img: np.ndarray, box: tuple[int, int, int, int], kind: str, *,
               sides: bool = False) -> float:
    """The roll (deg) of the object's image in ``box`` of the 8-bit frame ``img``: the
    angle of its axis from the frame's vertical, positive with its top to the right.
    A pencil's from its painted region's long axis (its second moments), a panel's from
    the slopes of its top and bottom boundaries (robust line fits, which drop the
    columns a pencil in front of it covers); 0 where neither can be found.  With
    ``sides`` (a 3-D frame's panel), where its top and foot slope apart by over
    SLOPES_AGREE_DEG, from its sides' slopes: one side's where only one is found, both
    where they agree; else from its top and foot as without."""
    u0, v0, u1, v1 = box
    crop = np.asarray(img[v0:v1 + 1, u0:u1 + 1], np.float32)
    if kind == "beacon":
        ys, xs = np.nonzero(pencil_mask(crop))
        if len(xs) < 10:
            return 0.0
        c = np.cov(np.vstack([xs, ys]).astype(float))
        w, v = np.linalg.eigh(c)
        ax = v[:, np.argmax(w)]
        if ax[1] > 0:  # point it up the frame (−v)
            ax = -ax
        return math.degrees(math.atan2(ax[0], -ax[1]))
    grey, inner = _grey_mask(img, box)
    slopes = [s for s in (_boundary_slope(grey, inner, top=True),
                          _boundary_slope(grey, inner, top=False)) if s is not None]
    if sides and len(slopes) == 2 and not _agree(slopes):
        # the top and the foot slope apart: perspective, not a roll (a panel raised
        # above the camera's eye slopes both the same way, by different amounts: read
        # so, an upright glass's panel was turned by 3.9° and read 3 % tall, s3d0060 of
        # development seed 7002), and no turn makes both level.  A level camera keeps
        # upright edges upright: the roll is the sides' (columns per row, transposed
        # into _boundary_slope's rows; the frame's v runs down, so a top to the right
        # slopes them negative)
        u0, v0, u1, v1 = inner
        leans = [s for s in (_boundary_slope(grey.T, (v0, u0, v1, u1), top=True),
                             _boundary_slope(grey.T, (v0, u0, v1, u1), top=False))
                 if s is not None]
        if len(leans) == 1 or _agree(leans):
            return math.degrees(math.atan(-float(np.mean(leans))))
    return math.degrees(math.atan(float(np.mean(slopes)))) if slopes else 0.0


def _agree(slopes: list[float]) -> bool:
    """Whether two boundaries' slopes lie within SLOPES_AGREE_DEG of each other."""
    return len(slopes) == 2 and (abs(math.degrees(math.atan(slopes[0]) - math.atan(slopes[1])))
                                 <= SLOPES_AGREE_DEG)


def _grey_mask(img: np.ndarray, box: tuple[int, int, int, int]
               ) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """The panel's pixels in its box grown by ROLL_MARGIN_PX: near the median colour of
    the box's middle (the panel's grey), a little blurred against noise; and the box
    within that crop."""
    u0, v0, u1, v1 = box
    h, w = img.shape[:2]
    a0, b0 = max(0, u0 - ROLL_MARGIN_PX), max(0, v0 - ROLL_MARGIN_PX)
    a1, b1 = min(w - 1, u1 + ROLL_MARGIN_PX), min(h - 1, v1 + ROLL_MARGIN_PX)
    blur = cv2.GaussianBlur(np.asarray(img[b0:b1 + 1, a0:a1 + 1], np.float32), (5, 5), 0)
    inner = (u0 - a0, v0 - b0, u1 - a0, v1 - b0)
    bw, bh = inner[2] - inner[0] + 1, inner[3] - inner[1] + 1
    core = blur[inner[1] + bh // 3: inner[1] + 2 * bh // 3 + 1,
                inner[0] + bw // 3: inner[0] + 2 * bw // 3 + 1].reshape(-1, 3)
    ref = np.median(core, axis=0)
    return within(blur, ref, 0.12 * float(ref.max()) + 8) > 0, inner


def _boundary_slope(mask: np.ndarray, inner: tuple[int, int, int, int], *, top: bool
                    ) -> float | None:
    """The slope (rows per column) of the panel's top or bottom boundary over the middle
    60 % of the box ``inner``'s columns: a line fitted to each column's first (last)
    masked row, columns more than 1.5 px off it dropped twice.  A column masked at the
    crop's edge has no boundary there: something as bright as the panel lies beyond it
    (a wall in the glass, in a JPEG of a bench: taken for a flat top, it halved a 2°
    roll, bench0032 of acceptance seed 61207072)."""
    u0, _, u1, _ = inner
    first = u0 + int(0.2 * (u1 - u0))
    cols = np.arange(first, max(first + 1, u0 + int(0.8 * (u1 - u0))))
    edge = 0 if top else mask.shape[0] - 1
    us, vs = [], []
    for c in cols:
        rows = np.flatnonzero(mask[:, c])
        if len(rows) and (row := rows[0] if top else rows[-1]) != edge:
            us.append(c)
            vs.append(row)
    if len(us) < 6:
        return None
    from scipy.stats import siegelslopes

    u, v = np.asarray(us, float), np.asarray(vs, float)
    # repeated medians first (half the columns may be a pencil's or a post's in front of
    # the panel), then least squares on the columns within 1.5 px of that line
    b, a = siegelslopes(v, u)
    keep = np.abs(v - (a + b * u)) <= 1.5
    if keep.sum() < 6:
        return None
    b, a = np.polyfit(u[keep], v[keep], 1)
    return float(b)


def measure_rolled(linear: np.ndarray, img: np.ndarray, box: tuple[int, int, int, int],
                   *, kind: str, subsampled: bool = False, target_ratio: float | None = None,
                   cone_ratio: float | None = None, raised: bool = True,
                   roll: float | None = None) -> ImageMeasurement:
    """:func:`~mirrorsim.detection.edges.measure_region` of an image that may be rolled:
    measured upright in its neighbourhood turned by ``roll`` (deg; by default
    :func:`image_roll`'s), its foot and top
    taken back to the frame (see the module's text).  ``linear``: the frame's linear
    radiance; ``img``: its 8-bit values (float), where the regions are found (and a
    JPEG's pencil foot measured); ``target_ratio``: the panel's width over height;
    ``cone_ratio``: a pencil's cone over its band; ``raised``: a 3-D scene's frame (see
    ``measure_region``; a bench's camera roll and mirror tilt roll a planar scene's
    images too, by up to 5° within the bench model's tolerances)."""
    roll = image_roll(img, box, kind, sides=raised) if roll is None else roll
    if abs(roll) < MIN_ROLL_DEG:
        return measure_region(linear, box, kind, subsampled=subsampled, stored=img, raised=raised,
                              cone_ratio=cone_ratio)
    u0, v0, u1, v1 = box
    h, w = linear.shape[:2]
    a0, b0 = max(0, u0 - MARGIN_PX), max(0, v0 - MARGIN_PX)
    a1, b1 = min(w, u1 + MARGIN_PX + 1), min(h, v1 + MARGIN_PX + 1)
    centre = ((u0 + u1) / 2 - a0, (v0 + v1) / 2 - b0)
    # turn the neighbourhood so the image stands upright (OpenCV: +angle counter-clockwise)
    M = cv2.getRotationMatrix2D(centre, roll, 1.0)
    size = (a1 - a0, b1 - b0)

    def turned(a: np.ndarray) -> np.ndarray:
        return cv2.warpAffine(np.ascontiguousarray(a[b0:b1, a0:a1], np.float32), M, size,
                              flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)

    lin_r, img_r = turned(linear), np.clip(turned(img), 0.0, 255.0)
    found = (find_pencils(img_r) if kind == "beacon"
             else [b for b in [find_target(img_r, target_ratio, posts=raised)] if b is not None])
    if not found:
        return measure_region(linear, box, kind, subsampled=subsampled, stored=img, raised=raised,
                              cone_ratio=cone_ratio)
    near = min(found, key=lambda b: math.hypot((b[0] + b[2]) / 2 - centre[0],
                                               (b[1] + b[3]) / 2 - centre[1]))
    m = measure_region(lin_r, near, kind, subsampled=subsampled, stored=img_r, raised=raised,
                       cone_ratio=cone_ratio)
    return _back(m, M, (a0, b0), roll)


def _back(m: ImageMeasurement, M: np.ndarray, offset: tuple[int, int], roll: float
          ) -> ImageMeasurement:
    """A measurement made in the turned neighbourhood, in the frame's coordinates: its
    foot and top, on its axis, taken back, and each side at mid-height; its height and
    width stay lengths along and across its axis.  An edge not found stays None (the
    axis then on the region's middle column, as the pixel geometry takes it)."""
    inv = cv2.invertAffineTransform(M)

    def frame(u: float, v: float) -> tuple[float, float]:
        x, y = inv @ np.array([u, v, 1.0])
        return float(x + offset[0]), float(y + offset[1])

    u0, v0, u1, v1 = m.bbox_px
    axis = ((m.u_left + m.u_right) / 2 if m.u_left is not None and m.u_right is not None
            else (u0 + u1) / 2)
    mid_row = ((m.v_top + m.v_bottom) / 2 if m.v_top is not None and m.v_bottom is not None
               else (v0 + v1) / 2)
    top = None if m.v_top is None else frame(axis, m.v_top)
    foot = None if m.v_bottom is None else frame(axis, m.v_bottom)
    left = None if m.u_left is None else frame(m.u_left, mid_row)[0]
    right = None if m.u_right is None else frame(m.u_right, mid_row)[0]
    if left is not None and right is not None and top is not None and foot is not None:
        # the sides at the foot's and the top's mid-point: the bearing of the image's
        # mid-height (what solver.sltr3d.measured3 predicts)
        mid = (foot[0] + top[0]) / 2
        left, right = mid - m.width_px / 2, mid + m.width_px / 2
    corners = [frame(u, v) for u in (u0, u1) for v in (v0, v1)]
    xs, ys = [c[0] for c in corners], [c[1] for c in corners]
    return replace(m, u_axis=frame(axis, mid_row)[0],
                   v_top=None if top is None else top[1],
                   v_bottom=None if foot is None else foot[1],
                   u_left=left, u_right=right,
                   bbox_px=[int(min(xs)), int(min(ys)), int(max(xs)), int(max(ys))],
                   notes=(*m.notes, f"measured turned upright by its roll of {roll:+.2f}°"))
