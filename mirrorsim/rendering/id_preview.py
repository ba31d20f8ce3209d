"""The id labels for a viewer (``<name>.ids.preview.png``): each object's colour, what
the mirror shows of it lighter, and a legend strip naming each colour.  The labels
themselves are :func:`mirrorsim.rendering.id_pass.encode_ids`'."""

from __future__ import annotations

import numpy as np

from mirrorsim.rendering.id_pass import IN_MIRROR
from mirrorsim.rendering.mitsuba_scene import BACKGROUND_LABEL, BEACON_LABEL, TARGET_LABEL

_ID_COLOURS = {BACKGROUND_LABEL: (40, 40, 40), TARGET_LABEL: (230, 120, 20)}
_BEACON_COLOURS = ((240, 220, 40), (60, 200, 80), (220, 60, 200), (60, 200, 220),
                   (200, 60, 60), (150, 110, 240))
_GLASS_COLOUR = (70, 110, 190)


def colourise_ids(ids: np.ndarray, n_beacons: int) -> np.ndarray:
    """An RGB picture of :func:`encode_ids`' labels for a viewer (``<name>.ids.preview
    .png``): the labels themselves (0…~110) look black."""
    rgb = np.full((*ids.shape, 3), 128, np.uint8)  # occluders and anything unlisted
    colours = {**_ID_COLOURS, **{BEACON_LABEL + i: _BEACON_COLOURS[i % len(_BEACON_COLOURS)]
                                 for i in range(n_beacons)}}
    for label, colour in colours.items():
        rgb[ids == label] = colour
        rgb[ids == IN_MIRROR + label] = _lighter(colour)
    rgb[ids == IN_MIRROR + BACKGROUND_LABEL] = _GLASS_COLOUR
    return rgb


def _lighter(colour: tuple[int, int, int]) -> tuple[int, ...]:
    """How :func:`colourise_ids` shows what the mirror shows of an object."""
    return tuple(min(255, int(0.6 * c + 102)) for c in colour)


def id_preview(ids: np.ndarray, n_beacons: int) -> np.ndarray:
    """:func:`colourise_ids`' picture with a legend strip below it: a swatch and a name
    for each colour (the object seen directly, and lighter, in the mirror), so that the
    preview reads without docs/files.md beside it."""
    import cv2

    rgb = colourise_ids(ids, n_beacons)
    entries = [("background", _ID_COLOURS[BACKGROUND_LABEL]), ("glass", _GLASS_COLOUR),
               ("occluder", (128, 128, 128)), ("target", _ID_COLOURS[TARGET_LABEL]),
               ("target in mirror", _lighter(_ID_COLOURS[TARGET_LABEL]))]
    for i in range(n_beacons):
        colour = _BEACON_COLOURS[i % len(_BEACON_COLOURS)]
        entries += [(f"beacon {i}", colour), (f"beacon {i} in mirror", _lighter(colour))]
    width = rgb.shape[1]
    scale = max(0.35, width / 2400)  # legible on a 320 px frame and a 1920 px one
    row, pad = int(28 * scale / 0.5), int(8 * scale / 0.5)
    texts = [cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] for t, _ in entries]
    cell = max(texts) + row + 2 * pad
    per_row = max(1, width // cell)
    rows = -(-len(entries) // per_row)
    strip = np.full((rows * row + pad, width, 3), 255, np.uint8)
    for k, (text, colour) in enumerate(entries):
        x, y = (k % per_row) * cell + pad, (k // per_row) * row + pad
        swatch = row - pad
        strip[y:y + swatch, x:x + swatch] = colour
        cv2.rectangle(strip, (x, y), (x + swatch - 1, y + swatch - 1), (0, 0, 0), 1)
        cv2.putText(strip, text, (x + swatch + pad // 2, y + swatch - 2),
                    cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([rgb, strip], axis=0)
