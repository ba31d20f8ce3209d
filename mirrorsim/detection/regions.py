"""Segmentation: the image regions of the target (a neutral mid-grey panel) and of the
pencils (the only strongly saturated yellow), as pixel boxes for
:func:`mirrorsim.detection.edges.measure_region` to measure (the model in
:mod:`mirrorsim.detection.detector`'s docstring, *Finding*).  Pixels only, OpenCV.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from mirrorsim.detection.edges import cut_by_frame

FRAME_OPEN_PX = 13  # wider than the mirror frame's bars at the distances of our scenes
# where no panel is found so, the openings tried next: a long lens near the mirror makes
# its bars wider (14 px on a 1920 px frame of 46° with the mirror 80 cm away, which
# joined a panel whose image reached the bar: the panel was not found); a wider opening
# is tried only where the narrower one found nothing, so no panel found today moves
WIDER_OPEN_PX = (27, 55)
# how far (in 0–255 sRGB, each channel) a pixel's colour may lie from the panel's own
# and still belong to it when the panel's region is grown again
SAME_GREY = 22.0
MERGED_MIN_AREA = 2000  # px: a grey region this large that is no panel may hold one


def _components(mask: np.ndarray, min_area: int):
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), 8)
    out = []
    for k in range(1, n):
        x, y, w, h, area = stats[k]
        if area >= min_area:
            out.append((k, int(x), int(y), int(w), int(h), int(area)))
    return labels, out


def _channel_max(img: np.ndarray) -> np.ndarray:
    """The largest of an (H, W, 3) image's channels at each pixel: the same values as
    ``img.max(axis=2)``, several times faster (a reduction over a last axis of 3 is
    numpy's slow case)."""
    return np.maximum(np.maximum(img[..., 0], img[..., 1]), img[..., 2])


def _channel_min(img: np.ndarray) -> np.ndarray:
    """The smallest of an (H, W, 3) image's channels at each pixel."""
    return np.minimum(np.minimum(img[..., 0], img[..., 1]), img[..., 2])


def within(img: np.ndarray, centre: np.ndarray, reach: float) -> np.ndarray:
    """uint8 mask, nonzero where every channel of an (H, W, 3) image lies less than
    ``reach`` from ``centre`` (RGB): ``max_c |img - centre| < reach`` in float32, the
    same arithmetic done by OpenCV, five times faster than numpy's."""
    img = np.asarray(img, np.float32)  # OpenCV rounds a scalar to an integer image's type
    below = float(np.nextafter(np.float32(reach), np.float32(0)))  # < reach, as ≤
    centre = np.asarray(centre, np.float32)
    return cv2.inRange(cv2.absdiff(img, (*(float(c) for c in centre), 0.0)),
                       (0.0, 0.0, 0.0), (below, below, below))


# a pencil's image in front of the panel's splits it in two: its pixels count as the
# panel's where the panel's grey lies within this many px on both sides of it in its row
PENCIL_FILL_PX = 25
# a raised pencil's post (0.3 cm across) is 3-8 px wide at 60-100 cm in a full-size frame
POST_FILL_PX = 10
POST_DARK = 60  # 8-bit: a pencil's post reads 20-45 across a lit panel (sRGB of 0.06)


def find_target(img: np.ndarray, ratio: float, *, posts: bool = False,
                paint: np.ndarray | None = None) -> tuple[int, int, int, int] | None:
    """Bounding box (u0, v0, u1, v1) of the grey panel's image, or None.

    A pencil standing in front of the panel (its reflection or its direct view crossing
    the panel's image) splits the panel's region into two, each of which may pass for a
    panel; so the panel is looked for twice, as the grey pixels are and with the pencil
    pixels that lie between grey ones taken for the panel's, and of the two boxes the
    one whose width over height is nearer the panel's (``ratio``: seen square-on in the
    mirror, its image has the panel's proportions) is kept.  A pencil beside the panel,
    grey beyond it, would have widened the filled one.  ``posts`` (a 3-D scene's frame):
    a raised pencil's post, a dark line a few px wide, may cross the panel's image and
    split it (one of its shades is not neutral); its dark pixels between grey ones
    within POST_FILL_PX in their row are then taken for the panel's too.  ``paint``:
    :func:`pencil_mask` of ``img``, where the caller has it."""
    blur = cv2.GaussianBlur(img, (5, 5), 0)
    vmax, vmin = _channel_max(blur), _channel_min(blur)
    neutral = (vmax - vmin) < 0.12 * vmax + 6
    grey = neutral & (vmax > 20) & (vmax < 135)
    paint = pencil_mask(img) if paint is None else paint  # (the pencils' boxes too)
    inside = _between(paint, grey) | _cones_between(find_pencils(img, paint), grey)
    if posts:  # dark pixels (a pencil's post's shade) that are not the panel's grey
        dark = (~grey & (vmax < POST_DARK)).astype(np.uint8)
        inside |= _between(dark, grey, reach_px=POST_FILL_PX)
    for open_px in (FRAME_OPEN_PX, *WIDER_OPEN_PX):
        plain = _find_panel(blur, neutral, grey, np.zeros(grey.shape, bool), ratio, open_px)
        filled = _find_panel(blur, neutral, grey, inside, ratio, open_px) if inside.any() \
            else None
        found = [b for b in (plain, filled) if b is not None]
        if found:  # ranked as _rank ranks regions, then by shape
            return min(found, key=lambda b: (
                bool(cut_by_frame(b, img.shape[0])), _at_side(b, img.shape[1]),
                abs(math.log((b[2] - b[0] + 1) / (b[3] - b[1] + 1) / ratio))))
    return None


def _find_panel(blur: np.ndarray, neutral: np.ndarray, grey: np.ndarray, inside: np.ndarray,
                ratio: float, open_px: int = FRAME_OPEN_PX) -> tuple[int, int, int, int] | None:
    """:func:`find_target` on the mask ``grey`` with the pencil pixels ``inside`` added,
    opened by a disc ``open_px`` across (the mirror frame's bars taken off)."""
    mask = grey | inside
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (open_px, open_px))
    mask = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, kernel).astype(bool)
    labels, comps = _components(mask, 300)
    best = None
    for k, x, y, w, h, area in comps:
        whole = area / (w * h) >= 0.75 and 0.8 / ratio <= h / w <= 4.0
        if not whole and area < MERGED_MIN_AREA:
            continue
        # re-grow around the region's own colour: separates a differently grey neighbour,
        # also one that merged with the panel into a region no panel could be.  In a
        # window around the region (the whole frame only where what matters reaches the
        # window's edge: the same result, without rescanning the frame per region)
        box = (x, y, w, h)
        found = _regrow(blur, neutral, inside, labels, k, box, whole, ratio, kernel, max(w, h),
                        open_px)
        if found is None:
            found = _regrow(blur, neutral, inside, labels, k, box, whole, ratio, kernel, None,
                            open_px)
        for cand in found:
            if best is None or _rank(cand, blur.shape) > _rank(best, blur.shape):
                best = cand
    return None if best is None else best[:4]


