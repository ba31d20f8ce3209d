"""Scene files: YAML → :class:`mirrorsim.scene.model.Scene`, with every check.

:func:`load_scene` turns a file into a complete scene or raises
:class:`~mirrorsim.errors.SceneError`, whose one-line message names the file, the key
path and the bad value.  The geometric checks (edge-on mirror, objects behind it,
images that do not reach the camera) use :mod:`mirrorsim.truth.optics`.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from mirrorsim.errors import BadParameter, SceneError
from mirrorsim.formats.capture import read_distortion
from mirrorsim.formats.reader import Reader, read_resolution, read_yaml, show
from mirrorsim.scene.imperfections import REGISTRY, Imperfection, check_bounds, radius_bound
from mirrorsim.scene.model import (
    MAX_BOARD_CM,
    MAX_CURVATURE_RADIUS,
    MAX_FULL_WELL,
    MAX_READ_NOISE,
    PAN_WORDS,
    Beacon,
    Bench,
    Board,
    Camera,
    Mirror,
    Occluder,
    RenderSettings,
    Scene,
    SensorNoise,
    Target,
    footprints,
)
from mirrorsim.truth import optics, visibility
from solver.geometry import segment_distance, signed_distance

EDGE_ON_LIMIT_DEG = 5.0  # a mirror seen at a more grazing angle than this is edge-on
DEFAULT_RESOLUTION = (1920, 1088)


# a scene's name: a plain file name
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")

def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file.

    Raises
    ------
    SceneError
        For any bad input, with the file, the key path and what is wrong.
    """
    path = Path(path)
    return scene_from_dict(read_yaml(path), source=str(path), default_name=path.stem)


def read_camera_model(r: Reader, cam: dict, key: str,
                      default_resolution=DEFAULT_RESOLUTION) -> tuple[float, float,
                                                                   tuple[int, int]]:
    """A camera's model from its block (scene files and specs alike): mount height (cm),
    hfov (°), resolution (px)."""
    return (r.number(cam["height"], f"{key}.height", positive=True, high=MAX_BOARD_CM),
            r.number(cam["hfov"], f"{key}.hfov", positive=True, high=170.0),
            read_resolution(r, cam.get("resolution", default_resolution),
                            f"{key}.resolution"))


def read_render(r: Reader, block: Any, key: str = "render", seed: bool = True
                ) -> RenderSettings:
    """A ``render`` block (scene files and, with no ``seed``, specs), defaults for what
    it omits."""
    rr = r.mapping(block, key, set(),
                   {"spp", "sampler", "background_spp", "beacon_spp"}
                   | ({"seed"} if seed else set()))
    d = RenderSettings()
    try:  # the bounds are RenderSettings' own; here each key's type and its name
        return RenderSettings(
            spp=r.integer(rr.get("spp", d.spp), f"{key}.spp"),
            seed=r.integer(rr.get("seed", d.seed), f"{key}.seed"),
            sampler=rr.get("sampler", d.sampler),
            background_spp=r.integer(rr.get("background_spp", d.background_spp),
                                     f"{key}.background_spp"),
            beacon_spp=r.integer(rr.get("beacon_spp", d.beacon_spp), f"{key}.beacon_spp"))
    except BadParameter as exc:
        raise r.fail(f"{key}.{exc.parameter}", exc.message) from None


def scene_from_dict(data: Any, source: str = "<scene>", default_name: str = "scene") -> Scene:
    """Build and validate a :class:`Scene` from parsed YAML (see docs/scenes.md).

    Raises
    ------
    SceneError
        The first failure, with every other one found in the file in ``others``: the
        blocks are read independently, and the checks between objects (on the board,
        in front of the mirror, overlaps, sight) each run where their blocks were read.
    """
    return _build(data, source, default_name, _Failures())


