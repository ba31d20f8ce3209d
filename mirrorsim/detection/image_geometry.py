"""Where an object's image puts it: bearing, distance and clipping from its pixel edges.

Pure geometry of a level pinhole camera (no OpenCV): :mod:`mirrorsim.detection.edges` finds the
edges, this turns them into the angle of arrival α and the path length d_total.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from mirrorsim.detection.image_measurement import ImageMeasurement
from mirrorsim.errors import DetectionError
from mirrorsim.scene.model import FRONT_OFFSET, PENCIL_RADIUS, Camera, Point2
from solver.geometry import wrap_bearing

# the hexagon's silhouette half-width averaged over its turn: R·sin 30°/(π/6)
PENCIL_HALF_WIDTH = PENCIL_RADIUS * 3 / math.pi


@dataclass(frozen=True)
class Calibration:
    """Size-constancy constants K = s_px · (d − front offset) (px·cm), target and pencil."""

    target_k: float
    pencil_k: float
    # what the constants were measured for (the cache's key): not part of their value, so
    # a report's calibration read back from its JSON equals the one it was written from
    key: str = field(default="", compare=False)

    def height_px(self, kind: str, distance: float) -> float:
        """The image height (px) of the target or the beacon (``kind``) whose measured
        face stands ``distance`` cm from the camera along the optical axis."""
        k = self.target_k if kind == "target" else self.pencil_k
        return k / (distance - FRONT_OFFSET[kind])

    def constants(self) -> dict[str, float]:
        """The two constants as every file that records them names them (a report, the
        cache entry, ``calibrate --json``)."""
        return {"target_k": self.target_k, "pencil_k": self.pencil_k}


RATIO_TOLERANCE = 0.004  # relative: the panel's angular width/height ratio is exact unclipped


def alpha_of(camera: Camera, u: float) -> float:
    """Bearing of the image column u (sub-pixel)."""
    return float(wrap_bearing(camera.pan_deg - math.degrees(_off_axis(camera, u))))


def _off_axis(camera: Camera, u: float) -> float:
    """Angle (rad) of column u right of the optical axis."""
    return math.atan2(u - camera.cx, camera.fx)


def _column(camera: Camera, phi: float) -> float:
    return camera.cx + camera.fx * math.tan(phi)


def _axis_between(camera: Camera, u_left: float, u_right: float) -> tuple[float, float]:
    """The bearing of an upright object's axis from its two silhouette edges, and its
    column.  The object (a panel square-on to the line of sight, a pencil) subtends
    equal angles either side of its axis, so the axis lies at the *mean angle* of the
    edges, not at their mean column (that is off by about (w/2d)²·tan φ)."""
    phi = (_off_axis(camera, u_left) + _off_axis(camera, u_right)) / 2
    return float(wrap_bearing(camera.pan_deg - math.degrees(phi))), _column(camera, phi)


def distance_of(camera: Camera, u: float, height_px: float, *, k: float,
                front_offset: float = 0.0) -> float:
    """d_total from size constancy: the measured face's depth K/s along the optical axis,
    over cos φ, is its distance along the line of sight; plus the face's offset before
    the object's centre (along the line of sight too)."""
    return k / height_px / math.cos(_off_axis(camera, u)) + front_offset


def elevation_of(camera: Camera, m: ImageMeasurement) -> tuple[float, float]:
    """An image's elevation ε (deg) and its 3-D d_total (cm), for the 3-D solve
    (docs/method.md): the foot's row at the axis column, as the level camera sees it,
    gives the tangent of the measured face's foot's elevation, (cy − v)·cos φ / f; its
    horizontal distance (size constancy, ``m.d_total`` less the face's offset) puts the
    foot that far above or below the lens; ε is that rise over the axis's horizontal
    distance, d_total their hypotenuse.

    Raises
    ------
    DetectionError
        The image has no measured foot or distance.
    """
    require_foot(m)
    tan_face = (camera.cy - m.v_bottom) * math.cos(_off_axis(camera, m.u_axis)) / camera.fx
    return rise_reading(tan_face, m.d_total, m.kind)


