"""Scene files: YAML → :class:`mirrorsim.scene.model.Scene`, with every check.

:func:`load_scene` turns a file into a complete scene or raises
:class:`~mirrorsim.errors.SceneError`, whose one-line message names the file, the key
path and the bad value.  The geometric checks (edge-on mirror, objects behind it,
images that do not reach the camera) use :mod:`mirrorsim.truth.optics`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from mirrorsim.errors import BadParameter, SceneError
from mirrorsim.formats.capture import read_board, read_distortion
from mirrorsim.formats.files import jsonable
from mirrorsim.formats.reader import Reader, read_resolution, read_yaml, show
from mirrorsim.formats.scene_checks import (
    Failures,
    board_check,
    check_all_on_board,
    check_mirror_faces,
    check_overlaps,
    check_sight,
    fmt,
    unit_hints,
)
from mirrorsim.scene.imperfections import (
    REGISTRY,
    Imperfection,
    as_keys,
    check_bounds,
    radius_bound,
)
from mirrorsim.scene.model import (
    MAX_BOARD_CM,
    MAX_CURVATURE_RADIUS,
    MAX_FULL_WELL,
    MAX_HFOV_DEG,
    MAX_READ_NOISE,
    NAME_PATTERN,
    NAME_RULE,
    PAN_WORDS,
    Beacon,
    Bench,
    Camera,
    Mirror,
    Occluder,
    RenderSettings,
    Scene,
    SensorNoise,
    Target,
    check_is_scene,
    fx_of,
)
from mirrorsim.truth import optics

DEFAULT_RESOLUTION = (1920, 1088)


# a scene's name: a plain file name

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
                      default_resolution: tuple[int, int] = DEFAULT_RESOLUTION
                      ) -> tuple[float, float, tuple[int, int]]:
    """A camera's model from its block (scene files and specs alike): mount height (cm),
    hfov (°), resolution (px)."""
    return (r.number(cam["height"], f"{key}.height", positive=True, high=MAX_BOARD_CM),
            r.number(cam["hfov"], f"{key}.hfov", positive=True, high=MAX_HFOV_DEG),
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
    return _build(data, source, default_name, Failures())


def scene_and_failures(path: str | Path) -> tuple[Scene | None, tuple[SceneError, ...]]:
    """A scene file read as far as it goes: the scene (None where a block cannot be read)
    and every failure found, for ``mirrorsim plot`` to draw an invalid scene with its
    failures marked.  Never raises SceneError."""
    path = Path(path)
    f = Failures(lenient=True)
    try:
        scene = _build(read_yaml(path), str(path), path.stem, f)
    except SceneError as exc:
        return None, (exc, *exc.others)
    return scene, tuple(f.found)


def _build(data: Any, source: str, default_name: str, f: Failures) -> Scene:
    r = Reader(source, SceneError)
    top = r.mapping(
        data, "",
        required={"board", "camera", "mirror", "target"},
        optional={"name", "beacon", "beacons", "occluders", "render", "calibration"},
    )
    name = f.attempt(_name, r, top, default_name)
    board = f.attempt(read_board, r, top["board"])
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
    hint = unit_hints(board, mirror, hfov, [
        ("camera.position", position), ("mirror.center", mirror.center),
        ("target.position", target_position),
        *((f"{bkey(i)}.position", b.position) for i, b in enumerate(beacons))])
    on_board = board_check(r, board)
    bench = f.attempt(_bench, r, cam, m, top.get("calibration", {}), mirror, resolution, hfov)
    f.raise_any()  # a bench key out of its bounds is said as it is, without a unit hint
    bench = bench or Bench()  # (lenient, for plot: a bad bench key drawn as the ideal)
    check_all_on_board(f, on_board, position, mirror, target_position, beacons, bkey,
                        occluders)
    f.raise_any(hint)
    f.attempt(check_mirror_faces, f, r, position, mirror, target_position, beacons, bkey)
    f.raise_any(hint)

    # derived values, computed once here: the panel faces the camera's virtual image
    target = Target(target_position, target_size,
                    optics.target_facing(position, mirror, target_position))
    for end in target.ends():
        f.attempt(on_board, end, "target.position", f"the target panel's edge {fmt(end)}")
    f.raise_any(hint)
    pan_deg = optics.resolve_pan(position, pan, mirror, target_position, beacons[0].position)
    camera = Camera(position, height, resolution, hfov, pan, pan_deg)
    scene = Scene(name=name, board=board, camera=camera, mirror=mirror, target=target,
                  beacons=beacons, occluders=occluders, render=rs, bench=bench, source=source)
    check_overlaps(f, scene, r, bkey)
    warnings = check_sight(f, scene, r, bkey)
    f.raise_any(hint)
    return replace(scene, warnings=warnings)


def scene_document(scene: Scene) -> dict:
    """The scene as a scene file's keys (docs/scenes.md): what :func:`scene_from_dict`
    builds the same scene from (a dataset's scene files, :func:`edit_scene`)."""
    c, m, t = scene.camera, scene.mirror, scene.target
    d = {"name": scene.name,
         "board": {"size": list(scene.board.size), "hole_pitch": scene.board.hole_pitch},
         "camera": {"position": list(c.position), "height": c.height,
                    "resolution": list(c.resolution), "hfov": c.hfov, "pan": c.pan},
         "mirror": {"center": list(m.center), "yaw": m.yaw, "size": list(m.size)},
         "target": {"position": list(t.position), "size": list(t.size)},
         "beacons": [{"position": list(b.position), "height": b.height}
                     for b in scene.beacons],
         "occluders": [{"start": list(o.start), "end": list(o.end), "height": o.height}
                       for o in scene.occluders],
         "render": {"spp": scene.render.spp, "seed": scene.render.seed,
                    "sampler": scene.render.sampler,
                    "background_spp": scene.render.background_spp,
                    "beacon_spp": scene.render.beacon_spp}}
    for path, value in as_keys(scene).items():  # the bench's imperfections
        block, key = path.split(".")
        if block.startswith("beacons["):
            d["beacons"][int(block[len("beacons["):-1])][key] = value
        else:
            d.setdefault(block, {})[key] = value
    if len(scene.beacons) == 1:
        d["beacon"] = d.pop("beacons")[0]
    return d


def edit_scene(scene: Scene, changes: Mapping[str, Any]) -> Scene:
    """``scene`` with some of its file's keys changed, built again as a scene file is:
    every check runs, and what the file's geometry decides (the target panel's facing, a
    pan aimed with ``mirror``, ``target`` or ``beacon``) follows the edit.
    ``dataclasses.replace`` recomputes none of it.

    ``changes`` nests as the file does, ``{"mirror": {"yaw": 20}, "name": "yaw20"}``: a
    mapping merges into its block, whose other keys keep their values (a beacon moved by
    ``{"beacon": {"position": …}}`` keeps a ``known_position`` its file gave), and any
    other value (a list too: ``beacons``) replaces its key.  numpy numbers are taken as
    numbers.

    Raises
    ------
    SceneError
        An edit the file's checks refuse, naming its key (the source reads
        ``SOURCE (edited)``).
    BadParameter
        ``changes`` is not a mapping.
    """
    check_is_scene(scene)
    if not isinstance(changes, Mapping):
        raise BadParameter("changes", f"expected a mapping of scene-file keys, not "
                           f"{type(changes).__name__}")
    doc = scene_document(scene)
    if "beacons" in changes:  # the one-beacon form gives way to the list given
        doc.pop("beacon", None)
    elif "beacon" in changes and "beacons" in doc:
        raise BadParameter("changes", f"beacon: {scene.name} has {len(scene.beacons)} beacons; "
                           "give `beacons`, the whole list")
    # numpy numbers (a script's np.arange of yaws) as a file's; NaN left to be refused
    plain = jsonable(changes, nonfinite_as_null=False)
    edited = scene_from_dict(_merged(doc, plain), source=f"{scene.source} (edited)",
                             default_name=scene.name)
    return replace(edited, source=scene.source)


def _merged(doc: dict, changes: Mapping[str, Any]) -> dict:
    out = dict(doc)
    for key, value in changes.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def check_given_scene(scene: Any) -> Scene:
    """A scene given to the Python API, held to what its file would make of it: a scene
    edited with ``dataclasses.replace`` skips the file's checks and keeps the target's
    facing and the pan that its old geometry decided (a mirror turned by 10° left the
    panel facing the old mirror).  Returns ``scene``.

    Raises
    ------
    SceneError
        The edited scene fails a check of the scene file (naming the key).
    BadParameter
        ``scene`` is not a :class:`Scene`, or what its geometry decides has not followed
        an edit (use :func:`edit_scene`).
    """
    check_is_scene(scene)
    again = scene_from_dict(scene_document(scene), source=f"{scene.source} (edited)",
                            default_name=scene.name)
    stale = [what for what, given, made in (
        ("target panel's facing", scene.target.facing_deg, again.target.facing_deg),
        ("camera's pan bearing", scene.camera.pan_deg, again.camera.pan_deg))
        if not math.isclose(given, made, rel_tol=0, abs_tol=1e-9)]
    if stale:
        raise BadParameter("scene", f"{scene.name}: the {' and the '.join(stale)} no longer "
                           f"follow{'s' if len(stale) == 1 else ''} its geometry (edited with "
                           "dataclasses.replace, which recomputes nothing): edit it with "
                           "mirrorsim.edit_scene")
    return scene


def _name(r: Reader, top: dict, default_name: str) -> str:
    name = top.get("name", default_name)
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        rule = NAME_RULE
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
        corner = math.hypot(*resolution) / 2 / fx_of(resolution[0], hfov)
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