def scene_and_failures(path: str | Path) -> tuple[Scene | None, tuple[SceneError, ...]]:
    """A scene file read as far as it goes: the scene (None where a block cannot be read)
    and every failure found, for ``mirrorsim plot`` to draw an invalid scene with its
    failures marked.  Never raises SceneError."""
    path = Path(path)
    f = _Failures(lenient=True)
    try:
        scene = _build(read_yaml(path), str(path), path.stem, f)
    except SceneError as exc:
        return None, (exc, *exc.others)
    return scene, tuple(f.found)


def _build(data: Any, source: str, default_name: str, f: _Failures) -> Scene:
    r = Reader(source, SceneError)
    top = r.mapping(
        data, "",
        required={"board", "camera", "mirror", "target"},
        optional={"name", "beacon", "beacons", "occluders", "render", "calibration"},
    )
    name = f.attempt(_name, r, top, default_name)
    board = f.attempt(_board, r, top["board"])
    cam = f.attempt(r.mapping, top["camera"], "camera", {"position", "height", "hfov", "pan"},
                    {"resolution", *CAMERA_IMPERFECTIONS})
    pan = position = model = None
    if cam is not None:
        pan = f.attempt(read_pan, r, cam["pan"], "camera.pan")
        position = f.attempt(r.pair, cam["position"], "camera.position")
        model = f.attempt(read_camera_model, r, cam, "camera")
    m = f.attempt(r.mapping, top["mirror"], "mirror", {"center", "yaw", "size"},
                  set(MIRROR_IMPERFECTIONS))
    mirror = None if m is None else f.attempt(_mirror, r, m)
    target_position, target_size = f.attempt(_target, r, top["target"], default=(None, None))
    beacons, bkey = f.attempt(_beacons, r, top, default=(None, None))
    occluders = f.attempt(_occluders, r, top.get("occluders", []))
    rs = f.attempt(read_render, r, top.get("render", {}))
    f.raise_any(structural=True)  # a block that cannot be read leaves nothing to check

    height, hfov, resolution = model
    hint = _unit_hints(board, mirror, hfov, [
        ("camera.position", position), ("mirror.center", mirror.center),
        ("target.position", target_position),
        *((f"{bkey(i)}.position", b.position) for i, b in enumerate(beacons))])
    on_board = _board_check(r, board)
    bench = f.attempt(_bench, r, cam, m, top.get("calibration", {}), mirror, resolution, hfov)
    f.raise_any()  # a bench key out of its bounds is said as it is, without a unit hint
    bench = bench or Bench()  # (lenient, for plot: a bad bench key drawn as the ideal)
    _check_all_on_board(f, on_board, position, mirror, target_position, beacons, bkey,
                        occluders)
    f.raise_any(hint)
    f.attempt(_check_mirror_faces, f, r, position, mirror, target_position, beacons, bkey)
    f.raise_any(hint)

    # derived values, computed once here: the panel faces the camera's virtual image
    target = Target(target_position, target_size,
                    optics.target_facing(position, mirror, target_position))
    for end in target.ends():
        f.attempt(on_board, end, "target.position", f"the target panel's edge {_fmt(end)}")
    f.raise_any(hint)
    pan_deg = optics.resolve_pan(position, pan, mirror, target_position, beacons[0].position)
    camera = Camera(position, height, resolution, hfov, pan, pan_deg)
    scene = Scene(name=name, board=board, camera=camera, mirror=mirror, target=target,
                  beacons=beacons, occluders=occluders, render=rs, bench=bench, source=source)
    _check_overlaps(f, scene, r, bkey)
    warnings = _check_sight(f, scene, r, bkey)
    f.raise_any(hint)
    return replace(scene, warnings=warnings)


