"""One frame through the pipeline, written once: render → calibrate → detect.

Every command that measures a frame goes through here (and the benchmarks that do not
time the stages apart): :func:`measure_frame` for a frame on disk and its capture
record, :func:`render_and_measure` for a scene.  The detector is handed the capture
record (what the experimenter knows), never the scene.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from mirrorsim.camera.sensor import to_srgb8
from mirrorsim.detection.detector import Detection, detect_frame
from mirrorsim.detection.frame_files import read_stored_frame
from mirrorsim.detection.image_geometry import Calibration
from mirrorsim.errors import DetectionError
from mirrorsim.formats.capture import CaptureError, CaptureRecord, load_capture
from mirrorsim.formats.files import atomic_path, claim_run_folder, default_out
from mirrorsim.pipelines.calibrate import calibrate
from mirrorsim.pipelines.scenes import check_given_scene
from mirrorsim.rendering.backend import check_variant
from mirrorsim.rendering.frames import FrameFiles, capture_of, reused_frame, write_frame
from mirrorsim.rendering.passes import render_frame, scene_fingerprint
from mirrorsim.scene.model import Scene
from mirrorsim.scene.render_settings import AOVS


class FrameNotMeasured(DetectionError):
    """The detector found nothing usable in a frame: the message names the frame,
    ``reason`` is the detector's own words."""

    def __init__(self, where: str, reason: str):
        self.reason = reason
        super().__init__(f"{where}: {reason}")


@dataclass(frozen=True)
class MeasuredFrame:
    """A frame's pixels, the calibration it was measured with and what the detector found;
    ``files`` where the frame was rendered here."""

    image: np.ndarray
    calibration: Calibration
    detection: Detection
    files: FrameFiles | None = None


def calibration_for(capture: CaptureRecord, *, variant: str = "auto",
                    distance_error: float = 0.0, subsampled: bool = False) -> Calibration:
    """The size-constancy constants for the camera and objects a capture record names
    (``subsampled``: for its JPEG frames, which the detector measures otherwise; see
    :func:`~mirrorsim.detection.frame_files.read_stored_frame`).

    ``distance_error``: the bench's calibration error (cm), which a capture record cannot
    know; the simulator renders its calibration with it.

    Raises
    ------
    CaptureError
        If the record's beacons differ in height (see :func:`check_one_pencil_height`).
    """
    check_one_pencil_height(capture)
    return calibrate(capture.camera, capture.target_size, capture.beacons[0].height,
                     variant=variant, distance_error=distance_error, subsampled=subsampled)


def check_one_pencil_height(capture: CaptureRecord) -> None:
    """Refuse a frame whose pencils differ in height: one calibration measures one
    pencil's K, and every beacon's d_total would be scaled by the first's (a 6 cm pencil,
    4.8 cm of paint, beside a 4.2 cm one, 3.0 cm, would read 37.5 % near).  ``evaluate``
    renders each beacon in a frame of its own, with its own K."""
    heights = sorted({b.height for b in capture.beacons})
    if len(heights) > 1:
        raise CaptureError(capture.frame or "<capture record>", "beacons",
                           f"pencils of {', '.join(f'{h:g}' for h in heights)} cm in one "
                           "frame: a calibration measures one pencil height; render and "
                           "detect each beacon in a frame of its own (evaluate does)")


def check_pair(image_path: str | Path, found: str, capture: CaptureRecord,
               *, named: str | Path) -> None:
    """Refuse a frame (its bytes' SHA-256 ``found``) that is not the one its capture
    record was written with (the record's ``frame_sha256``, where it has one): beacon 1's
    record with beacon 0's frame was measured with the wrong believed position, without
    a word.  A frame renamed with its own record passes: the bytes decide, not the name."""
    if capture.frame_sha256 and found != capture.frame_sha256:
        raise CaptureError(named, "frame_sha256",
                           f"the record of frame {capture.frame or 'another frame'!r}, not of "
                           f"{str(image_path)!r} (its bytes differ): give the frame's own "
                           "capture record")


