"""The capture record: what the experimenter knows about a frame (docs/files.md).

``render`` writes ``<name>.capture.json`` beside each frame; the detector reads only it
and the pixels.  It holds the camera as its mount reports it (position, height, pan,
intrinsics), where the beacons are believed to stand and how tall they are, the
target's size, and the calibration's reference distance; never the mirror or where the
target stands.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from mirrorsim.errors import InputError
from mirrorsim.formats.reader import Reader, point_list, read_json, read_resolution, show
from mirrorsim.scene.model import MAX_HFOV_DEG, Beacon, Board, Camera, Point2, Scene, fx_of
from mirrorsim.scene.projection import hfov_of

REFERENCE_DISTANCE = 100.0  # cm: where calibration stands its reference objects
GEOMETRIES = ("planar", "3d")  # how a frame's set-up is solved (docs/method.md)


def read_board(r: Reader, raw: Any, required: tuple[str, ...] = ("size",),
               *, optional: tuple[str, ...] = ("hole_pitch",)) -> Board:
    """A ``board`` block: a scene file's (its size, and its hole pitch, 2.5 cm unless
    given) or a capture record's (which names the holes' diameter too)."""
    b = r.mapping(raw, "board", required, optional=optional)
    d = Board((1.0, 1.0))  # the defaults
    return r.built("board", Board, size=r.pair(b["size"], "board.size"),
                   hole_pitch=r.number(b.get("hole_pitch", d.hole_pitch), "board.hole_pitch"),
                   hole_diameter=r.number(b.get("hole_diameter", d.hole_diameter),
                                          "board.hole_diameter"))


def read_distortion(r: Reader, raw: Any, key: str) -> tuple[float, float]:
    """A lens's [k1, k2] (scene files and capture records alike)."""
    if not isinstance(raw, list) or len(raw) != 2:
        raise r.fail(key, f"expected [k1, k2], got {show(raw)}")
    return (r.number(raw[0], f"{key}[0]", low=-1.0, high=1.0),
            r.number(raw[1], f"{key}[1]", low=-1.0, high=1.0))


class CaptureError(InputError):
    """A bad capture record."""