def _rank(cand: tuple[int, int, int, int, int], shape: tuple[int, ...]
          ) -> tuple[bool, bool, int]:
    """A panel region's rank: one whose rows the frame leaves whole before one it cuts at
    the top or bottom (:func:`~mirrorsim.detection.edges.cut_by_frame`), which has no
    height to measure (a wall's grey cut by the frame's bottom, larger than the panel,
    had been taken for it), then one the frame's sides leave whole (the panel is seen in
    the mirror, whose frame the image holds: a blue-grey occluder near the lens, running
    off the frame's right side with 5.5 times the panel's area, had been taken for it:
    bench0047 of acceptance seed 61207022), then the larger."""
    return not cut_by_frame(cand[:4], shape[0]), not _at_side(cand[:4], shape[1]), cand[4]


def _at_side(box: tuple[int, int, int, int], width: int) -> bool:
    """Whether a region reaches the frame's first or last column."""
    return box[0] <= 0 or box[2] >= width - 1


def _regrow(blur, neutral, inside, labels, k, box, whole: bool, ratio: float, kernel,
            margin: int | None, open_px: int = FRAME_OPEN_PX
            ) -> list[tuple[int, int, int, int, int]] | None:
    """The panel-shaped regions of region ``k``'s own colour that belong to it, as
    (u0, v0, u1, v1, area), looked for within ``margin`` px of its box (None: the
    whole frame); None if one that matters comes near the window's edge, where the
    opening and the regions could differ from the whole frame's.  ``inside``: pencil
    pixels in front of grey ones, which belong to the panel they cross."""
    x, y, w, h = box
    H, W = labels.shape
    near = 2 * open_px  # the opening's reach, twice
    if margin is None:
        u0, v0, u1, v1 = 0, 0, W, H
    else:
        u0, v0 = max(0, x - margin - near), max(0, y - margin - near)
        u1, v1 = min(W, x + w + margin + near), min(H, y + h + margin + near)
    win = (slice(v0, v1), slice(u0, u1))
    mine = labels[win] == k
    own = mine & ~inside[win]  # its grey, the pencils in front of it apart
    med = np.median(blur[win][own if own.any() else mine], axis=0)
    similar = (within(blur[win], med, SAME_GREY) & neutral[win]) | inside[win]
    similar = cv2.morphologyEx(similar, cv2.MORPH_OPEN, kernel)
    lab2, comps2 = _components(similar, 300)
    # the region's own component: the one most of its pixels fall in (its centre may be
    # a hole, where a pencil's unpainted tip stands in front of the panel)
    held = lab2[mine]
    held = held[held > 0]
    seed = int(np.bincount(held).argmax()) if held.size else 0
    out = []
    for kk, x2, y2, w2, h2, area2 in comps2:
        if whole and kk != seed:
            continue
        if not whole and np.count_nonzero((lab2 == kk) & mine) < 0.5 * area2:
            continue
        inner = ((x2 < near and u0 > 0) or (y2 < near and v0 > 0)
                 or (x2 + w2 > (u1 - u0) - near and u1 < W)
                 or (y2 + h2 > (v1 - v0) - near and v1 < H))
        if inner:
            return None
        if area2 / (w2 * h2) < 0.75 or not 0.8 / ratio <= h2 / w2 <= 4.0:
            continue
        out.append((x2 + u0, y2 + v0, x2 + u0 + w2 - 1, y2 + v0 + h2 - 1, area2))
    return out


