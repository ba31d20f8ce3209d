"""What the detector measured of one object's image: its edges, the levels around
them, and the bearing and distance derived from them."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Surround:
    """Mean linear radiance just outside each edge of an image (NaN: not measured)."""

    left: float = float("nan")
    right: float = float("nan")
    top: float = float("nan")
    bottom: float = float("nan")


@dataclass(frozen=True)
class TopFace:
    """What a level camera sees of an upright panel's top face: it stands ``rise`` cm
    above the panel's top (≤ 0: the face is hidden), and the panel is ``height`` cm tall
    and ``thickness`` cm thick, facing the camera (in the mirror: its virtual image);
    ``fx`` and ``cx``: the film's focal length and principal column (px)."""

    rise: float
    height: float
    thickness: float
    fx: float
    cx: float

    def width_px(self, front_px: float, u: float) -> float:
        """The top face's image height (px) above the front face's top edge, for a front
        face ``front_px`` tall whose axis is column ``u``: the front face's depth along
        the optical axis is fx·H/s, the back edge's that plus t·cos φ (the face runs t
        along the line of sight), and a row lies fx·rise/depth below the principal
        row."""
        if self.rise <= 0.0 or front_px <= 0.0:
            return 0.0
        depth = self.fx * self.height / front_px
        back = depth + self.thickness * math.cos(math.atan((u - self.cx) / self.fx))
        return self.fx * self.rise * (1.0 / depth - 1.0 / back)


@dataclass(frozen=True)
class ImageMeasurement:
    """One object's image: its upright axis, vertical extent and derived α, d_total.

    Frozen: each stage of the detector (edges here, then the pixel geometry, then the
    beacons' assignment) returns a new value with what it found."""

    kind: str  # "target" or "beacon"
    source: str  # "mirror" or "direct"
    bbox_px: list[int]
    u_axis: float  # the column of the upright axis's bearing (see mirrorsim.detection.detector)
    v_top: float | None
    v_bottom: float | None
    height_px: float | None
    width_px: float | None
    u_left: float | None = None  # the side edges (None: no contrast there)
    u_right: float | None = None
    # mean linear radiance just outside each edge, and inside (for the clip decision)
    outside: Surround = Surround()
    inside: float = float("nan")
    clipped: str = ""  # '', 'top', 'left', 'right'
    alpha_deg: float = float("nan")
    d_total: float | None = None
    beacon_index: int | None = None
    notes: tuple[str, ...] = ()
    # what the edges' measurement found that the pixel geometry weighs (each also a note)
    sides_on_colour: bool = False  # a JPEG pencil's sides measured on the image's colour
    foreign_sides: tuple[str, ...] = ()  # a panel's sides not its own just inside their edge
    # a panel's sides measured across the outside's colour (None: not measured so)
    sides_across_outside: tuple[float | None, float | None] = (None, None)
