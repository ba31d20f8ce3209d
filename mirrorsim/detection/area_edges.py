"""Sub-pixel edges by the *area* method, in numpy.

With the inside and outside colours taken a few pixels either side, each pixel's
coverage c = ((x − out)·(in − out))/|in − out|² is summed over a window spanning the
edge; for a box-filtered render (area-weighted pixels) this is exact up to noise.  Bands
across the object give independent estimates; their median resists partial occlusion.
:mod:`mirrorsim.detection.edges` measures an object's image with these.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


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
                reach: int = 6, half: int = 1, near: bool = False, chroma: bool | str = False,
                slope: bool = False, out_reach: int | None = None):
    """An edge near ``guess`` in the mean profile of ``band`` (the columns, or rows,
    across it): coverages of the 2·half + 1 pixels about it, against the median colours
    of the next 4 pixels either side (inside: no further than ``reach``).  Local levels
    keep a shadow or a neighbour a few pixels away out of it; medians drop the holes.

    ``near``: for an outside that changes towards the edge (the board in a foot's contact
    shadow, read 2–5 px away, put the foot 0.3–0.6 px low): the level is the first pixel
    past the edge's own, and the window ends at the edge's pixel.

    ``chroma``: only the colour across the outside's counts (``edges.measure_region``);
    ``"inside"``: across the inside's (a lit face of the same paint reads as inside).
    ``slope``: each side's level is its straight-line fit over the next SLOPE_ROWS pixels
    (not 4), carried to each pixel of the window (a side that brightens or darkens
    towards the edge: a pencil's paint in its contact shadow, its wood cone); the line
    is fitted to the mean profile, so a hole still moves it.  ``out_reach``: the
    outside's pixels no farther than this from the edge's (a small pencil's cone).  The
    outside's rows are cut at their first step towards the inside
    (:func:`_outside_to_first_step`); under 4 left, a median (a line through 2 or 3,
    carried into the window, could land on the inside's level).

    Returns (edge or None, outside colour).
    """
    c = int(round(guess))

    def line(i: int) -> np.ndarray:
        i = min(max(i, 0), img.shape[axis] - 1)
        return (img[i, band] if axis == 0 else img[band, i]).mean(axis=0)

    rows = SLOPE_ROWS if slope else 4
    last = half + rows if out_reach is None else max(half + 1, min(half + rows, out_reach))
    k_out = range(half + 1, last + 1)
    k_in = range(half + 1, max(half + 2, min(half + 1 + rows, reach)))
    at = np.arange(-half, half + 1, dtype=float)
    k_b = np.array(k_in if inside_first else k_out, float)
    k_a = np.array(k_out if inside_first else k_in, float)
    rows_a, k_a, rows_b, k_b = _outside_to_first_step(
        np.array([line(c + int(k)) for k in k_a]), k_a, np.array([line(c - int(k)) for k in k_b]),
        k_b, inside_first, keep_all=bool(chroma))
    slope_out = slope and len(k_a if inside_first else k_b) >= 4  # a line through the rest
    before = _level(rows_b, -k_b, at, slope if inside_first else slope_out)
    after = _level(rows_a, k_a, at, slope_out if inside_first else slope)
    inside, outside = (before, after) if inside_first else (after, before)
    flat, zero = _projection(chroma, rows_b if inside_first else rows_a,
                             rows_a if inside_first else rows_b)
    if near:
        # the outside changes towards the edge (a contact shadow on the board): its level
        # is the first pixel past the edge's, and the window stops at the edge's pixel
        level = line(c + (1 if inside_first else -1))
        lo = c - half if inside_first else c
        window = np.array([line(i) for i in range(lo, lo + half + 1)])
        return (_edge_by_area(flat(window), lo, flat(inside), flat(level), inside_first),
                _mean_level(outside))
    window = np.array([line(i) for i in range(c - half, c + half + 1)])
    none = np.zeros(window.shape[-1], window.dtype)  # the level a projection zeroes
    return _edge_by_area(flat(window), c - half, none if zero == "inside" else flat(inside),
                         none if zero == "outside" else flat(outside), inside_first), \
        _mean_level(outside)


# how far towards the inside's colour (a fraction of the contrast) an outside pixel may
# lie from the nearest outside pixel and still count in the outside's level
OUTSIDE_STEP = 0.25


def _outside_to_first_step(rows_a: np.ndarray, k_a: np.ndarray, rows_b: np.ndarray,
                           k_b: np.ndarray, inside_first: bool, keep_all: bool = False
                           ) -> tuple[np.ndarray, ...]:
    """:func:`_local_edge`'s rows after (``rows_a``, at offsets ``k_a``) and before the
    edge, the outside's (nearest first) kept up to the first that steps towards the
    inside's colour by over OUTSIDE_STEP of the contrast: a dark bar 3 px beyond a panel's
    top (the mirror frame's, with a strip of pale wall between) put the outside's median
    half on the bar, and the top 1.4 px low (d_total 1.1 % long, 16 σ).  A nearest row
    still partly inside steps the other way (away from the inside) and keeps every row.
    A sloped level is cut too (a panel's side 2.5 px from the frame's bar: its line,
    fitted through the bar, put α 0.10° off).  ``keep_all`` across a colour (on a JPEG's
    stored chroma, blurred over 2 px, the step cut the rows a pencil's foot needs and put
    it up to 2 px off)."""
    if keep_all:
        return rows_a, k_a, rows_b, k_b
    rows, k, inside = ((rows_a, k_a, rows_b) if inside_first else (rows_b, k_b, rows_a))
    d = np.median(inside, axis=0) - rows[0]
    dd = float(d @ d)
    steps = np.flatnonzero((rows - rows[0]) @ d / dd > OUTSIDE_STEP) if dd > 0.0 else []
    if len(steps):
        rows, k = rows[:steps[0]], k[:steps[0]]
    return (rows, k, rows_b, k_b) if inside_first else (rows_a, k_a, rows, k)


def _projection(chroma: bool | str, inside_rows: np.ndarray, outside_rows: np.ndarray
                ) -> tuple[Callable[[np.ndarray], np.ndarray], str | None]:
    """What :func:`_local_edge`'s ``chroma`` measures on: the projection, and the side
    whose colour it takes out (that side's level is then zero)."""
    if chroma == "inside":  # across the inside's own colour (a panel's lit top face)
        return _across(np.median(inside_rows, axis=0)), "inside"
    if chroma:
        return _across(np.median(outside_rows, axis=0)), "outside"
    return (lambda x: x), None


def _across(outside: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """Projection onto the colours across ``outside``'s (its median over the rows: holes
    drop out): the outside's shading (a contact shadow, a hole, a facet turned from the
    light) scales its colour and so drops out."""
    o = outside / max(float(np.linalg.norm(outside)), 1e-9)
    return lambda x: x - (x @ o)[..., None] * o


def _mean_level(level: np.ndarray) -> np.ndarray:
    """One colour for a side's level (one per window row with ``slope``)."""
    return np.atleast_2d(level).mean(axis=0)


def median_edges(imgs: tuple[np.ndarray, np.ndarray], span: tuple[int, int],
                 cross: tuple[int, int], *, axis: int, band_px: int = 3,
                 chroma: tuple[bool | str, bool | str] = (False, False),
                 slope: tuple[bool, bool] = (False, False),
                 near: tuple[bool, bool] = (False, False),
                 max_off: float | None = None, drop_off: float | None = None,
                 half: tuple[int, int] = (1, 1), margin: tuple[float, float] = (0.2, 0.2),
                 out_reach: tuple[int | None, int | None] = (None, None)
                 ) -> tuple[float | None, float | None, np.ndarray, np.ndarray]:
    """Edges at both ends of an object spanning ``span`` = [lo, hi] along ``axis`` (0:
    top and bottom, 1: left and right) and ``cross`` across it, robust and precise;
    ``imgs`` and ``chroma``: the image each end is measured in, and whether on its colour
    across the outside's (``"inside"``: across the inside's); ``slope``: whether its
    levels are straight-line fits; ``near``: whether its outside level is the first
    pixel past it (see :func:`_local_edge`).

    Bands of ``band_px`` across the object (less ``margin`` each side) each give an edge near the
    region's boundary (±2 px); bands more than 1 px from their median (partly occluded
    ones) are dropped; the final edge is measured on the mean profile of the rest (with
    ``near``: on each of them, and averaged).  ``max_off``: bands whose edge lies farther
    than this (px) from the region's boundary are dropped too, and an end where fewer
    than half the bands remain is not measured (None): the region's boundary is then not
    the object's (see ``edges.measure_region``).  ``drop_off``: such bands are dropped
    without that rule (where many bands find no contrast at all, as on a pencil's side).
    ``half``: each end's final window, 2·half + 1 px about the edge.  ``margin``: the
    fraction of the object's width each end's bands leave out at each side;
    ``out_reach``: each end's outside level from no farther than that (see
    :func:`_local_edge`).
    Returns (edge_lo, edge_hi, outside_lo, outside_hi).
    """
    reach = max(2, (span[1] - span[0]) // 2)
    ends = [_end_edge(imgs[end], bands(*cross, band_px=band_px, margin=margin[end]),
                      span[end], end == 1,
                      axis=axis, reach=reach, chroma=chroma[end], slope=slope[end],
                      near=near[end], half=half[end], out_reach=out_reach[end],
                      max_off=max_off, drop_off=drop_off)
            for end in (0, 1)]
    return ends[0][0], ends[1][0], ends[0][1], ends[1][1]


def _end_edge(img: np.ndarray, bands: list[np.ndarray], guess: int, inside_first: bool, *,
              axis: int, reach: int, chroma: bool | str, slope: bool, near: bool, half: int,
              out_reach: int | None, max_off: float | None, drop_off: float | None
              ) -> tuple[float | None, np.ndarray]:
    """One end of :func:`median_edges`: (edge or None, outside colour)."""
    coarse = [_local_edge(img, band, axis, guess, inside_first, reach, half=2, chroma=chroma,
                          out_reach=out_reach)
              for band in bands]
    off = max_off if max_off is not None else drop_off
    if off is not None:
        boundary = guess + (0.5 if inside_first else -0.5)
        coarse = [(e if e is not None and abs(e - boundary) <= off else None, o)
                  for e, o in coarse]
    vals = [e for e, _ in coarse if e is not None]
    if not vals or (max_off is not None and len(vals) < 0.5 * len(bands)):
        return None, np.median([o for _, o in coarse], axis=0)
    m = float(np.median(vals))
    kept = [(band, e) for band, (e, _) in zip(bands, coarse, strict=True)
            if e is not None and abs(e - m) < 1.0]
    if near:
        # the level is the first pixel past the edge: per band, at the band's own
        # position (in perspective a foot slants by up to a pixel across the object,
        # and on their mean profile the next row is partly inside)
        per = [_local_edge(img, band, axis, e0, inside_first, reach, near=True,
                           chroma=chroma, out_reach=out_reach)
               for band, e0 in (kept or [(bd, m) for bd in bands])]
        got = [e for e, _ in per if e is not None]
        return (float(np.mean(got)) if got else None), np.mean([o for _, o in per], axis=0)
    keep = np.concatenate([band for band, _ in kept]) if kept else np.concatenate(bands)
    # round(m) is the pixel the edge crosses: the window is centred on it
    edge, level = _local_edge(img, keep, axis, m, inside_first, reach, half=half,
                              chroma=chroma, slope=slope, out_reach=out_reach)
    if edge is None and slope and out_reach is not None:
        # found by the coarse pass on medians, lost on lines: a pencil's top under its
        # cone, whose shading flattens near the band, and the line carried in took the
        # contrast under the floor (an unlit cone's blue is 5.5 over the paint's 0.15;
        # its line put 3.5-4.4 at the window: ideal0056_b0 of seed 61207021 lost its beacon)
        edge, level = _local_edge(img, keep, axis, m, inside_first, reach, half=half,
                                  chroma=chroma, out_reach=out_reach)
    return edge, level


def bands(cross_lo: int, cross_hi: int, *, band_px: int, margin: float = 0.2
           ) -> list[np.ndarray]:
    """Bands of ``band_px`` rows (or columns) across [cross_lo, cross_hi] less a
    ``margin`` of it at each side (0.2: the middle 60 %)."""
    span = cross_hi - cross_lo + 1
    a = cross_lo + int(margin * span)
    b = max(a + 1, cross_hi - int(margin * span) + 1)
    return [np.arange(s, min(s + band_px, b)) for s in range(a, b, band_px)]