def measure_frame(image_path: str | Path, capture: CaptureRecord | str | Path, *,
                  calibration: Calibration | None = None, variant: str = "auto",
                  distance_error: float = 0.0, source: str = "",
                  pixels: np.ndarray | None = None) -> MeasuredFrame:
    """Calibrate (unless given) and detect one frame from its pixels and capture record
    (``capture``: the record, or its ``.capture.json`` file; ``pixels``: the file's pixels
    already in memory, a PNG just written).

    Raises
    ------
    InputError
        If the frame's file is missing, not a PNG or JPEG, damaged, or not of the
        capture record's camera size.
    FrameNotMeasured
        Naming the frame (and ``source``, where given) when nothing usable is found.
    DetectionError
        When the calibration's own references cannot be measured.
    """
    named = capture if isinstance(capture, str | Path) else capture.frame or "<capture record>"
    if isinstance(capture, str | Path):  # its file, read and checked (CaptureError)
        capture = load_capture(capture)
    if calibration is None:  # before the frame is read: a refusal costs nothing
        check_one_pencil_height(capture)
    cam = capture.camera
    if pixels is None:
        stored = read_stored_frame(image_path, (cam.width, cam.height_px))
        check_pair(image_path, stored.sha256, capture, named=named)  # before the calibration
        image, lossy, quality = stored.pixels, stored.subsampled, stored.jpeg_quality
    else:  # a lossless PNG just made
        image, lossy, quality = pixels, False, 0
    cal = calibration or calibration_for(capture, variant=variant,
                                         distance_error=distance_error, subsampled=lossy)
    try:
        det = detect_frame(image, capture, cal, subsampled=lossy,
                           jpeg_quality=quality)  # never the scene
    except DetectionError as exc:
        where = f"{image_path} ({source})" if source else str(image_path)
        raise FrameNotMeasured(where, str(exc)) from None
    return MeasuredFrame(image, cal, det)


def render_and_measure(scene: Scene, out: str | Path, *, variant: str = "auto",
                       progress: bool = True, reuse: bool = True, ids: bool = True,
                       calibration: Calibration | None = None,
                       aov: tuple[str, ...] = ()) -> MeasuredFrame:
    """Render ``scene`` into ``out`` (or reuse its render), then :func:`measure_frame`;
    ``aov``: the frame's depth and normals besides (:mod:`mirrorsim.rendering.aov`)."""
    out = Path(out)
    measure = partial(measure_frame, calibration=calibration, variant=variant,
                      distance_error=scene.bench.calibration_distance_error)
    files = reused_frame(scene, out, ids) if reuse else None
    write_aovs(scene, out, aov, variant=variant, fresh=files is None)
    if files is not None:
        return replace(measure(files.image, files.capture), files=files)
    frame = render_frame(scene, variant=variant, progress=progress)
    write = partial(write_frame, scene, frame, out, fingerprint=scene_fingerprint(scene), ids=ids)
    if scene.bench.jpeg_quality is not None:  # the detector must see a JPEG as decoded
        files = write()
        return replace(measure(files.image, files.capture), files=files)
    # a lossless frame is measured from its pixels in memory while a second thread
    # encodes and writes its files (PNG encoding and detection each hold one core)
    srgb = to_srgb8(frame.linear)
    capture = capture_of(scene, out)
    with ThreadPoolExecutor(1) as pool:
        writing = pool.submit(write, srgb=srgb)
        try:
            m = measure(out / capture.frame, capture, pixels=srgb)
        finally:
            files = writing.result()  # the files are whole, measured or not
    return replace(m, files=files)


def write_aovs(scene: Scene, out: Path, names: tuple[str, ...], *, variant: str,
               fresh: bool = True) -> None:
    """``out/<frame>.<name>.npy`` for each of ``names`` (float32 arrays).  ``fresh``: the
    frame is rendered now, so that any such file of an earlier render of that name is
    not its own: each is made again, or removed where not asked for; otherwise (a
    frame reused) only those missing are made."""
    from mirrorsim.rendering.aov import render_aovs

    if fresh:
        for name in set(AOVS) - set(names):
            (out / f"{scene.name}.{name}.npy").unlink(missing_ok=True)
    todo = [n for n in names if fresh or not (out / f"{scene.name}.{n}.npy").exists()]
    if not todo:
        return
    out.mkdir(parents=True, exist_ok=True)
    for name, array in render_aovs(scene, tuple(todo), variant=variant).items():
        with atomic_path(out / f"{scene.name}.{name}.npy") as tmp, open(tmp, "wb") as fh:
            np.save(fh, array, allow_pickle=False)


def render_to_files(scene: Scene, out: str | Path | None = None, *, variant: str = "auto",
                    progress: bool = True, reuse: bool = False, ids: bool = True
                    ) -> FrameFiles:
    """Render ``scene`` with its render settings (or, with ``reuse``, take a render of
    exactly this scene already in ``out``) and write its files (default folder
    ``renders/<name>/``; the id labels only with ``ids``)."""
    check_given_scene(scene)  # edited by a script: held to what its file would make
    check_variant(variant)
    out = claim_run_folder(out if out is not None else default_out(scene.name), "out",
                           [("scene", scene.source)])
    found = reused_frame(scene, out, ids) if reuse else None
    if found is not None:
        return found
    frame = render_frame(scene, variant=variant, progress=progress)
    return write_frame(scene, frame, out, fingerprint=scene_fingerprint(scene), ids=ids)
