"""Sub-pixel measurement of an object's image: its upright axis and vertical extent.

Pure numpy.  An edge is located by the *area* method: with the inside and outside
colours taken a few pixels either side, each pixel's coverage
c = ((x − out)·(in − out))/|in − out|² is summed over a window spanning the edge; for a
box-filtered render (area-weighted pixels) this is exact up to noise.  Bands give
independent estimates; their median resists partial occlusion.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from mirrorsim.camera.sensor import LINEAR_OF_CODE, lookup_codes, to_srgb8
from mirrorsim.detection.image_measurement import ImageMeasurement, Surround

# ---------------------------------------------------------------- edge measurement


def _edge_by_area(profile: np.ndarray, start: int, inside: np.ndarray, outside: np.ndarray,
                  inside_first: bool) -> float | None:
    """Sub-pixel edge position in a 1-D colour profile (rows of ``profile``: positions
    start, start+1, …) by summing pixel coverages; ``None`` if there is no contrast.
    ``inside`` and ``outside``: one colour each, or one per row of ``profile``."""
    d = inside - outside
    dd = np.sum(d * d, axis=-1)
    if float(np.mean(dd)) < 5.0**2:  # a 0–255 scale (linear, or a JPEG's stored values)
        return None
    # not clipped to [0, 1]: clipping noise on the flat parts would bias the sum inwards
    c = np.sum((profile - outside) * d, axis=-1) / dd
    if inside_first:
        return start - 0.5 + float(c.sum())
    return start - 0.5 + float((1.0 - c).sum())


def _level(rows: np.ndarray, offsets: np.ndarray, at: np.ndarray, slope: bool) -> np.ndarray:
    """A side's colour at the window's rows ``at`` (offsets from the edge's pixel) from
    its rows at ``offsets``: their median, or (``slope``) their straight-line fit."""
    if not slope or np.unique(offsets).size < 2:  # a line needs two offsets (a window
        # cut short at the frame's edge leaves one): the median there
        return np.median(rows, axis=0)
    coef = np.polyfit(offsets, rows, 1)  # (2, channels)
    return coef[0] * at[:, None] + coef[1]


SLOPE_ROWS = 8  # pixels each side for a sloped level: a longer line, less noise


def _local_edge(img: np.ndarray, band, axis: int, guess: float, inside_first: bool,
                reach: int = 6, half: int = 1, near: bool = False, chroma: bool = False,
                slope: bool = False):
    """An edge near ``guess`` in the mean profile of ``band`` (the columns, or rows,
    across it): coverages of the 2·half + 1 pixels about it, against the median colours
    of the next 4 pixels either side (inside: no further than ``reach``).  Local levels
    keep a shadow or a neighbour a few pixels away (a contact shadow at a foot, another
    object beside a thin pencil) out of it; medians drop the pegboard's holes.

    ``near``: for an outside that changes towards the edge.  The board in an object's
    contact shadow brightens over the first pixels away from its foot, so an outside
    level taken 2–5 px away counts the darker pixels next to the edge as partly inside
    (the foot measured 0.3–0.6 px low on full-size frames); beside a pencil the board
    brightens or darkens towards it.  Here the level is the first pixel past the edge's
    own, and the window ends at the edge's pixel.

    ``chroma``: only the colour across the outside's counts (see :func:`measure_region`).
    ``slope``: each side's level is its straight-line fit over the next SLOPE_ROWS pixels
    (not 4), carried to each pixel of the window (a side that brightens or darkens
    towards the edge, such as a pencil's paint in its contact shadow, or its wood cone
    below its first facets);
    the line is fitted to the mean profile, so a hole still moves it.

    Returns (edge or None, outside colour).
    """
    n = img.shape[axis]
    c = int(round(guess))

    def line(i: int) -> np.ndarray:
        i = min(max(i, 0), n - 1)
        return (img[i, band] if axis == 0 else img[band, i]).mean(axis=0)

    rows = SLOPE_ROWS if slope else 4
    k_out = range(half + 1, half + 1 + rows)
    k_in = range(half + 1, max(half + 2, min(half + 1 + rows, reach)))
    at = np.arange(-half, half + 1, dtype=float)
    k_b = np.array(k_in if inside_first else k_out, float)
    k_a = np.array(k_out if inside_first else k_in, float)
    rows_b = np.array([line(c - int(k)) for k in k_b])
    rows_a = np.array([line(c + int(k)) for k in k_a])
    before, after = _level(rows_b, -k_b, at, slope), _level(rows_a, k_a, at, slope)
    inside, outside = (before, after) if inside_first else (after, before)
    flat = _across(np.median(rows_a if inside_first else rows_b, axis=0)) if chroma \
        else (lambda x: x)
    if near:
        # the outside changes towards the edge (a contact shadow on the board): its level
        # is the first pixel past the edge's, and the window stops at the edge's pixel
        step = 1 if inside_first else -1
        level = line(c + step)
        lo = c - half if inside_first else c
        window = np.array([line(i) for i in range(lo, lo + half + 1)])
        return (_edge_by_area(flat(window), lo, flat(inside), flat(level), inside_first),
                _mean_level(outside))
    window = np.array([line(i) for i in range(c - half, c + half + 1)])
    if chroma:
        return _edge_by_area(flat(window), c - half, flat(inside),
                             np.zeros(window.shape[-1], window.dtype), inside_first), \
            _mean_level(outside)
    return _edge_by_area(window, c - half, inside, outside, inside_first), _mean_level(outside)


def _across(outside: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """Projection onto the colours across ``outside``'s (its median over the rows: holes
    drop out): the outside's shading (a contact shadow, a hole, a facet turned from the
    light) scales its colour and so drops out."""
    o = outside / max(float(np.linalg.norm(outside)), 1e-9)
    return lambda x: x - (x @ o)[..., None] * o


def _mean_level(level: np.ndarray) -> np.ndarray:
    """One colour for a side's level (one per window row with ``slope``)."""
    return np.atleast_2d(level).mean(axis=0)