class _Failures:
    """The failures found so far in one file: each independent check is attempted, and
    the first failure is raised with the others attached (``SceneError.others``)."""

    def __init__(self, lenient: bool = False):
        self.found: list[SceneError] = []
        # lenient: only a block that cannot be read stops the scene being built (plot)
        self.lenient = lenient

    def attempt(self, fn: Callable, *args, default: Any = None) -> Any:
        """``fn(*args)``, or ``default`` with its SceneError recorded."""
        try:
            return fn(*args)
        except SceneError as exc:
            self.found.append(exc)
            return default

    def raise_any(self, hint: str = "", structural: bool = False) -> None:
        """Raise the first failure found, the others attached (and ``hint`` added to
        its line: a value in the wrong units is blamed on another key); when lenient,
        only ``structural`` failures (a block not read) are raised."""
        if self.found and self.lenient and not structural:
            if hint and hint not in self.found[0].message:
                first = self.found[0]
                self.found[0] = SceneError(first.file, first.key, f"{first.message} ({hint})")
            return
        if self.found:
            first = self.found[0]
            if hint:
                first = SceneError(first.file, first.key, f"{first.message} ({hint})")
            first.others = tuple(self.found[1:])
            raise first


def _unit_hints(board: Board, mirror: Mirror, hfov: float, positions) -> str:
    """Why a geometric check may have failed: a length given in mm, an angle in radians.
    Only said once a check has failed, since each such value is also a valid one."""
    W, H = board.size
    hints = []
    if hfov <= math.pi:
        hints.append(f"camera.hfov is in degrees: {hfov:g} looks like radians "
                     f"({math.degrees(hfov):.1f}°)?")
    if 0 < abs(mirror.yaw) <= 2 * math.pi and mirror.yaw != round(mirror.yaw):
        hints.append(f"mirror.yaw is in degrees: {mirror.yaw:g} looks like radians "
                     f"({math.degrees(mirror.yaw):.1f}°)?")
    if max(mirror.size) > max(W, H) >= max(mirror.size) / 10:
        hints.append(f"mirror.size is in cm: {_fmt(mirror.size)} looks like mm?")
    # far off the board (3× its size), yet on it at a tenth: millimetres
    off = [k for k, p in positions if max(abs(p[0]) / W, abs(p[1]) / H) > 3
           and 0 <= p[0] / 10 <= W and 0 <= p[1] / 10 <= H]
    if off:
        hints.append(f"{', '.join(off)} in cm: mm?")
    return "; ".join(hints)


def _name(r: Reader, top: dict, default_name: str) -> str:
    name = top.get("name", default_name)
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        rule = "letters, digits, '.', '_', '-'; no path"
        if "name" not in top:  # the file's own name stands in: say so, not blame a key
            raise r.fail("", f"has no `name:` and its file name {show(name)} cannot stand in "
                         f"for one ({rule}): add a `name:` key")
        raise r.fail("name", f"{show(name)} is not a plain file name ({rule})")
    return name


def _mirror(r: Reader, m: dict) -> Mirror:
    return Mirror(center=r.pair(m["center"], "mirror.center"),
                  yaw=r.number(m["yaw"], "mirror.yaw"),
                  size=r.pair(m["size"], "mirror.size", positive=True, high=MAX_BOARD_CM))