def require_foot(m: ImageMeasurement) -> None:
    """Refuse an image without a measured foot or distance: it has no elevation.

    Raises
    ------
    DetectionError
        Naming the image's kind.
    """
    if m.v_bottom is None or m.d_total is None:
        raise DetectionError(f"the {m.kind}'s image has no measured foot or height: no "
                             "elevation")


def rise_reading(tan_face: float, d_total: float, kind: str) -> tuple[float, float]:
    """ε (deg) and the 3-D d_total of an image whose measured face's foot is seen at an
    elevation of tangent ``tan_face``, ``d_total`` (cm, size constancy's, horizontal)
    away: the foot lies tan_face·(d_total − the face's offset) above the lens
    (:func:`elevation_of`; the board's pose gives its own tangent,
    :func:`~mirrorsim.detection.posed.corrected_image3`)."""
    rise = tan_face * (d_total - FRONT_OFFSET[kind])
    return math.degrees(math.atan2(rise, d_total)), math.hypot(d_total, rise)


# a pencil image's angular width over what its height implies: beyond this, one side is
# wrong.  On a lossless frame the good ones are 0.91-1.07 (237 images of acceptance seeds
# 61207021-22); a pencil before the panel's side read its left edge on the panel's at
# 1.16-1.25 (α 0.11°).  A JPEG's blurred sides read up to 1.23
PENCIL_WIDTH_RATIO = (0.8, 1.25)
PENCIL_WIDTH_MAX_LOSSLESS = 1.12
# a JPEG pencil's yellow region narrower than this part of it is partly hidden
PENCIL_REGION_MIN = 0.95


def _half_angle(cam: Camera, half_width: float, height_px: float, height: float,
                phi: float) -> float:
    """β, the angular half-width of an upright object of ``half_width`` and ``height``
    (cm) whose image is ``height_px`` tall, its axis at φ off the optical axis (rad):
    tan β = half_width·s·cos φ/(f·height)."""
    return math.atan(half_width * height_px * math.cos(phi) / (cam.fx * height))


def _height_px(cam: Camera, half_width: float, beta: float, height: float, phi: float
               ) -> float:
    """The inverse of :func:`_half_angle`: the image height (px) of an upright object of
    ``half_width`` and ``height`` (cm) whose half-width subtends ``beta`` at φ (rad)."""
    return math.tan(beta) * cam.fx * height / (half_width * math.cos(phi))


def _dark(m: ImageMeasurement, side: str) -> bool:
    """Whether the level just outside ``side`` of the image is under half its inside's
    (something dark there, the mirror's frame, may cut it; a level not measured is NaN:
    not dark)."""
    return getattr(m.outside, side) < 0.5 * m.inside


def _axis_from_edge(cam: Camera, edge_u: float, side: str, half_width: float,
                    height_px: float, height: float) -> float:
    """The axis column of an object seen by one side edge (``side``: which) and its
    height: β from that edge, β's cos φ taken at the axis (refined twice)."""
    phi_edge = _off_axis(cam, edge_u)
    sign = 1.0 if side == "left" else -1.0
    beta = _half_angle(cam, half_width, height_px, height, phi_edge)
    for _ in range(2):
        beta = _half_angle(cam, half_width, height_px, height, phi_edge + sign * beta)
    return _column(cam, phi_edge + sign * beta)


def _width_ratio(cam: Camera, left: float, right: float, height_px: float,
                 paint_height: float) -> float:
    """The angular width between columns ``left`` and ``right`` over a pencil's, as its
    height implies."""
    a, b = _off_axis(cam, left), _off_axis(cam, right)
    return (b - a) / 2 / _half_angle(cam, PENCIL_HALF_WIDTH, height_px, paint_height,
                                     (a + b) / 2)