def pencil_mask(img: np.ndarray) -> np.ndarray:
    """uint8 mask of the painted (yellow, saturated) pixels of an 8-bit RGB image."""
    blur = cv2.GaussianBlur(img, (3, 3), 0)
    r, g, b = blur[..., 0], blur[..., 1], blur[..., 2]
    vmax, vmin = _channel_max(blur), _channel_min(blur)
    sat = (vmax - vmin) / np.maximum(vmax, 1.0)
    yellow = (r + g) / 2 - b
    mask = (sat > 0.55) & (yellow > 30) & (vmax > 40)
    return cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))


def _between(pencil: np.ndarray, grey: np.ndarray, reach_px: int = PENCIL_FILL_PX
             ) -> np.ndarray:
    """The pencil pixels that have ``grey`` pixels within ``reach_px`` on their left and
    on their right in their row (bool)."""
    if not pencil.any():
        return np.zeros(pencil.shape, bool)
    g = grey.astype(np.uint8)
    reach = reach_px + 1
    # a one-sided dilation: the kernel's anchor at its right end spreads each grey pixel
    # rightwards (a grey pixel on the left), at its left end leftwards
    row = np.ones((1, reach), np.uint8)
    left = cv2.dilate(g, row, anchor=(reach - 1, 0))
    right = cv2.dilate(g, row, anchor=(0, 0))
    between = ((pencil > 0) & (left > 0) & (right > 0)).astype(np.uint8)
    # and the blend of pencil and panel at either side (the blur's few px)
    return cv2.dilate(between, np.ones((1, 7), np.uint8)) > 0


# how far above a pencil's painted band its cone (bare wood and graphite: neither yellow nor
# grey) may reach, in the band's widths (the rendered pencils' cones: 1.2-2 widths)
CONE_WIDTHS = 3.0


