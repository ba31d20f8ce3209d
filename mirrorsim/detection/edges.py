"""Sub-pixel measurement of an object's image: its upright axis and vertical extent.

Pure numpy: each edge by the area method (:mod:`mirrorsim.detection.area_edges`), its
bands and levels chosen for what stands beside it (a pencil's cone, the board's contact
shadow, the mirror's frame).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from mirrorsim.camera.sensor import LINEAR_OF_CODE, lookup_codes, to_srgb8
from mirrorsim.detection.area_edges import SLOPE_ROWS, bands, median_edges
from mirrorsim.detection.image_measurement import ImageMeasurement, Surround, TopFace
from mirrorsim.detection.panel_sides import foreign_sides, sides_across_outside
from mirrorsim.scene.model import TARGET_THICKNESS, Camera

# the note of a JPEG pencil whose sides the blue channel lost and the colour measured
# (its one side may then stand against what hides part of it: image_geometry checks)
SIDES_ON_COLOUR = "sides on the image's colour: JPEG's smeared blue lost both"

# the note of an image whose foot had no colour contrast with the board (a panel or a
# pencil in shadow) and was measured on the image's colour
FOOT_ON_COLOUR = "foot on the image's colour: no colour contrast with the board"

# the note of a panel whose foot across the board's colour was something else's (see
# _panel_edges)
FOOT_NOT_ON_CHROMA = ("foot on the image's colour: across the board's colour it read "
                      "something else's edge")

# the note of a panel's top measured across the outside's colour: on the image's it lay
# far above the panel's region, on something as bright as the panel beyond it
TOP_ON_CHROMA = "top across the outside's colour: on the image's it lay above the region"
# the note of a panel's top that lay far from its region on both colours
TOP_OFF_REGION = "top far from its region on both colours: not the panel's"
# how far a panel's top may lie from its region's boundary (px) before it is measured so
# (of the ideal acceptance set's 88 panel tops, one lay beyond 2 px: 2.7 px, on the bar)
TOP_MAX_OFF_PX = 2.5

# the note of a panel's top measured across its own colour, the camera above it: the
# silhouette is the top face's back edge, the front face's top lies the face's width below
TOP_FACE = "top across the panel's own colour, less its lit top face's width"


def panel_top_face(camera: Camera, size: tuple[float, float]) -> TopFace:
    """What ``camera`` (level) sees of the top face of an upright panel of ``size``
    (width, height cm) standing on the board."""
    return TopFace(rise=camera.height - size[1], height=size[1], thickness=TARGET_THICKNESS,
                   fx=camera.fx, cx=camera.cx)


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
                   raised: bool = False, cone_ratio: float | None = None,
                   top_face: TopFace | None = None) -> ImageMeasurement:
    """Sub-pixel edges of an object's image in ``box`` and the radiance just outside each
    (pixels only: :mod:`mirrorsim.detection.detector` turns them into α and d_total).

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
    chroma), which smears the colour across an edge over 2–4 px: the target's edges and
    the pencil's top are then measured on the image's colour (JPEG keeps its luma whole),
    the pencil's foot on the colour across the board's of the 8-bit values as stored
    (``stored``; from ``img`` if not given) over a 5-px window, where JPEG moves chroma
    between neighbours without changing its sum (figures: docs/method.md).

    A lossless panel's foot is also measured on the image's colour, taken so where over
    1 px apart.  ``raised`` (3-D): a panel's top off its region is kept (_panel_edges).

    ``cone_ratio`` (a pencil): its cone's height over its band's (the frame's tallest
    pencil's), which bounds where its top's outside is read (:func:`_cone_reach`).

    ``top_face`` (a panel): what the camera sees of its top face (:func:`panel_top_face`),
    whose lit strip the front face's top is found below (:func:`_front_top`).
    """
    u0, v0, u1, v1 = box
    if kind == "beacon":
        e = _pencil_edges(img, box, subsampled=subsampled, stored=stored,
                          cone_ratio=cone_ratio)
    else:
        e = _panel_edges(img, box, on_chroma=not subsampled, raised=raised,
                         top_face=top_face)
    top, bottom, left, right = e.top, e.bottom, e.left, e.right
    cut = cut_by_frame(box, img.shape[0])
    if cut:  # (a near pencil's direct view runs off the frame: its foot there is not one)
        top, bottom = (None, bottom) if v0 <= 0 else (top, None)
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
        notes=(*e.notes, *cut), sides_on_colour=e.sides_on_colour,
        foreign_sides=e.foreign_sides, sides_across_outside=e.sides_across_outside)
    if left is not None and right is not None:
        m = replace(m, u_axis=(left + right) / 2)
    return _with_clipping(m, cut, v0 <= 0)


def _with_clipping(m: ImageMeasurement, cut: tuple[str, ...], top_cut: bool
                   ) -> ImageMeasurement:
    """``m`` flagged clipped where the frame cuts it (``cut``: :func:`cut_by_frame`'s
    note) or an end had no contrast."""
    if cut:
        return replace(m, clipped="top" if top_cut else "bottom")
    if m.v_top is None or m.v_bottom is None:
        return replace(m, clipped="top", notes=(*m.notes, "no contrast at the top or "
                                                "bottom edge: height not measured"))
    return m

def cut_by_frame(box: tuple[int, int, int, int], rows: int) -> tuple[str, ...]:
    """The note of an image whose region reaches the frame's top or bottom row."""
    return tuple(f"cut by the frame's {row} row: height not measured"
                 for row, at in (("top", box[1] <= 0), ("bottom", box[3] >= rows - 1)) if at)


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
    sides_on_colour: bool = False  # a JPEG pencil's sides on the image's colour
    foreign_sides: tuple[str, ...] = ()  # a panel's sides not its own just inside
    # a panel's sides across the outside's colour (panel_sides.sides_across_outside)
    sides_across_outside: tuple[float | None, float | None] = (None, None)


# the middle of a pencil's width whose bands its top is measured on (a margin of 0.35
# each side): the cone above narrows to its point, so a band farther out leaves it
# sooner and its outside level takes in what lies behind the cone
TOP_MARGIN = 0.35


def _cone_reach(box: tuple[int, int, int, int], cone_ratio: float | None) -> int | None:
    """How far above a pencil's painted band (px from the edge's pixel) its top's outside
    level may be read (None: no bound).  At k px above the band the cone's half-width is
    r·(1 − k/cone), so a column x·r from the axis stays on the wood while
    k < (1 − x)·cone; x is that of the outermost column the top's bands hold
    (:func:`~mirrorsim.detection.area_edges.bands`, margin TOP_MARGIN; on a
    narrow pencil the rounding keeps 40–60 % of the width).  With the level read 8 px
    up over the middle 60 %, the top of 2–8 cm pencils whose cone is 5–13 px tall read
    0.3–1.8 px low on 14 of 157 images of drawn scenes (the background's level taken for
    the wood's), 2–4 % of their d_total."""
    if cone_ratio is None:
        return None
    u0, v0, u1, v1 = box
    cols = bands(u0, u1, band_px=3, margin=TOP_MARGIN)  # the top's (median_edges' width)
    first, last = int(cols[0][0]), int(cols[-1][-1])
    axis, half_width = (u0 + u1) / 2, (u1 - u0 + 1) / 2
    x = max(abs(first - 0.5 - axis), abs(last + 0.5 - axis)) / half_width
    return int(max(0.0, 1.0 - x) * cone_ratio * (v1 - v0 + 1) - 0.5)


# A lossless frame's pencil top takes its outside level from the wood's first row past
# the edge: higher, as the cone narrows, a band's columns see other facets or the
# background, and a line through those rows put a 13-16 px band's top 0.17-0.27 px off
# (d_total 1.2-1.6 %: ideal0027 and ideal0080 of acceptance seed 61207071; over 148
# images the top's RMS error went 0.101 -> 0.036 px under 20 px, 0.047 -> 0.027 over
# 50).  A JPEG's blur spreads the edge past that row, so there it stays a line.


def _pencil_edges(img: np.ndarray, box: tuple[int, int, int, int], *, subsampled: bool,
                  stored: np.ndarray | None, cone_ratio: float | None = None) -> _Edges:
    """A pencil's edges (:func:`measure_region`): its sides and top on the blue channel,
    its foot on the colour across the board's; with ``cone_ratio``, its top on the
    middle of its width and its outside level within the cone (:func:`_cone_reach`)."""
    u0, v0, u1, v1 = box
    top_reach = _cone_reach(box, cone_ratio)
    sides_note: tuple[str, ...] = ()
    on_colour = False  # its sides measured on the image's colour (JPEG)
    blue = np.ascontiguousarray(img[..., 2:3])
    foot_img = img
    if subsampled:
        foot_img = np.asarray(stored if stored is not None else to_srgb8(img / 255.0),
                              np.float32)
    # (the top's outside level on a lossless frame: the note above this function)
    top, bottom, out_top, out_bottom = median_edges((img if subsampled else blue, foot_img),
                                                     (v0, v1), (u0, u1), axis=0,
                                                     chroma=(False, True),
                                                     slope=(True, True),
                                                     near=(not subsampled, False),
                                                     half=(1, 2 if subsampled else 1),
                                                     margin=(0.2 if top_reach is None
                                                             else TOP_MARGIN, 0.2),
                                                     out_reach=(top_reach, None))
    if subsampled:  # the board's level below the foot (a mean of stored values) as
        # linear radiance like the rest: the radiance of that value, within a code's
        # step of the mean radiance
        out_bottom = np.interp(out_bottom, np.arange(256), _LINEAR_LUT)
    elif bottom is None and v1 + SLOPE_ROWS + 2 < img.shape[0]:
        # (an image cut by the frame's bottom row keeps no foot)
        # a pencil in deep shade is a dark olive whose colour across a sandy board's is
        # 3-4 linear levels, under the area method's floor (2 of 120 drawn scenes lost
        # their only beacon): its foot on the image's colour, the board's contact shadow
        # counted (as a panel in shadow's, FOOT_ON_COLOUR)
        _, bottom, _, out_bottom = median_edges((img, img), (v0, v1), (u0, u1), axis=0,
                                                 near=(False, True))
        if bottom is not None:
            sides_note = (*sides_note, FOOT_ON_COLOUR)
    # a pencil 3 px from the frame's bar: the bar is the coarse pass's outside, the
    # board between reads as coverage and a side lands on the other (14 px in)
    left, right, out_left, out_right = median_edges((blue, blue), (u0, u1), (v0, v1), axis=1,
                                                     near=(True, True),
                                                     drop_off=SIDE_MAX_OFF_PX)
    if subsampled and left is None and right is None:
        # JPEG smears the blue channel (mostly chroma) over 2-3 px: a pencil pressed
        # against the mirror's frame on one side and 2 px from a wall on the other
        # had neither side in it (2 of 40 planned benches), and was dropped.  The
        # image's colour keeps its edges at full resolution in the luma
        left, right, out_left, out_right = median_edges((img, img), (u0, u1), (v0, v1),
                                                         axis=1, near=(True, True),
                                                         drop_off=SIDE_MAX_OFF_PX)
        # a side against a grey wall has little contrast in the colour either, and
        # can land off the (yellow) region: then the axis comes from the other side
        left = left if left is not None and abs(left - (u0 - 0.5)) <= SIDE_MAX_OFF_PX else None
        right = right if right is not None and abs(right - (u1 + 0.5)) <= SIDE_MAX_OFF_PX \
            else None
        sides_note, on_colour = (*sides_note, SIDES_ON_COLOUR), True
    return _Edges(top, bottom, left, right, out_top, out_bottom, out_left, out_right,
                  sides_note, sides_on_colour=on_colour)


# how far the top on the image's colour must lie below the silhouette for the top face's
# strip to count as seen: at least [0] and at most [1] times the predicted strip plus [2] px
STRIP_PULL = (0.5, 8.0, 0.5)


def _front_top(img: np.ndarray, box: tuple[int, int, int, int], top: float | None,
               bottom: float | None, top_face: TopFace | None
               ) -> tuple[float, np.ndarray] | None:
    """The front face's top edge and the level above it, for a camera above the panel
    (None where it is not, or the silhouette has no colour against the outside).

    The top face, lit from above, shines 3-4 times the front face: a strip of it above the
    front face's top pulled the top measured on the image's colour down, up to 0.48 px
    below the front face's (d_total up to 0.5 % long where σ said 0.04 %: 22 of the ideal
    acceptance set's panels stood below the camera).  The face is the front's paint: across
    the panel's own colour it reads as panel, and the edge found is the silhouette, the
    face's back edge; the front's top lies the face's width (:meth:`TopFace.width_px`)
    below it."""
    if top_face is None or top_face.rise <= 0.0 or top is None or bottom is None:
        return None
    u0, v0, u1, v1 = box
    axis = (u0 + u1) / 2
    strip = top_face.width_px(bottom - top, axis)
    silhouette, _, out_s, _ = median_edges((img, img), (v0, v1), (u0, u1), axis=0,
                                           chroma=("inside", False))
    # the strip must show: the lit face pulls the top on the image's colour below the
    # silhouette by at least half its width (1.5-6 times it in the acceptance frames);
    # a mirror tilted back may hide the face, and the two then agree
    pulled = top - silhouette if silhouette is not None else math.nan
    if not STRIP_PULL[0] * strip <= pulled <= STRIP_PULL[1] * strip + STRIP_PULL[2]:
        return None
    strip = 0.0
    for _ in range(3):  # (the front's height is the silhouette's less the strip)
        strip = top_face.width_px(bottom - silhouette - strip, axis)
    return silhouette + strip, out_s


def _panel_edges(img: np.ndarray, box: tuple[int, int, int, int], *, on_chroma: bool,
                 raised: bool = False, top_face: TopFace | None = None) -> _Edges:
    """The target panel's edges (:func:`measure_region`): on its colour against the
    outside's, the sides with sloped levels; on a lossless frame (``on_chroma``) the top
    below its top face where seen (:func:`_front_top`), the foot as measure_region says."""
    u0, v0, u1, v1 = box
    sides_note: tuple[str, ...] = ()
    top, bottom, out_top, out_bottom = median_edges((img, img), (v0, v1), (u0, u1), axis=0,
                                                     chroma=(False, on_chroma),
                                                     near=(False, True))
    front = _front_top(img, box, top, bottom, top_face) if on_chroma else None
    if front is not None:
        (top, out_top), sides_note = front, (*sides_note, TOP_FACE)
    elif on_chroma and top is not None and abs(top - (v0 - 0.5)) > TOP_MAX_OFF_PX:
        # a top that far above the region (found on the panel's own colour) took in
        # something as bright as the panel above it: a strip of brown wall in the glass,
        # 3 px under the mirror frame's dark bar, and the edge fell on the bar (3.8 px
        # high, d_total 1.5 % short, 12 σ).  Across the outside's colour the strip is
        # told from the neutral panel: the top is measured so where that lies at the region
        top_c, _, out_c, _ = median_edges((img, img), (v0, v1), (u0, u1), axis=0,
                                          chroma=(True, False))
        if top_c is not None and abs(top_c - (v0 - 0.5)) <= TOP_MAX_OFF_PX:
            top, out_top, sides_note = top_c, out_c, (*sides_note, TOP_ON_CHROMA)
        elif not raised:  # neither is the panel's top (the frame's bar 1-2 px above it
            # took the edge 10 px up): none, and the height comes from the width
            # (image_geometry; a raised panel's region, beside its stand, may be short)
            top, sides_note = None, (*sides_note, TOP_OFF_REGION)
    if on_chroma and bottom is not None:
        # across the outside's colour a foot may be read on something else: a raised
        # panel's against the room's pale baseboard, as neutral as the panel (the foot
        # on the baseboard's far side, 2.5 px low); a dark neutral panel's with a yellow
        # pencil before it (only the pencil's bands had contrast, and its top was taken
        # for the foot: 5.5 px high, d_total +9.2 %).  The foot on the image's colour is
        # taken where the two lie over a pixel apart (on the board: 0.3-0.6 px apart)
        _, plain, _, out_plain = median_edges((img, img), (v0, v1), (u0, u1), axis=0,
                                               near=(False, True))
        if plain is not None and abs(plain - bottom) > 1.0:
            bottom, out_bottom, sides_note = plain, out_plain, (*sides_note, FOOT_NOT_ON_CHROMA)
    if bottom is None and on_chroma:
        # a panel in shadow is a dark grey with almost no colour across the board's
        # (a drawn scene's lost its height, 1 of 24): its foot on the image's colour,
        # where the board's contact shadow counts (as on a JPEG frame)
        _, bottom, _, out_bottom = median_edges((img, img), (v0, v1), (u0, u1), axis=0,
                                                 near=(False, True))
        if bottom is not None:
            sides_note = (*sides_note, FOOT_ON_COLOUR)
    # a side 2-3 px from the mirror frame's inner edge leaves a bright strip of glass
    # between them: the coarse pass's outside level then falls on the dark frame bar,
    # the strip reads as coverage far above 1 and the edge is pushed 9-13 px out.  The
    # region (found on the panel's own colour) is right; a side far from it is dropped
    # and the axis taken from the other side (image_geometry.target_geometry)
    left, right, out_left, out_right = median_edges((img, img), (u0, u1), (v0, v1), axis=1,
                                                     slope=(True, True),
                                                     max_off=SIDE_MAX_OFF_PX)
    foreign, foreign_notes = foreign_sides(img, box, left=left, right=right, top=top,
                                                   lossless=on_chroma)
    return _Edges(top, bottom, left, right, out_top, out_bottom, out_left, out_right,
                  (*sides_note, *foreign_notes), foreign_sides=foreign,
                  sides_across_outside=sides_across_outside(img, box) if on_chroma
                  else (None, None))