def _target(r: Reader, raw: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    t = r.mapping(raw, "target", {"position", "size"})
    return (r.pair(t["position"], "target.position"),
            r.pair(t["size"], "target.size", positive=True, high=MAX_BOARD_CM))


def _leaves(block: str) -> tuple[str, ...]:
    """The imperfection keys a scene file's ``block`` may hold (the registry's)."""
    return tuple(imp.leaf for imp in REGISTRY if imp.block == block)


CAMERA_IMPERFECTIONS = _leaves("camera")
MIRROR_IMPERFECTIONS = _leaves("mirror")


def _bench(r: Reader, cam: dict, m: dict, cal: Any, mirror: Mirror,
           resolution: tuple[int, int], hfov: float) -> Bench:
    """The bench imperfections (docs/scenes.md), each read in its registry form; every key
    optional, absent = ideal."""
    blocks = {"camera": cam, "mirror": m,
              "calibration": r.mapping(cal, "calibration", set(), set(_leaves("calibration")))}
    values = {}
    for imp in REGISTRY:
        # null is "absent" where the ideal bench has none (no lens, noise, JPEG, curvature);
        # a number or a flag must be given as one
        given = imp.block in blocks and imp.leaf in blocks[imp.block]
        if given and (blocks[imp.block][imp.leaf] is not None or imp.form in NUMERIC_FORMS):
            values[imp.field] = _imperfection(r, imp, blocks[imp.block][imp.leaf], mirror,
                                              resolution, hfov)
    return Bench(**values)


NUMERIC_FORMS = ("angle", "number", "flag")


def _imperfection(r: Reader, imp: Imperfection, raw: Any, mirror: Mirror,
                  resolution: tuple[int, int], hfov: float) -> Any:
    """One imperfection's value as its ``form`` reads it, bounds checked."""
    key = imp.key
    if imp.form in ("angle", "number"):
        value = r.number(raw, key)
        why = check_bounds(imp, value)
        if why:
            raise r.fail(key, why)
        return value
    if imp.form == "flag":
        if not isinstance(raw, bool):
            raise r.fail(key, f"{show(raw)}: expected true or false")
        return raw
    if imp.form == "quality":
        return r.integer(raw, key, low=int(imp.low), high=int(imp.high))
    if imp.form == "lens":
        k = read_distortion(r, raw, key)
        corner = math.hypot(*resolution) / 2 / ((resolution[0] / 2)
                                                 / math.tan(math.radians(hfov) / 2))
        if not distortion_monotonic(k, corner):
            raise r.fail(key, f"{list(k)}: the lens folds the image over before the "
                         "frame's corner (r·(1 + k1 r² + k2 r⁴) must grow)")
        return k
    if imp.form == "noise":
        n = r.mapping(raw, key, {"full_well", "read_noise"})
        return SensorNoise(r.number(n["full_well"], f"{key}.full_well", positive=True,
                                    high=MAX_FULL_WELL),
                           r.number(n["read_noise"], f"{key}.read_noise", low=0.0,
                                    high=MAX_READ_NOISE))
    if imp.form == "radius":
        radius = r.number(raw, key)
        diagonal = radius_bound(mirror.size)
        if not diagonal <= abs(radius) <= MAX_CURVATURE_RADIUS:
            raise r.fail(key, f"{radius:g}: |radius| must be at least the mirror's diagonal "
                         f"({diagonal:.1f} cm) and at most {MAX_CURVATURE_RADIUS:g} cm "
                         "(flatter: leave the key out)")
        return radius
    raise AssertionError(f"{imp.key}: no scene-file reader for form {imp.form!r}")


def distortion_monotonic(k: tuple[float, float], r_max: float) -> bool:
    """Whether r·(1 + k1 r² + k2 r⁴) grows on [0, r_max] (normalized radius): a lens
    that folds its image over is no lens."""
    r = np.linspace(0.0, r_max, 512)
    return bool((1 + 3 * k[0] * r**2 + 5 * k[1] * r**4 > 0).all())


def _board(r: Reader, raw: Any) -> Board:
    b = r.mapping(raw, "board", {"size"}, {"hole_pitch"})
    board = Board(size=r.pair(b["size"], "board.size", positive=True, high=MAX_BOARD_CM),
                  hole_pitch=r.number(b.get("hole_pitch", 2.5), "board.hole_pitch", low=0.0))
    if 0.0 < board.hole_pitch <= board.hole_diameter:
        raise r.fail("board.hole_pitch", f"{board.hole_pitch:g} must exceed the hole diameter "
                     f"{board.hole_diameter:g} cm (or be 0 for a plain board)")
    return board


def _beacons(r: Reader, top: dict) -> tuple[tuple[Beacon, ...], Callable[[int], str]]:
    if ("beacon" in top) == ("beacons" in top):
        raise r.fail("beacon", "give exactly one of `beacon:` or `beacons:`")
    if "beacon" in top:
        raw_beacons, bkey = [top["beacon"]], lambda _i: "beacon"
    else:
        raw_beacons, bkey = top["beacons"], lambda i: f"beacons[{i}]"
        if not isinstance(raw_beacons, list) or not raw_beacons:
            raise r.fail("beacons", f"expected a non-empty list, got {show(raw_beacons)}")
    beacons = []
    for i, raw in enumerate(raw_beacons):
        bb = r.mapping(raw, bkey(i), {"position", "height"}, {"known_position"})
        known = bb.get("known_position")
        beacons.append(Beacon(position=r.pair(bb["position"], f"{bkey(i)}.position"),
                              height=r.number(bb["height"], f"{bkey(i)}.height", positive=True,
                                              high=MAX_BOARD_CM),
                              known_position=None if known is None else
                              r.pair(known, f"{bkey(i)}.known_position")))
    return tuple(beacons), bkey


def _occluders(r: Reader, raw_occ: Any) -> tuple[Occluder, ...]:
    if not isinstance(raw_occ, list):
        raise r.fail("occluders", f"expected a list, got {show(raw_occ)}")
    occluders = []
    for i, raw in enumerate(raw_occ):
        o = r.mapping(raw, f"occluders[{i}]", {"start", "end", "height"})
        occ = Occluder(start=r.pair(o["start"], f"occluders[{i}].start"),
                       end=r.pair(o["end"], f"occluders[{i}].end"),
                       height=r.number(o["height"], f"occluders[{i}].height", positive=True,
                                       high=MAX_BOARD_CM))
        if np.hypot(occ.end[0] - occ.start[0], occ.end[1] - occ.start[1]) < 0.1:
            raise r.fail(f"occluders[{i}].end", f"{list(occ.end)}: the wall has no length")
        occluders.append(occ)
    return tuple(occluders)


def read_pan(r: Reader, raw: Any, key: str) -> float | str:
    """A camera's pan: a bearing in degrees or one of :data:`PAN_WORDS` (scene files and
    specs alike)."""
    if isinstance(raw, str):
        if raw not in PAN_WORDS:
            raise r.fail(key, f"{show(raw)}: expected a bearing in degrees or one of "
                         f"{', '.join(PAN_WORDS)}")
        return raw
    return r.number(raw, key)


def _check_all_on_board(f: _Failures, on_board, position, mirror: Mirror, target_position,
                        beacons, bkey, occluders) -> None:
    """Every object stands on the board (the mirror's ends, believed positions too)."""
    f.attempt(on_board, position, "camera.position", "the camera")
    if f.attempt(on_board, mirror.center, "mirror.center", "the mirror", default=False) \
            is None:  # the mirror's ends only where its centre is on the board
        for end in mirror.ends():
            if f.attempt(on_board, end, "mirror.center", f"the mirror's end {_fmt(end)}",
                         default=False) is False:
                break
    f.attempt(on_board, target_position, "target.position", "the target")
    for i, b in enumerate(beacons):
        f.attempt(on_board, b.position, f"{bkey(i)}.position", "the beacon")
        if b.known_position is not None:
            f.attempt(on_board, b.known_position, f"{bkey(i)}.known_position",
                      "the believed position")
    for i, o in enumerate(occluders):
        f.attempt(on_board, o.start, f"occluders[{i}].start", "the wall's start")
        f.attempt(on_board, o.end, f"occluders[{i}].end", "the wall's end")


def _board_check(r: Reader, board: Board):
    W, H = board.size

    def on_board(p, key: str, what: str) -> None:
        tol = 1e-9
        if not (-tol <= p[0] <= W + tol and -tol <= p[1] <= H + tol):
            raise r.fail(key, f"{_fmt(p)}: {what} lies off the board [0, {W:g}] × [0, {H:g}]")

    return on_board


def _check_mirror_faces(f: _Failures, r: Reader, camera_position, mirror: Mirror,
                        target_position, beacons, bkey) -> None:
    """The camera must see the mirror's face, and the objects stand in front of it."""
    # The reflective face is the one turned towards the camera; a camera on the line
    # (or nearly so) sees the mirror edge-on.
    cam = np.asarray(camera_position, float)
    cam_side = float(signed_distance(cam, mirror.center, mirror.yaw))
    dist = float(np.hypot(*(np.asarray(mirror.center, float) - cam)))
    graze = math.degrees(math.asin(min(1.0, abs(cam_side) / dist))) if dist > 0 else 0.0
    if graze < EDGE_ON_LIMIT_DEG:
        raise r.fail("mirror.yaw", f"{mirror.yaw:g}: the camera sees the mirror edge-on "
                     f"(line of sight {graze:.2f}° off its surface; need ≥ {EDGE_ON_LIMIT_DEG:g}°)")

    def in_front(p, key: str, what: str) -> None:
        s = float(signed_distance(p, mirror.center, mirror.yaw))
        if s * cam_side <= 0.0:
            raise r.fail(key, f"{_fmt(p)}: the {what} stands behind the mirror (on its back, "
                         f"{abs(s):.2f} cm from its surface line), so the mirror cannot show it")

    f.attempt(in_front, target_position, "target.position", "target")
    for i, b in enumerate(beacons):
        f.attempt(in_front, b.position, f"{bkey(i)}.position", "beacon")


def _check_sight(f: _Failures, scene: Scene, r: Reader, bkey) -> tuple[str, ...]:
    """Refuse images that do not reach the camera; warn of clipped or direct views."""
    sighted = [("target.position", scene.target, "target")] + [
        (f"{bkey(i)}.position", b, "beacon") for i, b in enumerate(scene.beacons)]
    warnings = []
    failed = {e.key for e in f.found}  # (lenient) an object already refused: once
    for key, obj, what in sighted:
        if key in failed:
            continue
        vis = visibility.visibility(scene, obj)
        if vis.axis_fraction == 0.0:
            f.found.append(r.fail(key, f"{_fmt(obj.position)}: the {what}'s image does not "
                                  f"reach the camera through the mirror: {vis.reason}"))
            continue
        if vis.clipped:
            warnings.append(f"{key}: the {what}'s image is clipped ({vis.reason})")
    direct = visibility.direct_view_fraction(scene, scene.target)
    if direct > 0.0:
        warnings.append(f"target.position: the camera also sees the target directly "
                        f"({100 * direct:.0f}% of its axis unobstructed): not an NLOS set-up")
    return tuple(warnings)


def _check_overlaps(f: _Failures, scene: Scene, r: Reader, bkey) -> None:
    fps = footprints(scene, bkey)
    for j in range(len(fps)):
        for i in range(j):
            ki, a0, a1, ra = fps[i]
            kj, b0, b1, rb = fps[j]
            gap = segment_distance(a0, a1, b0, b1) - ra - rb
            if gap < 0.0:
                what_i = ki.split(".")[0]
                f.found.append(r.fail(kj, f"overlaps {what_i} (footprints intersect by "
                                          f"{-gap:.2f} cm)"))
    cam = np.asarray(scene.camera.position, float)
    for k, a0, a1, ra in fps:
        if segment_distance(cam, cam, a0, a1) < ra:
            f.found.append(r.fail("camera.position",
                                  f"{_fmt(cam)}: the camera stands inside {k}"))


def _fmt(p) -> str:
    return "[" + ", ".join(f"{float(v):g}" for v in p) + "]"


def scene_template(path: str | Path) -> str:
    """The commented template scene (``mirrorsim new``), named after ``path``'s stem.

    Raises
    ------
    SceneError
        When the file's name cannot be a scene's name.
    """
    from importlib import resources

    name = Path(path).stem
    if not NAME_PATTERN.fullmatch(name):
        raise SceneError(str(path), "", f"{name!r} cannot name a scene (letters, digits, "
                                        "'.', '_', '-'; starting with a letter or digit)")
    text = (resources.files("mirrorsim") / "data" / "template.yaml").read_text(encoding="utf-8")
    # quoted: a name such as 123, yes or null would read as another type
    return text.replace("name: NAME ", f"name: {json.dumps(name)} ", 1)