def _cones_between(pencils: list[tuple[int, int, int, int]], grey: np.ndarray) -> np.ndarray:
    """The pixels of each pencil's cone (``pencils``: the bands' boxes,
    :func:`find_pencils`) that lie between ``grey`` ones in their row: a
    pencil in front of the panel hides it with its cone too, and the notch left in the
    panel's region took its fill below a whole panel's (bench0039 of the bench acceptance
    set, a 5 px pencil across a 44 px JPEG panel: 0.749 of its box, and no panel found)."""
    cone = np.zeros(grey.shape, np.uint8)
    for u0, v0, u1, _ in pencils:
        cone[max(0, v0 - int(CONE_WIDTHS * (u1 - u0 + 1))):v0, u0:u1 + 1] = 1
    return _between(cone & ~grey, grey)


def find_pencils(img: np.ndarray, mask: np.ndarray | None = None
                 ) -> list[tuple[int, int, int, int]]:
    """Bounding boxes of painted (yellow) pencil bands: upright regions at least 1.6
    times as tall as wide, their width less the pixel the blur adds across their sides
    (a 2 cm pencil's band, 1.95 times its width, was 9 × 6 px in a small frame's
    calibration render at 103 cm, and was missed at 2·0.8 of the box's width); a region
    that is two pencils touching split (:func:`_split_at_step`), each widened over its
    dark faces, and pieces of one pencil's paint made one (:func:`_merged_pieces`).
    ``mask``: :func:`pencil_mask` of ``img``, where the caller has it."""
    mask = pencil_mask(img) if mask is None else mask
    labels, comps = _components(mask, 30)
    boxes = [_with_dark_faces(img, b) for comp in comps for b in _split_at_step(labels, comp)
             if b[3] - b[1] + 1 >= 1.6 * (b[2] - b[0])]
    return _merged_pieces(boxes)


# a region's columns either side of a split must be this many, and their median top or
# foot rows this far apart (px, and as a fraction of its height)
SPLIT_MIN_COLS, SPLIT_STEP = 3, (3.0, 0.1)


def _split_at_step(labels: np.ndarray, comp: tuple) -> list[tuple[int, int, int, int]]:
    """A painted region's box, or two where it is two pencils' images side by side and
    touching: split where the columns either side lie nearest their own median top and
    foot rows, if most of each side's columns lie within SPLIT_STEP of those medians
    (not a ramp: a narrow pencil rolled 15° shifts its top and foot 3.7 px a column
    together), and one side's top and foot both lie higher than the other's by over
    SPLIT_STEP, over the two parts and over the SPLIT_MIN_COLS columns each side of the
    split alike (the farther pencil's, both below the camera's eye; a wide pencil rolled
    steps only its top or only its foot at a corner).  A bench's convex mirror put a
    pencil's reflection against its direct view, one region from the reflection's top
    to the direct view's foot, read at d_total 26 cm, nearer than the beacon (bench0017
    of acceptance seed 61207082)."""
    k, x, y, w, h, _ = comp
    sub = labels[y:y + h, x:x + w] == k
    cols = np.flatnonzero(sub.any(axis=0))
    if len(cols) < 2 * SPLIT_MIN_COLS:
        return [(x, y, x + w - 1, y + h - 1)]
    top = sub[:, cols].argmax(axis=0)
    foot = h - 1 - sub[::-1, cols].argmax(axis=0)
    step = max(SPLIT_STEP[0], SPLIT_STEP[1] * h)

    def spread(i: int) -> float:  # the two parts' rows about their own medians
        return sum(float(np.abs(r - np.median(r)).sum())
                   for r in (top[:i], top[i:], foot[:i], foot[i:]))

    at = min(range(SPLIT_MIN_COLS, len(cols) - SPLIT_MIN_COLS + 1), key=spread)
    whole = [(x, y, x + w - 1, y + h - 1)]
    parts = []
    for part in (slice(None, at), slice(at, None)):
        c, t, f = cols[part], top[part], foot[part]
        # a column where the two touch holds one's top and the other's foot: left out
        own = (np.abs(t - np.median(t)) <= step) & (np.abs(f - np.median(f)) <= step)
        if own.sum() < max(SPLIT_MIN_COLS, len(c) / 2):  # a ramp (a narrow pencil rolled)
            return whole
        parts.append((c[own], t[own], f[own]))
    (_, lt, lf), (_, rt, rf) = parts
    n = SPLIT_MIN_COLS
    steps = [float(np.median(r) - np.median(q)) for q, r in (
        (lt, rt), (lf, rf), (lt[-n:], rt[:n]), (lf[-n:], rf[:n]))]  # parts, then at the split
    if min(abs(d) for d in steps) <= step or not (all(d > 0 for d in steps)
                                                   or all(d < 0 for d in steps)):
        return whole
    return [(x + int(c.min()), y + int(t.min()), x + int(c.max()), y + int(f.max()))
            for c, t, f in parts]


