"""What lies beside a target panel's side edges: whether the pixels just inside an edge
are the panel's (the region, grown on the panel's grey, may take in the mirror frame's
bar or a strip of glass beside it), and the sides measured across the outside's colour.

Pure numpy; :mod:`mirrorsim.detection.edges` measures the panel, and
:mod:`mirrorsim.detection.image_geometry` drops a side these say is not the panel's
where the image's width also disagrees with its height.
"""

from __future__ import annotations

import math

import numpy as np

from mirrorsim.detection.area_edges import median_edges

ACROSS_OFF_PX = 5.0  # how far from the region a side across the outside's colour may lie


def sides_across_outside(img: np.ndarray, box: tuple[int, int, int, int]
                         ) -> tuple[float | None, float | None]:
    """A panel's sides measured across the outside's colour: where a shadow of a coloured
    wall lies beside it, as dark as the panel, this one reads the shadow as outside
    (image_geometry takes a side so where the width then fits the height)."""
    u0, v0, u1, v1 = box
    left, right, _, _ = median_edges((img, img), (u0, u1), (v0, v1), axis=1,
                                     slope=(True, True), chroma=(True, True),
                                     drop_off=ACROSS_OFF_PX)
    return left, right


# the note of a panel's side whose pixels just inside it are much darker than the
# panel's middle: the region took in something dark beside it (the mirror frame's bar,
# 1-2 px of background away), and the side found is that thing's outer edge
# (image_geometry drops it where the image is also wider than its height implies)
DARKER_SIDE = "darker than the panel just inside its edge: "
DARKER_RATIO = 0.7  # a side strip's level over the middle's (a frame bar: 0.43)

# the note of a panel's side with a column paler than the panel's middle at it or within
# two columns inside, against a dark outside: with a box filter an edge's pixel lies
# between its two levels, so that column is something else's.  A strip of glass 1.5 px
# wide between the panel and the frame's bar was taken in, the side found on the bar
# (1.4 px out, α 0.062°, 13.8 σ; ideal0028 of acceptance seed 61207051)
PALER_SIDE = "a paler strip just inside its edge, a dark one outside: "
# how far above the middle that column must lie, as a fraction of the middle's level
# over the outside's (that strip: 0.34) and in the middle's column-to-column scatter
PALER_FRACTION, PALER_SCATTER = 0.2, 4.0


def foreign_sides(img: np.ndarray, box: tuple[int, int, int, int], *, left: float | None,
                  right: float | None, top: float | None, lossless: bool
                  ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The panel's sides whose pixels just inside are not the panel's, as (the sides,
    their notes).  A side ('left', 'right', 'top') whose 2-px strip just inside the edge,
    over the middle half of the rows (of the columns, for the top), is darker than
    DARKER_RATIO of the panel's middle (a top there: the frame's bar, a strip of wall
    between, taken in); on a ``lossless`` frame (JPEG's ringing makes such columns) a
    side with a column at the edge or within two inside it paler than the middle by
    PALER_FRACTION of its contrast with a darker outside."""
    u0, v0, u1, v1 = box
    rows = slice(v0 + (v1 - v0) // 4, v1 - (v1 - v0) // 4 + 1)
    cols = slice(u0 + (u1 - u0) // 4, u1 - (u1 - u0) // 4 + 1)
    core = float(np.median(img[rows, cols]))
    middle = np.median(img[rows, cols].mean(axis=-1), axis=0)  # its middle columns' levels
    found: list[tuple[str, str]] = []
    for side, edge, step in (("left", left, 1), ("right", right, -1), ("top", top, 1)):
        if edge is None or core <= 0:
            continue
        first = int(math.floor(edge + 0.5)) + (1 if step > 0 else -1)  # wholly inside
        lo, hi = sorted((first, first + step))
        cells = img[max(lo, 0):hi + 1, cols] if side == "top" else img[rows, max(lo, 0):hi + 1]
        if cells.size == 0:  # (a panel a pixel or two wide at the frame's side)
            continue
        if float(np.median(cells)) < DARKER_RATIO * core:
            found.append((side, DARKER_SIDE))
        elif lossless and side != "top" and _paler_inside(img, rows, middle, edge, step):
            found.append((side, PALER_SIDE))
    return tuple(s for s, _ in found), tuple(note + s for s, note in found)


def _paler_inside(img: np.ndarray, rows: slice, middle: np.ndarray, edge: float, step: int
                  ) -> bool:
    """Whether the column holding a side edge, or one of the next two in, lies paler
    than the panel's ``middle`` columns (their levels over ``rows``) against a darker
    column just outside (PALER_SIDE)."""
    at = int(math.floor(edge + 0.5))  # the column holding the edge (its centre at +0)
    outside, ins = at - step, (at, at + step, at + 2 * step)
    if min(outside, *ins) < 0 or max(outside, *ins) >= img.shape[1]:
        return False
    level = [float(np.median(img[rows, c].mean(axis=-1))) for c in (outside, *ins)]
    core = float(np.median(middle))
    scatter = 1.4826 * float(np.median(np.abs(middle - core)))
    contrast = core - level[0]
    return contrast > 0 and max(level[1:]) - core > max(PALER_FRACTION * contrast,
                                                        PALER_SCATTER * scatter)