@dataclass(frozen=True)
class CaptureRecord:
    """All the detector may know about a frame."""

    camera: Camera
    beacons: tuple[Beacon, ...]
    target_size: Point2
    frame: str = ""
    reference_distance: float = REFERENCE_DISTANCE
    distortion: tuple[float, float] = (0.0, 0.0)  # the lens's k1, k2 as calibrated
    # the pegboard the camera stands on, as built (its size and hole grid): what measures
    # the camera's pose (mirrorsim.detection.board); None in a record made before it
    board: Board | None = None
    # the SHA-256 of the frame file this record was written with ('' where unknown: a
    # hand-written record): `detect` refuses a frame whose bytes differ, the record of
    # another frame (beacon 1's record with beacon 0's frame gave a wrong position)
    frame_sha256: str = ""
    # "3d": objects may stand off the board and the mirror lean (docs/method.md), so the
    # detector holds no image to the board's plane; "planar" otherwise
    geometry: str = "planar"

    @classmethod
    def from_scene(cls, scene: Scene, frame: str = "") -> CaptureRecord:
        """What an experimenter of this scene knows: its camera as the mount reports it
        (the pan as a bearing, off by the bench's pan error; level), the lens distortion
        if it was calibrated, where the beacons are believed to stand, the target's size."""
        bench = scene.bench
        reported = scene.camera.pan_deg + bench.pan_error
        camera = replace(scene.camera, pan=reported, pan_deg=reported)
        beacons = tuple(Beacon(b.believed, b.height, z=b.z) for b in scene.beacons)
        return cls(camera=camera, beacons=beacons, target_size=scene.target.size,
                   frame=frame, geometry="3d" if scene.is_3d else "planar",
                   distortion=bench.distortion if bench.distortion_known else (0.0, 0.0),
                   board=scene.board)

    def to_json(self) -> dict:
        """The capture record document."""
        c = self.camera
        return {"frame": self.frame,
                "camera": {"position": list(c.position), "height": c.height,
                           "pan_deg": c.pan_deg, "resolution": list(c.resolution),
                           "fx": c.fx, "fy": c.fx, "cx": c.cx, "cy": c.cy,
                           "hfov_deg": c.hfov, "distortion": list(self.distortion)},
                "beacons": [{"position": point_list(b.position, b.z),
                             "height": b.height} for b in self.beacons],
                "target": {"size": list(self.target_size)},
                "calibration": {"reference_distance": self.reference_distance},
                **({"board": {"size": list(self.board.size),
                              "hole_pitch": self.board.hole_pitch,
                              "hole_diameter": self.board.hole_diameter}}
                   if self.board is not None else {}),
                **({"frame_sha256": self.frame_sha256} if self.frame_sha256 else {}),
                **({"geometry": self.geometry} if self.geometry != "planar" else {})}

    @classmethod
    def from_json(cls, data: Any, source: str | Path = "<capture>") -> CaptureRecord:
        """Parse and check a record (raises :class:`CaptureError` naming file and key)."""
        r = Reader(source, CaptureError)
        top = r.mapping(data, "", ("camera", "beacons", "target"),
                        optional=("frame", "calibration", "board", "frame_sha256", "geometry"))
        c = r.mapping(top["camera"], "camera", ("position", "height", "pan_deg", "resolution",
                                                "fx"),
                      optional=("fy", "cx", "cy", "hfov_deg", "distortion"))
        resolution = read_resolution(r, c["resolution"], "camera.resolution")
        fx = r.number(c["fx"], "camera.fx", positive=True)
        hfov = (r.number(c["hfov_deg"], "camera.hfov_deg", positive=True, high=MAX_HFOV_DEG)
                if "hfov_deg" in c else hfov_of(resolution[0], fx))
        if abs(fx_of(resolution[0], hfov) - fx) > 1e-6 * fx:
            raise r.fail("camera.fx", f"{fx:g} disagrees with hfov_deg {hfov:g} (square "
                         "pixels, the principal point at the centre)")
        distortion = (read_distortion(r, c["distortion"], "camera.distortion")
                      if "distortion" in c else (0.0, 0.0))
        pan = r.number(c["pan_deg"], "camera.pan_deg")
        camera = r.built("camera", Camera, position=r.pair(c["position"], "camera.position"),
                         height=r.number(c["height"], "camera.height"),
                         resolution=resolution, hfov=hfov, pan=pan, pan_deg=pan)
        if not isinstance(top["beacons"], list) or not top["beacons"]:
            raise r.fail("beacons", "expected a non-empty list")
        beacons = []
        for i, b in enumerate(top["beacons"]):
            b = r.mapping(b, f"beacons[{i}]", ("position", "height"))
            position, z = r.point(b["position"], f"beacons[{i}].position")
            beacons.append(r.built(f"beacons[{i}]", Beacon, position=position, z=z,
                                   height=r.number(b["height"], f"beacons[{i}].height")))
        t = r.mapping(top["target"], "target", ("size",))
        cal = r.mapping(top.get("calibration", {}), "calibration", (),
                        optional=("reference_distance",))
        board = (read_board(r, top["board"], ("size", "hole_pitch", "hole_diameter"), optional=())
                 if "board" in top else None)
        geometry = top.get("geometry", "planar")
        if geometry not in GEOMETRIES:
            raise r.fail("geometry", f"{show(geometry)}: expected one of {', '.join(GEOMETRIES)}")
        sha = top.get("frame_sha256", "")
        if not (isinstance(sha, str) and (sha == "" or re.fullmatch(r"[0-9a-f]{64}", sha))):
            raise r.fail("frame_sha256", f"{sha!r} is not a SHA-256 (64 hexadecimal digits)")
        return cls(camera=camera, beacons=tuple(beacons), board=board, geometry=geometry,
                   target_size=r.pair(t["size"], "target.size", positive=True),
                   frame=str(top.get("frame", "")), distortion=distortion, frame_sha256=sha,
                   reference_distance=r.number(cal.get("reference_distance", REFERENCE_DISTANCE),
                                               "calibration.reference_distance",
                                               positive=True))


def load_capture(path: str | Path) -> CaptureRecord:
    """Read a ``<name>.capture.json`` (raises CaptureError)."""
    return CaptureRecord.from_json(read_json(path, CaptureError), path)