def _median_edges(imgs, lo, hi, cross_lo, cross_hi, axis, band_px=3,
                  chroma=(False, False), slope=(False, False), near=(False, False),
                  max_off: float | None = None, drop_off: float | None = None,
                  half: tuple[int, int] = (1, 1)):
    """Edges at both ends of an object spanning [lo, hi] along ``axis`` (0: top and
    bottom, 1: left and right), robust and precise; ``imgs`` and ``chroma``: the image
    each end is measured in, and whether on its colour across the outside's; ``slope``:
    whether its levels are straight-line fits; ``near``: whether its outside level is the
    first pixel past it (see :func:`_local_edge`).

    Bands of ``band_px`` across the object's middle 60 % each give an edge near the
    region's boundary (±2 px); bands more than 1 px from their median (partly occluded
    ones) are dropped; the final edge is measured on the mean profile of the rest (with
    ``near``: on each of them, and averaged).  ``max_off``: bands whose edge lies farther
    than this (px) from the region's boundary are dropped too, and an end where fewer
    than half the bands remain is not measured (None): the region's boundary is then not
    the object's (see :func:`measure_region`).  ``drop_off``: such bands are dropped
    without that rule (where many bands find no contrast at all, as on a pencil's side).
    ``half``: each end's final window, 2·half + 1 px about the edge.
    Returns (edge_lo, edge_hi, outside_lo, outside_hi).
    """
    bands = _bands(cross_lo, cross_hi, band_px)
    reach = max(2, (hi - lo) // 2)
    final, outs = [], []
    for end, guess in ((0, lo), (1, hi)):
        img, flat = imgs[end], chroma[end]
        coarse = [_local_edge(img, band, axis, guess, end == 1, reach, half=2, chroma=flat)
                  for band in bands]
        off = max_off if max_off is not None else drop_off
        if off is not None:
            boundary = guess + (0.5 if end == 1 else -0.5)
            coarse = [(e if e is not None and abs(e - boundary) <= off else None, o)
                      for e, o in coarse]
        vals = [e for e, _ in coarse if e is not None]
        if not vals or (max_off is not None and len(vals) < 0.5 * len(bands)):
            final.append(None)
            outs.append(np.median([o for _, o in coarse], axis=0))
            continue
        m = float(np.median(vals))
        kept = [(band, e) for band, (e, _) in zip(bands, coarse, strict=True)
                if e is not None and abs(e - m) < 1.0]
        if near[end]:
            # the level is the first pixel past the edge: per band, at the band's own
            # position (in perspective a foot slants by up to a pixel across the object,
            # and on their mean profile the next row is partly inside)
            per = [_local_edge(img, band, axis, e0, end == 1, reach, near=True, chroma=flat)
                   for band, e0 in (kept or [(bd, m) for bd in bands])]
            got = [e for e, _ in per if e is not None]
            final.append(float(np.mean(got)) if got else None)
            outs.append(np.mean([o for _, o in per], axis=0))
            continue
        keep = np.concatenate([band for band, _ in kept]) if kept else np.concatenate(bands)
        # round(m) is the pixel the edge crosses: the window is centred on it
        e, out = _local_edge(img, keep, axis, m, end == 1, reach, half=half[end],
                             chroma=flat, slope=slope[end])
        final.append(e)
        outs.append(out)
    return final[0], final[1], outs[0], outs[1]


def _bands(cross_lo: int, cross_hi: int, band_px: int) -> list[np.ndarray]:
    """Bands of ``band_px`` rows (or columns) across the middle 60 % of [cross_lo,
    cross_hi]."""
    span = cross_hi - cross_lo + 1
    a = cross_lo + int(0.2 * span)
    b = max(a + 1, cross_hi - int(0.2 * span) + 1)
    return [np.arange(s, min(s + band_px, b)) for s in range(a, b, band_px)]


# the note of a JPEG pencil whose sides the blue channel lost and the colour measured
# (its one side may then stand against what hides part of it: image_geometry checks)
SIDES_ON_COLOUR = "sides on the image's colour: JPEG's smeared blue lost both"

# the note of a target whose foot had no colour contrast with the board (a panel in
# shadow) and was measured on the image's colour
FOOT_ON_COLOUR = "foot on the image's colour: no colour contrast with the board"

# the note of a raised panel whose foot, against something as neutral as itself, was
# measured on the image's colour
FOOT_AGAINST_ROOM = ("foot on the image's colour: against something as neutral as the "
                     "panel (a raised panel before the room's baseboard)")

# how far a side edge may lie from its region's boundary (px): good images are within
# 1.1 px (198 random scenes), a side measured on the mirror frame 8-17 px
SIDE_MAX_OFF_PX = 2.5


def to_linear(srgb: np.ndarray) -> np.ndarray:
    """8-bit sRGB values → linear radiance on the same 0–255 scale.

    A box-filtered pixel is the area-weighted mean of *linear* radiance; coverages
    measured on the gamma-encoded values would be biased by the curve.
    """
    return lookup_codes(srgb, _LINEAR_LUT)


_LINEAR_LUT = (255.0 * LINEAR_OF_CODE).astype(np.float32)


def measure_region(img: np.ndarray, box: tuple[int, int, int, int], kind: str,
                   *, subsampled: bool = False, stored: np.ndarray | None = None,
                   raised: bool = False) -> ImageMeasurement:
    """Sub-pixel edges of an object's image in ``box``: top and bottom, left and right,
    with the radiance just outside each (pixels only: :mod:`mirrorsim.detection.detector` turns them
    into a bearing and a distance with the camera's geometry).

    ``img`` holds linear RGB radiance (see :func:`to_linear`).  The target's top and
    sides are measured on its colour against the outside's (the sides with sloped
    levels: the glass beside the panel brightens towards it).  A pencil's
    (``kind="beacon"``) sides and top on the blue channel: the paint's blue is ~0 on lit
    and shadowed faces alike, so the hexagon's shading does not disturb the coverages;
    its sides against the first pixel past each edge.  Both feet on the colour across
    the board's: the board's contact shadow and the pegboard's dark holes in front of
    the foot only scale the board's colour, and drop out (in the blue channel a hole is
    as dark as the paint, and the pencil's foot moved with the holes in front of it).

    ``subsampled``: the frame stored its colour at half resolution (a JPEG's 4:2:0
    chroma), which smears the colour across an edge over 2–4 px and moves an edge
    measured on linear colour by up to 2.5 px (``benchmarks/jpeg_edges.py``).  The
    target's edges and the pencil's top are then measured on the image's colour, which
    JPEG keeps at full resolution in its luma.  The pencil's foot stays on the colour
    across the board's, but of the 8-bit values as stored (``stored``; from ``img`` if
    not given), over a 5-px window: JPEG averages and interpolates chroma in those
    values, which moves chroma between neighbouring pixels without changing its sum over
    the window, so the area method still finds the edge.  On 12 rendered scenes at
    quality 90 the foot measured so lies −0.15 ± 0.20 px from the geometry (on the image's
    colour, where the contact shadow and holes count, +0.26 ± 0.35 px); the −0.15 px is
    coverage summed on gamma-encoded values, and a lossless frame measured so (the
    calibration's reference) reads −0.15 ± 0.06 px, so it nearly cancels.

    ``raised`` (a 3-D scene's frame): the panel may stand off the board, its foot seen
    against the room (its pale baseboard is as neutral as the panel: across the
    outside's colour the two are one, and the foot read 2.5 px low); the foot is then
    measured on the image's colour too, and taken so where the two differ by a pixel.
    """
    u0, v0, u1, v1 = box
    if kind == "beacon":
        e = _pencil_edges(img, box, subsampled=subsampled, stored=stored)
    else:
        e = _panel_edges(img, box, on_chroma=not subsampled, raised=raised)
    top, bottom, left, right = e.top, e.bottom, e.left, e.right
    core = img[v0 + (v1 - v0) // 4: v1 - (v1 - v0) // 4 + 1,
               u0 + (u1 - u0) // 4: u1 - (u1 - u0) // 4 + 1]
    m = ImageMeasurement(
        kind=kind, source="mirror", bbox_px=[u0, v0, u1, v1], u_axis=float("nan"),
        v_top=top, v_bottom=bottom,
        height_px=None if top is None or bottom is None else bottom - top,
        width_px=None if left is None or right is None else right - left,
        u_left=left, u_right=right,
        outside=Surround(*(float(np.mean(o)) for o in (e.out_left, e.out_right, e.out_top,
                                                       e.out_bottom))),
        inside=float(np.median(core.reshape(-1, img.shape[-1]).mean(axis=1))),
        notes=e.notes)
    if left is not None and right is not None:
        m = replace(m, u_axis=(left + right) / 2)
    if top is None or bottom is None:
        m = replace(m, clipped="top", notes=(*m.notes, "no contrast at the top or bottom "
                                             "edge: height not measured"))
    return m

class _Edges(NamedTuple):
    """An image's four edges (px; None where not found), the levels just outside each,
    and what was measured otherwise than usual."""

    top: float | None
    bottom: float | None
    left: float | None
    right: float | None
    out_top: np.ndarray
    out_bottom: np.ndarray
    out_left: np.ndarray
    out_right: np.ndarray
    notes: tuple[str, ...]


def _pencil_edges(img: np.ndarray, box: tuple[int, int, int, int], *, subsampled: bool,
                  stored: np.ndarray | None) -> _Edges:
    """A pencil's edges (:func:`measure_region`): its sides and top on the blue channel,
    its foot on the colour across the board's."""
    u0, v0, u1, v1 = box
    sides_note: tuple[str, ...] = ()
    blue = np.ascontiguousarray(img[..., 2:3])
    foot_img = img
    if subsampled:
        foot_img = np.asarray(stored if stored is not None else to_srgb8(img / 255.0),
                              np.float32)
    top, bottom, out_top, out_bottom = _median_edges((img if subsampled else blue, foot_img),
                                                     v0, v1, u0, u1, axis=0,
                                                     chroma=(False, True),
                                                     slope=(True, True),
                                                     half=(1, 2 if subsampled else 1))
    if subsampled:  # the board's level below the foot (a mean of stored values) as
        # linear radiance like the rest: the radiance of that value, within a code's
        # step of the mean radiance
        out_bottom = np.interp(out_bottom, np.arange(256), _LINEAR_LUT)
    # a pencil 3 px from the frame's bar: the bar is the coarse pass's outside, the
    # board between reads as coverage and a side lands on the other (14 px in)
    left, right, out_left, out_right = _median_edges((blue, blue), u0, u1, v0, v1, axis=1,
                                                     near=(True, True),
                                                     drop_off=SIDE_MAX_OFF_PX)
    if subsampled and left is None and right is None:
        # JPEG smears the blue channel (mostly chroma) over 2-3 px: a pencil pressed
        # against the mirror's frame on one side and 2 px from a wall on the other
        # had neither side in it (2 of 40 planned benches), and was dropped.  The
        # image's colour keeps its edges at full resolution in the luma
        left, right, out_left, out_right = _median_edges((img, img), u0, u1, v0, v1,
                                                         axis=1, near=(True, True),
                                                         drop_off=SIDE_MAX_OFF_PX)
        # a side against a grey wall has little contrast in the colour either, and
        # can land off the (yellow) region: then the axis comes from the other side
        left = left if left is not None and abs(left - (u0 - 0.5)) <= SIDE_MAX_OFF_PX else None
        right = right if right is not None and abs(right - (u1 + 0.5)) <= SIDE_MAX_OFF_PX \
            else None
        sides_note = (SIDES_ON_COLOUR,)
    return _Edges(top, bottom, left, right, out_top, out_bottom, out_left, out_right,
                  sides_note)


def _panel_edges(img: np.ndarray, box: tuple[int, int, int, int], *, on_chroma: bool,
                 raised: bool = False) -> _Edges:
    """The target panel's edges (:func:`measure_region`): on its colour against the
    outside's, the sides with sloped levels."""
    u0, v0, u1, v1 = box
    sides_note: tuple[str, ...] = ()
    top, bottom, out_top, out_bottom = _median_edges((img, img), v0, v1, u0, u1, axis=0,
                                                     chroma=(False, on_chroma),
                                                     near=(False, True))
    if raised and on_chroma and bottom is not None:
        # a raised panel's foot may stand against the room's pale baseboard, as neutral
        # as the panel: across the outside's colour the two read as one and the foot
        # lands on the baseboard's far side (2.5 px low).  On the image's colour it is
        # found; where the two disagree by more than a pixel (a foot on the board reads
        # 0.3-0.6 px apart, its contact shadow counted), the image's colour is taken
        _, plain, _, out_plain = _median_edges((img, img), v0, v1, u0, u1, axis=0,
                                               near=(False, True))
        if plain is not None and abs(plain - bottom) > 1.0:
            bottom, out_bottom, sides_note = plain, out_plain, (FOOT_AGAINST_ROOM,)
    if bottom is None and on_chroma:
        # a panel in shadow is a dark grey with almost no colour across the board's
        # (a drawn scene's lost its height, 1 of 24): its foot on the image's colour,
        # where the board's contact shadow counts (as on a JPEG frame)
        _, bottom, _, out_bottom = _median_edges((img, img), v0, v1, u0, u1, axis=0,
                                                 near=(False, True))
        if bottom is not None:
            sides_note = (FOOT_ON_COLOUR,)
    # a side 2-3 px from the mirror frame's inner edge leaves a bright strip of glass
    # between them: the coarse pass's outside level then falls on the dark frame bar,
    # the strip reads as coverage far above 1 and the edge is pushed 9-13 px out.  The
    # region (found on the panel's own colour) is right; a side far from it is dropped
    # and the axis taken from the other side (image_geometry.target_geometry)
    left, right, out_left, out_right = _median_edges((img, img), u0, u1, v0, v1, axis=1,
                                                     slope=(True, True),
                                                     max_off=SIDE_MAX_OFF_PX)
    return _Edges(top, bottom, left, right, out_top, out_bottom, out_left, out_right,
                  sides_note)
