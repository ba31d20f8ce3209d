"""Scene files parsed: YAML → a :class:`mirrorsim.scene.model.Scene` whose every value is
checked on its own, and back (:func:`scene_document`).

:func:`parse_scene` reads each block's keys and values or raises
:class:`~mirrorsim.errors.SceneError`, whose one-line message names the file, the key
path and the bad value.  It only parses: what the geometry decides (the target panel's
facing, the camera's pan bearing) is left NaN, and the checks between objects are the
composer's (:func:`mirrorsim.truth.compose.compose_scene`); the entry points
(:mod:`mirrorsim.pipelines.scenes`) call one, then the other.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mirrorsim.errors import Failures, SceneError
from mirrorsim.formats.capture import read_board, read_distortion
from mirrorsim.formats.reader import Reader, point_list, read_resolution, read_yaml, show
from mirrorsim.scene.imperfections import (
    REGISTRY,
    Imperfection,
    as_keys,
)
from mirrorsim.scene.model import (
    MAX_BOARD_CM,
    MAX_HFOV_DEG,
    MAX_LEAN_DEG,
    NAME_PATTERN,
    NAME_RULE,
    PAN_WORDS,
    Beacon,
    Bench,
    Camera,
    Mirror,
    Occluder,
    Scene,
    SensorNoise,
    Target,
)
from mirrorsim.scene.render_settings import RenderSettings

DEFAULT_RESOLUTION = (1920, 1088)


# a scene's name: a plain file name

def read_scene_file(path: str | Path, *, failures: Failures | None = None
                    ) -> tuple[Scene, Callable[[int], str]]:
    """A scene file parsed (:func:`parse_scene`), its file's stem the name it lacks."""
    path = Path(path)
    return parse_scene(read_yaml(path), source=str(path), default_name=path.stem,
                       failures=failures)


def read_camera_model(r: Reader, cam: dict, key: str,
                      *, default_resolution: tuple[int, int] = DEFAULT_RESOLUTION
                      ) -> tuple[float, float, tuple[int, int]]:
    """A camera's model from its block (scene files and specs alike): mount height (cm),
    hfov (°), resolution (px)."""
    return (r.number(cam["height"], f"{key}.height", positive=True, high=MAX_BOARD_CM),
            r.number(cam["hfov"], f"{key}.hfov", positive=True, high=MAX_HFOV_DEG),
            read_resolution(r, cam.get("resolution", default_resolution),
                            f"{key}.resolution"))


def read_render(r: Reader, block: Any, key: str = "render", *, seed: bool = True
                ) -> RenderSettings:
    """A ``render`` block (scene files and, with no ``seed``, specs), defaults for what
    it omits."""
    rr = r.mapping(block, key, set(),
                   optional={"spp", "sampler", "background_spp", "beacon_spp"}
                   | ({"seed"} if seed else set()))
    d = RenderSettings()
    # the bounds are RenderSettings' own; here each key's type and its name
    return r.built(key, RenderSettings,
                   spp=r.integer(rr.get("spp", d.spp), f"{key}.spp"),
                   seed=r.integer(rr.get("seed", d.seed), f"{key}.seed"),
                   sampler=rr.get("sampler", d.sampler),
                   background_spp=r.integer(rr.get("background_spp", d.background_spp),
                                            f"{key}.background_spp"),
                   beacon_spp=r.integer(rr.get("beacon_spp", d.beacon_spp),
                                        f"{key}.beacon_spp"))


def parse_scene(data: Any, *, source: str = "<scene>", default_name: str = "scene",
                failures: Failures | None = None) -> tuple[Scene, Callable[[int], str]]:
    """A scene file's parsed YAML (see docs/scenes.md) as a :class:`Scene` whose values
    are each checked, its derived fields NaN; and how the file names beacon ``i``
    (``beacon`` or ``beacons[i]``), for the composer's messages.

    Raises
    ------
    SceneError
        The first failure, with every other one found in the file in ``others`` (the
        blocks are read independently); with a lenient ``failures``, only a block that
        cannot be read.
    """
    f = Failures() if failures is None else failures
    r = Reader(source, SceneError)
    top = r.mapping(
        data, "",
        required={"board", "camera", "mirror", "target"},
        optional={"name", "beacon", "beacons", "occluders", "render", "calibration"},
    )
    name = f.attempt(_name, r, top, default_name)
    board = f.attempt(read_board, r, top["board"])
    cam = f.attempt(r.mapping, top["camera"], "camera", {"position", "height", "hfov", "pan"},
                    optional={"resolution", *CAMERA_IMPERFECTIONS})
    pan = position = model = None
    if cam is not None:
        pan = f.attempt(read_pan, r, cam["pan"], "camera.pan")
        position = f.attempt(r.pair, cam["position"], "camera.position")
        model = f.attempt(read_camera_model, r, cam, "camera")
    m = f.attempt(r.mapping, top["mirror"], "mirror", {"center", "yaw", "size"},
                  optional={"lean", *MIRROR_IMPERFECTIONS})
    mirror = None if m is None else f.attempt(_mirror, r, m)
    target = f.attempt(_target, r, top["target"])
    beacons, bkey = f.attempt(_beacons, r, top, default=(None, None))
    occluders = f.attempt(_occluders, r, top.get("occluders", []))
    rs = f.attempt(read_render, r, top.get("render", {}))
    f.raise_any(structural=True)  # a block that cannot be read leaves nothing to check

    height, hfov, resolution = model
    bench = f.attempt(_bench, r, cam, m, top.get("calibration", {}))
    f.raise_any()  # a bench key that cannot be read is said as it is, without a unit hint
    bench = bench or Bench()  # (lenient, for plot: a bad bench key drawn as the ideal)
    # the pan's bearing is the composer's: NaN until it is composed
    camera = r.built("camera", Camera, position=position, height=height,
                     resolution=resolution, hfov=hfov, pan=pan, pan_deg=math.nan)
    return Scene(name=name, board=board, camera=camera, mirror=mirror, target=target,
                 beacons=beacons, occluders=occluders, render=rs, bench=bench,
                 source=source), bkey


