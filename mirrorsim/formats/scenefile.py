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

import numpy as np

from mirrorsim.errors import BadParameter, Failures, SceneError
from mirrorsim.formats.capture import read_board, read_distortion
from mirrorsim.formats.reader import Reader, read_resolution, read_yaml, show
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
    fx_of,
)

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
                  optional=set(MIRROR_IMPERFECTIONS))
    mirror = None if m is None else f.attempt(_mirror, r, m)
    target_position, target_size = f.attempt(_target, r, top["target"], default=(None, None))
    beacons, bkey = f.attempt(_beacons, r, top, default=(None, None))
    occluders = f.attempt(_occluders, r, top.get("occluders", []))
    rs = f.attempt(read_render, r, top.get("render", {}))
    f.raise_any(structural=True)  # a block that cannot be read leaves nothing to check

    height, hfov, resolution = model
    bench = f.attempt(_bench, r, cam, m, top.get("calibration", {}), mirror, resolution, hfov)
    f.raise_any()  # a bench key out of its bounds is said as it is, without a unit hint
    bench = bench or Bench()  # (lenient, for plot: a bad bench key drawn as the ideal)
    # what the geometry decides is the composer's: NaN until it is composed
    target = Target(target_position, target_size, math.nan)
    camera = Camera(position, height, resolution, hfov, pan, math.nan)
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
              "calibration": r.mapping(cal, "calibration", set(),
                                       optional=set(_leaves("calibration")))}
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
        bb = r.mapping(raw, bkey(i), {"position", "height"}, optional={"known_position"})
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
