"""What the detector measured of one object's image: its edges, the levels around
them, and the bearing and distance derived from them."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Surround:
    """Mean linear radiance just outside each edge of an image (NaN: not measured)."""

    left: float = float("nan")
    right: float = float("nan")
    top: float = float("nan")
    bottom: float = float("nan")


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
    darker_sides: tuple[str, ...] = ()  # a panel's sides darker just inside their edge