def scene_document(scene: Scene) -> dict:
    """The scene as a scene file's keys (docs/scenes.md): what :func:`scene_from_dict`
    builds the same scene from (a dataset's scene files, :func:`edit_scene`)."""
    c, m, t = scene.camera, scene.mirror, scene.target
    d = {"name": scene.name,
         "board": {"size": list(scene.board.size), "hole_pitch": scene.board.hole_pitch},
         "camera": {"position": list(c.position), "height": c.height,
                    "resolution": list(c.resolution), "hfov": c.hfov, "pan": c.pan},
         "mirror": {"center": point_list(m.center, m.z), "yaw": m.yaw, "size": list(m.size),
                    **({"lean": m.lean} if m.lean else {})},
         "target": {"position": point_list(t.position, t.z), "size": list(t.size)},
         "beacons": [{"position": point_list(b.position, b.z), "height": b.height}
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
    center, z = r.point(m["center"], "mirror.center")
    lean = r.number(m.get("lean", 0.0), "mirror.lean", low=-MAX_LEAN_DEG, high=MAX_LEAN_DEG)
    return r.built("mirror", Mirror, center=center, yaw=r.number(m["yaw"], "mirror.yaw"),
                   size=r.pair(m["size"], "mirror.size"), lean=lean, z=z)


def _target(r: Reader, raw: Any) -> Target:
    t = r.mapping(raw, "target", {"position", "size"})
    position, z = r.point(t["position"], "target.position")
    # what the geometry decides is the composer's: its facing NaN until it is composed
    return r.built("target", Target, position=position,
                   size=r.pair(t["size"], "target.size"), facing_deg=math.nan, z=z)


def _leaves(block: str) -> tuple[str, ...]:
    """The imperfection keys a scene file's ``block`` may hold (the registry's)."""
    return tuple(imp.leaf for imp in REGISTRY if imp.block == block)


CAMERA_IMPERFECTIONS = _leaves("camera")
MIRROR_IMPERFECTIONS = _leaves("mirror")


def _bench(r: Reader, cam: dict, m: dict, cal: Any) -> Bench:
    """The bench imperfections (docs/scenes.md), each read in its registry form; every key
    optional, absent = ideal."""
    blocks = {"camera": cam, "mirror": m,
              "calibration": r.mapping(cal, "calibration", set(),
                                       optional=set(_leaves("calibration")))}
    values = {}
    for imp in REGISTRY:
        # null is "absent" where the ideal bench has none (no lens, noise, JPEG, curvature);
        # a number or a flag must be given as one
        given = imp.block in blocks and imp.leaf in blocks[imp.block]
        if given and (blocks[imp.block][imp.leaf] is not None or imp.form in NUMERIC_FORMS):
            values[imp.field] = _imperfection(r, imp, blocks[imp.block][imp.leaf])
    return Bench(**values)


NUMERIC_FORMS = ("angle", "number", "flag")


def _imperfection(r: Reader, imp: Imperfection, raw: Any) -> Any:
    """One imperfection's value as its ``form`` reads it (its bounds, which relate it to
    the mirror or the camera, are the composer's:
    :func:`~mirrorsim.scene.bench_values.value_failure`)."""
    key = imp.key
    if imp.form in ("angle", "number", "radius"):
        return r.number(raw, key)
    if imp.form == "flag":
        if not isinstance(raw, bool):
            raise r.fail(key, f"{show(raw)}: expected true or false")
        return raw
    if imp.form == "quality":
        return r.integer(raw, key)
    if imp.form == "lens":
        return read_distortion(r, raw, key)
    if imp.form == "noise":
        n = r.mapping(raw, key, {"full_well", "read_noise"})
        return r.built(key, SensorNoise, full_well=r.number(n["full_well"], f"{key}.full_well"),
                       read_noise=r.number(n["read_noise"], f"{key}.read_noise"))
    raise AssertionError(f"{imp.key}: no scene-file reader for form {imp.form!r}")


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
        bb = r.mapping(raw, bkey(i), {"position", "height"}, optional={"known_position"})
        known = bb.get("known_position")
        position, z = r.point(bb["position"], f"{bkey(i)}.position")
        beacons.append(r.built(bkey(i), Beacon, position=position, z=z,
                               height=r.number(bb["height"], f"{bkey(i)}.height"),
                               known_position=None if known is None else
                               r.pair(known, f"{bkey(i)}.known_position")))
    return tuple(beacons), bkey


def _occluders(r: Reader, raw_occ: Any) -> tuple[Occluder, ...]:
    if not isinstance(raw_occ, list):
        raise r.fail("occluders", f"expected a list, got {show(raw_occ)}")
    occluders = []
    for i, raw in enumerate(raw_occ):
        o = r.mapping(raw, f"occluders[{i}]", {"start", "end", "height"})
        occluders.append(r.built(f"occluders[{i}]", Occluder,
                                 start=r.pair(o["start"], f"occluders[{i}].start"),
                                 end=r.pair(o["end"], f"occluders[{i}].end"),
                                 height=r.number(o["height"], f"occluders[{i}].height")))
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
