"""A rendered frame's files: ``<name>.png`` (or ``.jpg``), the ground truth
``<name>.json``, the capture record and the object ids ``<name>.ids.png``; computed
once, written atomically, reused by fingerprint once verified.

The truth file records the SHA-256 of each file written with it and a checksum of its
own contents (``sha256``), so a cached frame that was damaged, truncated or swapped for
another render is not reused: it is rendered again, with a ``warning:`` line.
"""

from __future__ import annotations

import contextlib
import hashlib
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mirrorsim.camera.sensor import to_srgb8
from mirrorsim.formats.cache import seal
from mirrorsim.formats.capture import CaptureRecord, load_capture
from mirrorsim.formats.files import (
    atomic_path,
    dumps,
    encode_jpeg,
    encode_png,
    frame_suffix,
    read_regular_bytes,
)
from mirrorsim.rendering.id_pass import IN_MIRROR, encode_ids
from mirrorsim.rendering.id_preview import id_preview
from mirrorsim.rendering.mitsuba_scene import (
    BACKGROUND_LABEL,
    BEACON_LABEL,
    MIRROR_LABEL,
    TARGET_LABEL,
)
from mirrorsim.rendering.passes import RenderedFrame, scene_fingerprint
from mirrorsim.scene.model import Scene
from mirrorsim.truth import groundtruth
from mirrorsim.truth.annotations import frame_annotations
from mirrorsim.truth.groundtruth import GroundTruth, MirrorPixels, load_truth


@dataclass(frozen=True)
class FrameFiles:
    """A frame on disk, its capture record (what the detector may know) and its ground
    truth (for scoring only)."""

    image: Path  # the frame: PNG, or JPEG for a bench that stores JPEG
    truth_json: Path
    ids_png: Path | None  # None: not kept (a dataset's --keep)
    capture_json: Path
    capture: CaptureRecord
    truth: GroundTruth
    reused: bool = False
    # the frame's 8-bit RGB pixels as written to a lossless PNG just now (None: reused, or
    # a JPEG, which the detector must see as decoded): detection need not decode it again
    pixels: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def seconds(self) -> float:
        """Wall time of the render (0 if reused)."""
        r = self.truth.render
        return 0.0 if self.reused or r is None or r.seconds_total is None else r.seconds_total


def truth_of(scene: Scene, frame: RenderedFrame, fingerprint: str | None) -> GroundTruth:
    """The exact ground truth with what the id pass saw of each object."""
    truth = groundtruth.ground_truth(scene)

    def seen(obj, label: int):
        bbox, n = _mask_stats(frame.in_mirror == label)
        return replace(obj, bbox_px=bbox, visible_px=n)

    return replace(
        truth,
        annotations=frame_annotations(scene, frame.first, frame.in_mirror,
                                      labels=object_labels(scene)),
        target=seen(truth.target, TARGET_LABEL),
        beacons=tuple(seen(b, BEACON_LABEL + i) for i, b in enumerate(truth.beacons)),
        mirror_pixels=MirrorPixels(*_mask_stats(frame.first == MIRROR_LABEL)),
        id_labels={"background": BACKGROUND_LABEL, "mirror": MIRROR_LABEL,
                   "target": TARGET_LABEL, "beacons": BEACON_LABEL,
                   "occluders": BEACON_LABEL + len(scene.beacons),
                   "seen_in_mirror_offset": IN_MIRROR},
        render=replace(frame.info, fingerprint=fingerprint))


def object_labels(scene: Scene) -> dict[str, int]:
    """Each object's label in the id pass, by its name in the annotations."""
    return {"target": TARGET_LABEL, "mirror": MIRROR_LABEL,
            **{f"beacons[{i}]": BEACON_LABEL + i for i in range(len(scene.beacons))}}