def pencil_geometry(cam: Camera, m: ImageMeasurement, paint_height: float, *, k: float,
                    subsampled: bool = False) -> ImageMeasurement:
    """A pencil's bearing from its edges and its d_total from its height (K = ``k``);
    with one edge (the other side runs into something of the paint's blue, such as the
    mirror's dark frame) its bearing from that edge and the pencil's angular half-width,
    tan β = r·s·cos φ/(f·H) (r its mean silhouette half-width, H its painted height).
    ``subsampled``: a JPEG frame's (its sides blur wider)."""
    notes = m.notes
    if m.u_left is not None and m.u_right is not None and m.height_px:
        # a backstop: a width far from what the height implies means one side is not the
        # pencil's (PENCIL_WIDTH_RATIO); the side farther from its region's edge is dropped
        r = _width_ratio(cam, m.u_left, m.u_right, m.height_px, paint_height)
        widest = PENCIL_WIDTH_RATIO[1] if subsampled else PENCIL_WIDTH_MAX_LOSSLESS
        if not PENCIL_WIDTH_RATIO[0] <= r <= widest:
            u0, _, u1, _ = m.bbox_px
            bad = "left" if abs(m.u_left - (u0 - 0.5)) > abs(m.u_right - (u1 + 0.5)) else "right"
            notes = (*notes, f"width {r:.2f} of what the height implies: the {bad} edge is "
                     "not the pencil's")
            m = replace(m, **{f"u_{bad}": None})
    if m.u_left is not None and m.u_right is not None:
        alpha, u_axis = _axis_between(cam, m.u_left, m.u_right)
    else:
        side = "left" if m.u_left is not None else "right"
        missing = "right" if side == "left" else "left"
        u_axis = _axis_from_edge(cam, m.u_left if side == "left" else m.u_right, side,
                                 PENCIL_HALF_WIDTH, m.height_px, paint_height)
        alpha = alpha_of(cam, u_axis)
        notes = (*notes, f"no edge on the {missing} (no contrast there, or not the "
                 "pencil's): axis from the other edge and the pencil's half-width")
        if m.sides_on_colour:
            # its one edge, measured on the colour, may be where the mirror's frame hides
            # part of it: a yellow region narrower than the height implies says so (a
            # whole JPEG pencil's region: 1.03-1.12 of it, widened by the blur)
            u0, _, u1, _ = m.bbox_px
            r = _width_ratio(cam, u0 - 0.5, u1 + 0.5, m.height_px, paint_height)
            if r < PENCIL_REGION_MIN:
                return replace(m, clipped=side, notes=(
                    *notes, f"its region {r:.2f} of the width its height implies: "
                    f"partly hidden at its {side} edge, not used"))
    return replace(m, alpha_deg=alpha, u_axis=u_axis, notes=notes,
                   d_total=distance_of(cam, u_axis, m.height_px, k=k,
                                       front_offset=FRONT_OFFSET["beacon"]))


def target_geometry(cam: Camera, m: ImageMeasurement, size: Point2, *, k: float
                    ) -> ImageMeasurement:
    """The panel's bearing, clipping and distance from its edges.

    Seen square-on at distance D (front face), the panel's half-width subtends
    β = atan((w/2)/D) and its height s = f·H/(D·cos φ) pixels, so tan β = w·s·cos φ/(2fH):
    its angular width follows from its height, exactly, at any angle off the axis.  An
    image narrower than that, whose missing side runs into something dark (the mirror's
    frame), is clipped there and its axis is β from the other edge; one wider than its
    height allows, under something dark, is clipped at the top, and its height comes from
    its width where its sides are the panel's (:func:`_height_from_width`).
    """
    edges = {"left": m.u_left, "right": m.u_right}
    present = [k_ for k_, u in edges.items() if u is not None]
    if m.height_px is not None and present:
        m, present, beta = _target_clip(cam, m, size, present)
        if len(present) == 1:
            side = present[0]
            u_axis = _axis_from_edge(cam, edges[side], side, size[0] / 2, m.height_px,
                                     size[1])
            m = replace(m, u_axis=u_axis, alpha_deg=alpha_of(cam, u_axis))
        else:
            alpha, u_axis = _axis_between(cam, m.u_left, m.u_right)
            m = replace(m, alpha_deg=alpha, u_axis=u_axis)
    elif len(present) == 2:
        alpha, u_axis = _axis_between(cam, m.u_left, m.u_right)
        m = replace(m, alpha_deg=alpha, u_axis=u_axis)
        if m.v_bottom is not None and m.clipped == "top":
            # no contrast at its top (under the mirror frame's bar, a strip of glass
            # between: ideal0022 of seed 61207021 measured no d_total)
            m = _height_from_width(cam, m, size, "height from its width")
        elif m.clipped == "top" and m.v_bottom is None and m.v_top is not None \
                and not (_dark(m, "top") or "top" in m.foreign_sides):
            # no contrast at its foot, its top its own: a JPEG's colour block took the
            # panel's last rows out of its region, whose foot then lay inside the panel
            # (bench0076 of seed 61207052 measured no d_total)
            m = _height_from_width(cam, m, size, "no contrast at its foot: height from "
                                   "its width, foot below its top")
    else:
        raise DetectionError("the target's image has neither a measurable height nor two "
                             "side edges")
    if m.height_px is not None:
        m = replace(m, d_total=distance_of(cam, m.u_axis, m.height_px, k=k,
                                           front_offset=FRONT_OFFSET["target"]))
    return m


