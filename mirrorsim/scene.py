"""The scene model: load a YAML scene, validate it, and place every object in 3-D.

A :class:`Scene` is plain data.  :func:`load_scene` turns a file into one or raises
:class:`SceneError`, whose message names the file, the key path and the bad value.
The geometric checks (edge-on mirror, objects behind it, images that do not reach
the camera) use :mod:`mirrorsim.optics`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from solver.geometry import bearing_deg, segment_distance, signed_distance, unit
from solver.measurements import InputError

# Physical dimensions of the rendered objects that the scene file does not set (cm).
# They enter the overlap checks, so they live here rather than in the renderer.
MIRROR_DEPTH = 0.6  # glass + dark backing + frame, behind the reflective plane
MIRROR_FRAME = 0.5  # frame width on the sides and top, outside the reflective area
TARGET_THICKNESS = 0.4
PENCIL_RADIUS = 0.4  # circumradius of the hexagonal pencil (0.69 cm across flats)
OCCLUDER_THICKNESS = 1.0
EDGE_ON_LIMIT_DEG = 5.0  # a mirror seen at a more grazing angle than this is edge-on

PAN_WORDS = ("mirror", "target", "beacon")


class SceneError(InputError):
    """A bad scene file: ``str(err)`` is the one-line message for the user."""


@dataclass(frozen=True)
class Board:
    size: tuple[float, float]
    hole_pitch: float = 2.5
    hole_diameter: float = 0.6


@dataclass(frozen=True)
class Camera:
    position: tuple[float, float]
    height: float
    resolution: tuple[int, int]
    hfov: float
    pan: float | str  # as written: a bearing or one of PAN_WORDS
    pan_deg: float = float("nan")  # resolved bearing of the optical axis

    @property
    def width(self) -> int:
        return self.resolution[0]

    @property
    def height_px(self) -> int:
        return self.resolution[1]

    @property
    def fx(self) -> float:
        """Focal length in px: (W/2)/tan(hfov/2); square pixels, so fy = fx."""
        return (self.width / 2.0) / math.tan(math.radians(self.hfov) / 2.0)

    @property
    def cx(self) -> float:
        """Principal point, OpenCV convention (pixel centres at integers)."""
        return self.width / 2.0 - 0.5

    @property
    def cy(self) -> float:
        return self.height_px / 2.0 - 0.5

    @property
    def center3(self) -> np.ndarray:
        """Optical centre in 3-D."""
        return np.array([self.position[0], self.position[1], self.height])


@dataclass(frozen=True)
class Mirror:
    center: tuple[float, float]
    yaw: float
    size: tuple[float, float]  # width along the surface line, height

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """The two ends of the reflective bottom edge."""
        c, d = np.asarray(self.center, float), unit(self.yaw) * self.size[0] / 2.0
        return c - d, c + d


@dataclass(frozen=True)
class Target:
    position: tuple[float, float]
    size: tuple[float, float]  # width, height
    facing_deg: float = float("nan")  # bearing of the panel's front normal (set by load)

    @property
    def height(self) -> float:
        return self.size[1]

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """Ends of the panel's footprint (its width runs across the facing direction)."""
        p, d = np.asarray(self.position, float), unit(self.facing_deg + 90.0) * self.size[0] / 2
        return p - d, p + d


@dataclass(frozen=True)
class Beacon:
    position: tuple[float, float]
    height: float


@dataclass(frozen=True)
class Occluder:
    start: tuple[float, float]
    end: tuple[float, float]
    height: float


@dataclass(frozen=True)
class RenderSettings:
    spp: int = 16
    seed: int = 0


@dataclass(frozen=True)
class Scene:
    """A validated scene.  Build one with :func:`load_scene` or :func:`scene_from_dict`."""

    name: str
    board: Board
    camera: Camera
    mirror: Mirror
    target: Target
    beacons: tuple[Beacon, ...]
    occluders: tuple[Occluder, ...] = ()
    render: RenderSettings = field(default_factory=RenderSettings)
    source: str = "<scene>"
    warnings: tuple[str, ...] = ()


# --------------------------------------------------------------------------- YAML


class _StrictLoader(yaml.SafeLoader):
    """Safe loading that also refuses duplicate keys (a silent override otherwise)."""


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False):
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep)


_StrictLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping
)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file.

    Raises
    ------
    SceneError
        For any bad input, with the file, the key path and what is wrong.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SceneError(path, "", "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(path, "", f"cannot read: {exc}") from None
    try:
        data = yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SceneError(path, "", f"malformed YAML: {where}{problem}") from None
    return scene_from_dict(data, source=str(path), default_name=path.stem)


# ------------------------------------------------------------------ typed readers


class _Reader:
    """Reads typed values from the parsed YAML, raising SceneError with key paths."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, message: str) -> SceneError:
        return SceneError(self.source, key, message)

    def mapping(self, value: Any, key: str, required: set[str], optional: set[str]) -> dict:
        if not isinstance(value, dict):
            raise self.fail(key or "(top level)", f"expected a mapping, got {_show(value)}")
        prefix = f"{key}." if key else ""
        for k in value:
            if not isinstance(k, str) or k not in required | optional:
                allowed = ", ".join(sorted(required | optional))
                raise self.fail(f"{prefix}{k}", f"unknown key (allowed here: {allowed})")
        for k in sorted(required):
            if k not in value:
                raise self.fail(f"{prefix}{k}", "missing required key")
        return value

    def number(self, value: Any, key: str, *, positive: bool = False, low: float | None = None,
               high: float | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"expected a number, got {_show(value)}")
        v = float(value)
        if not math.isfinite(v):
            raise self.fail(key, f"{_show(value)} is not a finite number")
        if positive and v <= 0.0:
            raise self.fail(key, f"{_show(value)} must be > 0")
        if low is not None and v < low:
            raise self.fail(key, f"{_show(value)} must be ≥ {low:g}")
        if high is not None and v > high:
            raise self.fail(key, f"{_show(value)} must be ≤ {high:g}")
        return v

    def integer(self, value: Any, key: str, *, low: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"expected an integer, got {_show(value)}")
        if value < low:
            raise self.fail(key, f"{value} must be ≥ {low}")
        return value

    def pair(self, value: Any, key: str, *, positive: bool = False) -> tuple[float, float]:
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise self.fail(key, f"expected a list of two numbers, got {_show(value)}")
        return (
            self.number(value[0], f"{key}[0]", positive=positive),
            self.number(value[1], f"{key}[1]", positive=positive),
        )


def _show(value: Any) -> str:
    """A short rendering of a YAML value for error messages."""
    if isinstance(value, str):
        return repr(value) if len(value) <= 40 else repr(value[:37] + "...")
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list) and len(value) > 4:
        return f"a list of {len(value)} items"
    if value is None:
        return "nothing (null)"
    return str(value)


# ------------------------------------------------------------------- construction


def scene_from_dict(data: Any, source: str = "<scene>", default_name: str = "scene") -> Scene:
    """Build and validate a :class:`Scene` from parsed YAML (see INTERFACE.md)."""
    r = _Reader(source)
    top = r.mapping(
        data, "",
        required={"board", "camera", "mirror", "target"},
        optional={"name", "beacon", "beacons", "occluders", "render"},
    )
    name = top.get("name", default_name)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}", name):
        raise r.fail("name", f"{_show(name)} is not a plain file name "
                     "(letters, digits, '.', '_', '-'; no path)")

    b = r.mapping(top["board"], "board", {"size"}, {"hole_pitch"})
    board = Board(
        size=r.pair(b["size"], "board.size", positive=True),
        hole_pitch=r.number(b.get("hole_pitch", 2.5), "board.hole_pitch", low=0.0),
    )
    if 0.0 < board.hole_pitch <= board.hole_diameter:
        raise r.fail("board.hole_pitch", f"{board.hole_pitch:g} must exceed the hole diameter "
                     f"{board.hole_diameter:g} cm (or be 0 for a plain board)")

    c = r.mapping(top["camera"], "camera", {"position", "height", "hfov", "pan"}, {"resolution"})
    pan = c["pan"]
    if isinstance(pan, str):
        if pan not in PAN_WORDS:
            raise r.fail("camera.pan", f"{_show(pan)}: expected a bearing in degrees or one of "
                         f"{', '.join(PAN_WORDS)}")
    else:
        pan = r.number(pan, "camera.pan")
    res = c.get("resolution", [1920, 1088])
    if not isinstance(res, list) or len(res) != 2:
        raise r.fail("camera.resolution", f"expected [width, height] in px, got {_show(res)}")
    camera = Camera(
        position=r.pair(c["position"], "camera.position"),
        height=r.number(c["height"], "camera.height", positive=True),
        resolution=(r.integer(res[0], "camera.resolution[0]", low=2),
                    r.integer(res[1], "camera.resolution[1]", low=2)),
        hfov=r.number(c["hfov"], "camera.hfov", positive=True, high=170.0),
        pan=pan,
    )

    m = r.mapping(top["mirror"], "mirror", {"center", "yaw", "size"}, set())
    mirror = Mirror(
        center=r.pair(m["center"], "mirror.center"),
        yaw=r.number(m["yaw"], "mirror.yaw"),
        size=r.pair(m["size"], "mirror.size", positive=True),
    )

    t = r.mapping(top["target"], "target", {"position", "size"}, set())
    target = Target(
        position=r.pair(t["position"], "target.position"),
        size=r.pair(t["size"], "target.size", positive=True),
    )

    if ("beacon" in top) == ("beacons" in top):
        raise r.fail("beacon", "give exactly one of `beacon:` or `beacons:`")
    if "beacon" in top:
        raw_beacons, bkey = [top["beacon"]], lambda i: "beacon"
    else:
        raw_beacons, bkey = top["beacons"], lambda i: f"beacons[{i}]"
        if not isinstance(raw_beacons, list) or not raw_beacons:
            raise r.fail("beacons", f"expected a non-empty list, got {_show(raw_beacons)}")
    beacons = []
    for i, raw in enumerate(raw_beacons):
        bb = r.mapping(raw, bkey(i), {"position", "height"}, set())
        beacons.append(Beacon(
            position=r.pair(bb["position"], f"{bkey(i)}.position"),
            height=r.number(bb["height"], f"{bkey(i)}.height", positive=True),
        ))

    raw_occ = top.get("occluders", [])
    if not isinstance(raw_occ, list):
        raise r.fail("occluders", f"expected a list, got {_show(raw_occ)}")
    occluders = []
    for i, raw in enumerate(raw_occ):
        o = r.mapping(raw, f"occluders[{i}]", {"start", "end", "height"}, set())
        occ = Occluder(
            start=r.pair(o["start"], f"occluders[{i}].start"),
            end=r.pair(o["end"], f"occluders[{i}].end"),
            height=r.number(o["height"], f"occluders[{i}].height", positive=True),
        )
        if np.hypot(occ.end[0] - occ.start[0], occ.end[1] - occ.start[1]) < 0.1:
            raise r.fail(f"occluders[{i}].end", f"{list(occ.end)}: the wall has no length")
        occluders.append(occ)

    rs = RenderSettings()
    if "render" in top:
        rr = r.mapping(top["render"], "render", set(), {"spp", "seed"})
        rs = RenderSettings(
            spp=r.integer(rr.get("spp", rs.spp), "render.spp", low=1),
            seed=r.integer(rr.get("seed", rs.seed), "render.seed", low=0),
        )

    scene = Scene(name=name, board=board, camera=camera, mirror=mirror, target=target,
                  beacons=tuple(beacons), occluders=tuple(occluders), render=rs, source=source)
    return _validate_geometry(scene, r, bkey)


def _validate_geometry(scene: Scene, r: _Reader, bkey) -> Scene:
    """Board bounds, mirror orientation, overlaps and visibility; resolve derived fields."""
    from mirrorsim import optics  # optics needs the model above; imported late on purpose

    W, H = scene.board.size

    def on_board(p, key: str, what: str) -> None:
        tol = 1e-9
        if not (-tol <= p[0] <= W + tol and -tol <= p[1] <= H + tol):
            raise r.fail(key, f"{_fmt(p)}: {what} lies off the board [0, {W:g}] × [0, {H:g}]")

    on_board(scene.camera.position, "camera.position", "the camera")
    on_board(scene.mirror.center, "mirror.center", "the mirror")
    for end in scene.mirror.ends():
        on_board(end, "mirror.center", f"the mirror's end {_fmt(end)}")
    on_board(scene.target.position, "target.position", "the target")
    for i, b in enumerate(scene.beacons):
        on_board(b.position, f"{bkey(i)}.position", "the beacon")
    for i, o in enumerate(scene.occluders):
        on_board(o.start, f"occluders[{i}].start", "the wall's start")
        on_board(o.end, f"occluders[{i}].end", "the wall's end")

    # The reflective face is the one turned towards the camera; a camera on the line
    # (or nearly so) sees the mirror edge-on.
    cam = np.asarray(scene.camera.position, float)
    cam_side = float(signed_distance(cam, scene.mirror.center, scene.mirror.yaw))
    to_center = np.asarray(scene.mirror.center, float) - cam
    dist = float(np.hypot(*to_center))
    graze = math.degrees(math.asin(min(1.0, abs(cam_side) / dist))) if dist > 0 else 0.0
    if graze < EDGE_ON_LIMIT_DEG:
        raise r.fail("mirror.yaw", f"{scene.mirror.yaw:g}: the camera sees the mirror edge-on "
                     f"(line of sight {graze:.2f}° off its surface; need ≥ {EDGE_ON_LIMIT_DEG:g}°)")

    def in_front(p, key: str, what: str) -> None:
        s = float(signed_distance(p, scene.mirror.center, scene.mirror.yaw))
        if s * cam_side <= 0.0:
            raise r.fail(key, f"{_fmt(p)}: the {what} stands behind the mirror (on its back, "
                         f"{abs(s):.2f} cm from its surface line), so the mirror cannot show it")

    in_front(scene.target.position, "target.position", "target")
    for i, b in enumerate(scene.beacons):
        in_front(b.position, f"{bkey(i)}.position", "beacon")

    # The panel faces its reflection point, i.e. the camera's virtual image, so the
    # camera sees its face square-on in the mirror.
    rp = optics.mirror_image(scene.camera, scene.mirror, scene.target.position).reflection_point
    facing = math.degrees(math.atan2(rp[1] - scene.target.position[1],
                                     rp[0] - scene.target.position[0]))
    scene = replace(scene, target=Target(scene.target.position, scene.target.size, facing))
    for end in scene.target.ends():
        on_board(end, "target.position", f"the target panel's edge {_fmt(end)}")

    _check_overlaps(scene, r, bkey)

    scene = replace(scene, camera=_resolve_pan(scene))
    warnings = []
    for key, obj, what in _sighted(scene, bkey):
        vis = optics.visibility(scene, obj)
        if vis.axis_fraction == 0.0:
            raise r.fail(key, f"{_fmt(obj.position)}: the {what}'s image does not reach the "
                         f"camera through the mirror: {vis.reason}")
        if vis.clipped:
            warnings.append(f"{key}: the {what}'s image is clipped ({vis.reason})")
    direct = optics.direct_view_fraction(scene, scene.target)
    if direct > 0.0:
        warnings.append(f"target.position: the camera also sees the target directly "
                        f"({100 * direct:.0f}% of its axis unobstructed): not an NLOS set-up")
    return replace(scene, warnings=tuple(warnings))


def _sighted(scene: Scene, bkey):
    yield "target.position", scene.target, "target"
    for i, b in enumerate(scene.beacons):
        yield f"{bkey(i)}.position", b, "beacon"


def _resolve_pan(scene: Scene) -> Camera:
    from mirrorsim import optics

    cam, pan = scene.camera, scene.camera.pan
    if pan == "mirror":
        pan_deg = float(bearing_deg(cam.position, scene.mirror.center))
    elif pan == "target":
        pan_deg = optics.mirror_image(cam, scene.mirror, scene.target.position).alpha_deg
    elif pan == "beacon":
        pan_deg = optics.mirror_image(cam, scene.mirror, scene.beacons[0].position).alpha_deg
    else:
        pan_deg = float(pan)
    return Camera(cam.position, cam.height, cam.resolution, cam.hfov, cam.pan, pan_deg)


def footprints(scene: Scene, bkey=None) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """Each object's footprint as a capsule: (key, segment start, segment end, radius).

    ``bkey(i)`` names beacon i's key as the file wrote it (``beacon`` or ``beacons[i]``).
    """
    if bkey is None:
        bkey = (lambda i: f"beacons[{i}]") if len(scene.beacons) > 1 else (lambda i: "beacon")
    out = []
    m0, m1 = scene.mirror.ends()
    out.append(("mirror.center", m0, m1, MIRROR_DEPTH))
    t0, t1 = scene.target.ends()
    out.append(("target.position", t0, t1, TARGET_THICKNESS / 2))
    for i, b in enumerate(scene.beacons):
        p = np.asarray(b.position, float)
        out.append((f"{bkey(i)}.position", p, p, PENCIL_RADIUS))
    for i, o in enumerate(scene.occluders):
        out.append((f"occluders[{i}]", np.asarray(o.start, float), np.asarray(o.end, float),
                    OCCLUDER_THICKNESS / 2))
    return out


def _check_overlaps(scene: Scene, r: _Reader, bkey) -> None:
    fps = footprints(scene, bkey)
    for j in range(len(fps)):
        for i in range(j):
            ki, a0, a1, ra = fps[i]
            kj, b0, b1, rb = fps[j]
            gap = segment_distance(a0, a1, b0, b1) - ra - rb
            if gap < 0.0:
                what_i = ki.split(".")[0]
                raise r.fail(kj, f"overlaps {what_i} (footprints intersect by {-gap:.2f} cm)")
    cam = np.asarray(scene.camera.position, float)
    for k, a0, a1, ra in fps:
        if segment_distance(cam, cam, a0, a1) < ra:
            raise r.fail("camera.position", f"{_fmt(cam)}: the camera stands inside {k}")


def _fmt(p) -> str:
    return "[" + ", ".join(f"{float(v):g}" for v in p) + "]"