def write_frame(scene: Scene, frame: RenderedFrame, out: Path,
                *, fingerprint: str | None = None, ids: bool = True,
                srgb: np.ndarray | None = None) -> FrameFiles:
    """Write the frame, its capture record, its truth and (``ids``) its id labels into
    ``out``; they appear together.  ``srgb``: the frame's 8-bit pixels, if the caller
    has converted them already."""
    out.mkdir(parents=True, exist_ok=True)
    truth = truth_of(scene, frame, fingerprint)
    image, ids_png, js, cap = _paths(scene, out)
    srgb = to_srgb8(frame.linear) if srgb is None else srgb
    quality = scene.bench.jpeg_quality
    encoded = encode_png(srgb) if quality is None else encode_jpeg(srgb, quality)
    # the record names its frame's bytes: a record paired with another frame is refused
    capture = replace(capture_of(scene, out), frame_sha256=hashlib.sha256(encoded).hexdigest())
    files = {image: encoded, cap: dumps(capture.to_json()).encode()}
    if ids:
        labels = encode_ids(frame.first, frame.in_mirror)
        files[ids_png] = encode_png(labels)
        files[ids_png.with_suffix(".preview.png")] = encode_png(
            id_preview(labels, len(scene.beacons)))
    truth = replace(truth, render=replace(truth.render, files={
        p.name: hashlib.sha256(data).hexdigest() for p, data in files.items()}))
    files[js] = dumps(seal(truth.to_json())).encode()
    with contextlib.ExitStack() as stack:
        for path, data in files.items():
            stack.enter_context(atomic_path(path)).write_bytes(data)
    return FrameFiles(image=image, truth_json=js, ids_png=ids_png if ids else None,
                      capture_json=cap, capture=capture, truth=truth,
                      pixels=srgb if quality is None else None)


def capture_of(scene: Scene, out: Path) -> CaptureRecord:
    """The capture record of ``scene``'s frame written into ``out``."""
    return CaptureRecord.from_scene(scene, frame=_paths(scene, out)[0].name)


def _paths(scene: Scene, out: Path) -> tuple[Path, Path, Path, Path]:
    """The frame (PNG, or JPEG for a bench that stores JPEG), its ids, its truth and its
    capture record."""
    frame = frame_suffix(scene.bench.jpeg_quality)
    return tuple(out / f"{scene.name}{ext}"
                 for ext in (frame, ".ids.png", ".json", ".capture.json"))


def reused_frame(scene: Scene, out: Path, ids: bool) -> FrameFiles | None:
    """The verified frame of exactly this scene already in ``out`` (with its id labels
    where ``ids`` asks for them), or None."""
    found = _reusable(scene, out, scene_fingerprint(scene))
    return found if found is not None and (found.ids_png is not None or not ids) else None


def _reusable(scene: Scene, out: Path, fingerprint: str) -> FrameFiles | None:
    """The frame of exactly this scene already in ``out``, verified; None (with a warning
    where files are there but fail verification) to render it again."""
    image, ids, js, cap = _paths(scene, out)
    if not (image.exists() and js.exists() and cap.exists()):
        return None
    try:
        truth = load_truth(js)
    except (OSError, ValueError, KeyError, TypeError, RecursionError) as exc:
        return _rerender(image, str(exc))
    if truth.render is None or truth.render.fingerprint != fingerprint:
        return None  # another scene's (or another version's) frame: simply rendered anew
    try:
        digests = truth.render.files or {}
        # the id labels are optional (a dataset keeps them on request): checked if there
        have_ids = ids.name in digests and ids.exists()
        for path in (image, cap, *((ids,) if have_ids else ())):
            if digests.get(path.name) != hashlib.sha256(read_regular_bytes(path)).hexdigest():
                raise ValueError(f"{path.name}'s bytes do not match the hash in {js.name}")
        capture = load_capture(cap)
    except (OSError, ValueError, KeyError, TypeError) as exc:  # CaptureError: a ValueError
        return _rerender(image, str(exc))
    if replace(capture, frame_sha256="") != capture_of(scene, out):
        return None  # a record an older mirrorsim wrote (without the board): made anew
    return FrameFiles(image=image, truth_json=js, ids_png=ids if have_ids else None,
                      capture_json=cap, capture=capture, truth=truth, reused=True)


def _rerender(image: Path, why: str) -> None:
    warnings.warn(f"cached frame {str(image)!r} not trusted ({why}); rendering it again",
                  RuntimeWarning, stacklevel=3)
    return None


def _mask_stats(mask: np.ndarray) -> tuple[tuple[int, int, int, int] | None, int]:
    vs, us = np.nonzero(mask)
    if len(us) == 0:
        return None, 0
    return (int(us.min()), int(vs.min()), int(us.max()), int(vs.max())), int(len(us))