def _target_clip(cam: Camera, m: ImageMeasurement, size: Point2, present: list[str]
                 ) -> tuple[ImageMeasurement, list[str], float]:
    """The panel's angular width against the one its height implies: clipped at the top
    (height from its width where its sides allow), clipped on a side (that edge dropped),
    or noted.  Returns the measurement, the edges to use and the half-width β the height
    implies."""
    w, h = size
    edges = {"left": m.u_left, "right": m.u_right}
    dark = {side: _dark(m, side) for side in ("left", "right", "top")}
    phi0 = (sum(_off_axis(cam, edges[s_]) for s_ in present) / len(present))
    beta = _half_angle(cam, w / 2, m.height_px, h, phi0)
    if len(present) == 2:
        half = (_off_axis(cam, m.u_right) - _off_axis(cam, m.u_left)) / 2
        r = half / beta
        tol = max(RATIO_TOLERANCE, 0.3 / max(m.width_px, 1.0))
        if r > 1 + tol and dark["top"]:
            m = _height_from_width(cam, replace(m, clipped="top"), size, (
                f"image {100 * (r - 1):.1f}% shorter than its width implies, under a dark "
                "edge: clipped at the top, height from its width"))
        elif r < 1 - tol and (dark["left"] or dark["right"]):
            side = ("left" if dark["left"] and not (dark["right"]
                                                    and m.outside.right < m.outside.left)
                    else "right")
            present = ["right" if side == "left" else "left"]
            m = replace(m, clipped=side, notes=(
                *m.notes, f"image {100 * (1 - r):.1f}% narrower than its height implies, "
                f"beside a dark edge: clipped on the {side}, axis from the other edge"))
        elif r > 1 + tol and len(foreign := [s_ for s_ in present
                                             if s_ in m.foreign_sides]) == 1:
            # wider than the height allows, one side not the panel's just inside: the
            # region took in a dark bar (the side at its far edge, 6 px out, α 0.26° off)
            # or a strip of glass before one (1.4 px out); that side is dropped
            side = foreign[0]
            present = [s_ for s_ in present if s_ != side]
            m = replace(m, **{f"u_{side}": None}, width_px=None, notes=(
                *m.notes, f"image {100 * (r - 1):.1f}% wider than its height implies, "
                f"not the panel's just inside its {side} edge: that edge is not its own, "
                "axis from the other"))
        elif r < 1 - tol and (dark["top"] or "top" in m.foreign_sides):  # its top on the
            # frame's bar: under it, or the bar taken into the region across 1 px of wall
            m = _height_from_width(cam, m, size, (
                f"image {100 * (1 - r):.1f}% narrower than its height implies, " + (
                    "under a dark edge, its sides not: its top is that edge's" if dark["top"]
                    else "darker just inside its top: its top is not the panel's")
                + ", height from its width"))
        elif r > 1 + tol and (shaded := _shaded_side(cam, m, beta, r)) is not None:
            m = shaded
        elif abs(r - 1) > tol:
            m = replace(m, notes=(*m.notes, f"angular width {100 * (r - 1):+.1f}% off what "
                                  "its height implies, with no dark edge to clip it: not "
                                  "treated as clipped"))
    else:
        # no edge on one side: no contrast there (a clip, or a background as dark as the
        # panel), or one far from the panel's region (edges.SIDE_MAX_OFF_PX); which, the
        # pixels cannot say, so it is noted, not flagged
        missing = "right" if present == ["left"] else "left"
        m = replace(m, notes=(*m.notes, f"no edge on the {missing} (no contrast there, or "
                              "not at the panel's region): axis from the other edge and the "
                              "width the height implies"))
    return m, present, beta