# how far apart (rows) two pieces of one pencil's paint may lie, one above the other
PIECE_GAP_PX = 2


def _merged_pieces(boxes: list[tuple[int, int, int, int]]) -> list[tuple[int, int, int, int]]:
    """Pencil boxes with the pieces of one pencil's paint made one: two boxes whose
    columns overlap over at least half the narrower's width and whose rows overlap or
    lie within PIECE_GAP_PX are one pencil, split by shadow or JPEG's colour blur and
    the opening.
    A 6 × 12 px piece of a shadowed band, measured turned by 9.7°, took a beacon's place
    at d_total 265 cm for 90 (bench0051 of acceptance seed 61207052); a 13 px piece of
    a reflection showing the pencil's dark back, its lit flanks in three pieces, took it
    at 296 cm for 68 (bench0060 of seed 61207072).  Another pencil's band so close in
    columns and rows is mostly hidden behind this one's paint; one seen beside a nearer
    pencil's cone, just above its band, would be merged with it (not met so far)."""
    boxes = list(boxes)
    i = 0
    while i < len(boxes):
        j = next((j for j in range(i + 1, len(boxes)) if _one_pencil(boxes[i], boxes[j])), None)
        if j is None:
            i += 1
            continue
        a, b = boxes[i], boxes.pop(j)
        boxes[i] = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
        i = 0  # the union may now reach a box it did not
    return boxes


def _one_pencil(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    """Whether two pencil boxes are pieces of one (:func:`_merged_pieces`)."""
    across = min(a[2], b[2]) - max(a[0], b[0]) + 1
    narrower = min(a[2] - a[0], b[2] - b[0]) + 1
    gap = max(a[1], b[1]) - min(a[3], b[3]) - 1
    return 2 * across >= narrower and gap <= PIECE_GAP_PX


# a pencil's faces turned from the light (a reflection shows its back) keep the paint's
# blue near 0 but are too dark for the yellow test (seen at 8-bit (21-46, 9-33, 0-9)):
# blue under a quarter of the red, where a sandy board, a grey panel, the wood or a rim
# blurred into the background hold over a third
DARK_PAINT_BLUE = 0.25
DARK_PAINT_MAX = 100  # 8-bit: their brightest channel (lit paint, another pencil's: 150-220)


def _with_dark_faces(img: np.ndarray, box: tuple[int, int, int, int]
                     ) -> tuple[int, int, int, int]:
    """A pencil band's box widened over the columns beside it that are its paint's dark
    faces in most of its middle rows, by at most its width each way: its yellow region
    held its lit flank alone (bench0011 of acceptance seed 61207022: 5 of the band's 10
    px, its sides measured within it and the image dropped as partly hidden).  Not over
    lit paint (above DARK_PAINT_MAX): another pencil's image beside it."""
    u0, v0, u1, v1 = box
    rows = img[v0 + (v1 - v0) // 5: v1 - (v1 - v0) // 5 + 1]

    def dark(u: int) -> bool:
        if not 0 <= u < img.shape[1]:
            return False
        px = np.asarray(rows[:, u], np.float32)
        vmax, vmin = px.max(axis=1), px.min(axis=1)
        paint = (vmax - vmin > 0.55 * vmax) & (px[:, 2] < DARK_PAINT_BLUE * px[:, 0]) \
            & (vmax > 15) & (vmax <= DARK_PAINT_MAX)
        return bool(paint.mean() > 0.5)

    lo, hi, w = u0, u1, u1 - u0 + 1
    while lo > u0 - w and dark(lo - 1):
        lo -= 1
    while hi < u1 + w and dark(hi + 1):
        hi += 1
    return lo, v0, hi, v1