# how far inside (px) a side across the outside's colour must lie to replace the side on
# the image's colour, and how much nearer 1 the width over what the height implies must
# then come (of the ideal acceptance set's 98 panels, 5 had a side so far apart: the
# width decided right in each)
SHADED_SIDE = (1.0, 0.5)


def _shaded_side(cam: Camera, m: ImageMeasurement, beta: float, r: float
                 ) -> ImageMeasurement | None:
    """``m`` with one side taken across the outside's colour, where the image on the
    image's colour is wider than its height implies (ratio ``r``) and that side, lying
    inside the other by over SHADED_SIDE[0] px, brings the ratio near 1.  A blue wall's
    shadow beside a grey panel is as dark as the panel: on the image's colour it counted
    as panel, the side 3.5 px out (α 0.106° off, 57 σ: ideal0013 of seed 61207021)."""
    inward, gain = SHADED_SIDE
    c_left, c_right = m.sides_across_outside
    fits = []  # (how far the ratio then lies from 1, side, its column, moved, the sides)
    for side, u, moved in (("left", c_left, None if c_left is None else c_left - m.u_left),
                           ("right", c_right, None if c_right is None else m.u_right - c_right)):
        if moved is None or moved <= inward:
            continue
        left, right = (u, m.u_right) if side == "left" else (m.u_left, u)
        r_side = (_off_axis(cam, right) - _off_axis(cam, left)) / 2 / beta
        if abs(r_side - 1) <= gain * abs(r - 1):
            fits.append((abs(r_side - 1), side, u, moved, r_side, right - left))
    if not fits:
        return None
    _, side, u, moved, r_side, width = min(fits)
    return replace(m, **{f"u_{side}": u}, width_px=width, notes=(
        *m.notes, f"image {100 * (r - 1):.1f}% wider than its height implies; its {side} "
        f"side across the outside's colour {moved:.1f} px in, {100 * (r_side - 1):+.1f}%: "
        "a shadow of the outside's colour beside it"))


# how near (px) a panel's sides across the outside's colour must lie to its sides for
# its width to stand for its height (a shadow of a coloured wall beside it: 3.5 px)
WIDTH_SIDES_PX = 1.0


def _height_from_width(cam: Camera, m: ImageMeasurement, size: Point2, note: str
                       ) -> ImageMeasurement:
    """``m`` with the height its two sides imply (tan β = w·s·cos φ/(2fH), target_geometry)
    where its top is not the panel's, from its foot (the board's check on the foot then
    holds it), or where it has no foot, from its top.  Only where both sides are the
    panel's: none beside something dark (the mirror frame's side bar may cut it there),
    none foreign just inside, and each within WIDTH_SIDES_PX of its measure across the
    outside's colour; else its height is not used."""
    dark = _dark(m, "left") or _dark(m, "right")
    across = [abs(c - u) for c, u in zip(m.sides_across_outside, (m.u_left, m.u_right),
                                         strict=True) if c is not None and u is not None]
    if (m.v_bottom is None and m.v_top is None) or m.u_left is None or m.u_right is None \
            or dark or \
            {"left", "right"} & set(m.foreign_sides) or any(d > WIDTH_SIDES_PX for d in across):
        return replace(m, height_px=None, notes=(*m.notes, note.replace(
            "height from its width", "height not used")))
    left, right = _off_axis(cam, m.u_left), _off_axis(cam, m.u_right)
    s = _height_px(cam, size[0] / 2, (right - left) / 2, size[1], (left + right) / 2)
    if m.v_bottom is None:  # its foot the height below its top
        return replace(m, height_px=s, v_bottom=m.v_top + s, notes=(*m.notes, note))
    return replace(m, height_px=s, v_top=m.v_bottom - s, notes=(*m.notes, note))
