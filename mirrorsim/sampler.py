"""Random valid scenes for datasets, drawn from the ranges of a spec file.

Seeded with the ``int | numpy.random.Generator`` convention; each drawn scene is a normal
scene (it validates, and `to_yaml` writes it as a scene file that `mirrorsim evaluate`
reruns alone).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mirrorsim import optics
from mirrorsim.errors import RunFailed, SceneError
from mirrorsim.imperfections import as_keys
from mirrorsim.model import PAN_WORDS, Camera, Scene
from mirrorsim.scenefile import (
    DEFAULT_RESOLUTION,
    read_camera_model,
    read_render,
    read_resolution,
    read_yaml,
    scene_from_dict,
)
from solver.reader import Reader, show

DEFAULT_SPEC = Path(__file__).resolve().parents[1] / "scenes" / "dataset_spec.yaml"


MAX_TRIES = 100_000  # a documented bound on a spec's max_tries
PROBE_TRIES = 300  # a spec that gives no valid scene in this many draws is refused at once


class NoValidScene(RunFailed):
    """No draw of a spec gave a usable scene (the scene's own failure in a dataset)."""


def load_spec(path: str | Path | None = None) -> dict:
    """Read and check a spec file (default: the bundled one).

    Every fixed value is checked as a scene file's would be, every range as a range, and
    a few draws must give a usable scene.

    Raises
    ------
    SceneError
        Naming the file, the key path (``mirror.yaw``) and the value.
    """
    path = Path(path) if path else DEFAULT_SPEC
    spec = read_yaml(path)
    r = Reader(path, SceneError)
    r.mapping(spec, "", {"board", "camera", "mirror", "target", "beacon", "occluder"},
              {"render", "max_tries"})
    r.mapping(spec["board"], "board", {"size"}, {"hole_pitch"})
    r.pair(spec["board"]["size"], "board.size", positive=True)
    cam = r.mapping(spec["camera"], "camera", {"x", "y"},
                    {"height", "hfov", "resolution", "pan", "models"})
    if "models" in cam:
        if not isinstance(cam["models"], list) or not cam["models"]:
            raise r.fail("camera.models", f"expected a list of camera models, got "
                         f"{show(cam['models'])}")
        extra = {"height", "hfov"} & set(cam)  # a resolution beside them is their default
        if extra:
            raise r.fail(f"camera.{sorted(extra)[0]}", "give it in each of camera.models, "
                         "not beside them")
        for k, m in enumerate(cam["models"]):
            r.mapping(m, f"camera.models[{k}]", {"height", "hfov"}, {"resolution"})
    # the resolution (beside models: their default); heights and fields of view drawn
    # from ranges are checked by _value as it draws
    read_resolution(r, cam.get("resolution", DEFAULT_RESOLUTION), "camera.resolution")
    if "models" in cam:
        camera_models(spec, r)
    pan = spec["camera"].get("pan", "mirror")
    if not isinstance(pan, str):
        r.number(pan, "camera.pan")
    elif pan not in PAN_WORDS:
        raise r.fail("camera.pan", f"{show(pan)}: expected a bearing in degrees or one of "
                     f"{', '.join(PAN_WORDS)}")
    r.mapping(spec["mirror"], "mirror", {"x", "y", "yaw", "width", "height"})
    r.mapping(spec["target"], "target", {"x", "y", "size"})
    r.pair(spec["target"]["size"], "target.size", positive=True)
    r.mapping(spec["beacon"], "beacon", {"depth", "along", "height"})
    r.mapping(spec["occluder"], "occluder", {"at", "length", "height"})
    read_render(r, spec.get("render", {}), seed=False)
    r.integer(spec.get("max_tries", 5000), "max_tries", low=1, high=MAX_TRIES)
    # draws find range errors (wrong types, lo > hi) with their key, and a spec under
    # which no usable scene exists
    _draw(spec, np.random.default_rng(0), path)
    try:
        sample_scene(spec, 0, "probe", tries=min(PROBE_TRIES, spec.get("max_tries", 5000)))
    except NoValidScene as exc:
        raise r.fail("", str(exc)) from None
    return spec


def camera_models(spec: dict, r: Reader | None = None) -> list[Camera] | None:
    """The spec's camera models as cameras (position and pan irrelevant: what K depends
    on), or None when the spec draws heights or fields of view from ranges.  A
    resolution beside the models is their default."""
    models = spec["camera"].get("models")
    if models is None:
        return None
    r = r or Reader("<spec>", SceneError)
    default = spec["camera"].get("resolution", DEFAULT_RESOLUTION)
    cams = []
    for k, m in enumerate(models):
        height, hfov, res = read_camera_model(r, m, f"camera.models[{k}]", default)
        cams.append(Camera(position=(0.0, 0.0), height=height, hfov=hfov, resolution=res,
                           pan=0.0, pan_deg=0.0))
    return cams


def _value(spec: dict, block: str, key: str, rng: np.random.Generator, where) -> Any:
    r = Reader(where, SceneError)
    if not isinstance(spec[block], dict):
        raise r.fail(block, f"expected a mapping, got {show(spec[block])}")
    v = spec[block].get(key)
    if isinstance(v, list) and len(v) == 2:
        lo = r.number(v[0], f"{block}.{key}[0]")
        hi = r.number(v[1], f"{block}.{key}[1]")
        if lo > hi:
            raise r.fail(f"{block}.{key}", f"{v}: the range's low end exceeds its high end")
        return float(rng.uniform(lo, hi))
    if v is None:
        raise r.fail(f"{block}.{key}", "missing required key (a number or [lo, hi])")
    return r.number(v, f"{block}.{key}")


def _draw(spec: dict, rng: np.random.Generator, where="<spec>") -> dict:
    """One candidate scene dict (not yet validated)."""
    g = lambda block, key: _value(spec, block, key, rng, where)  # noqa: E731
    position = [g("camera", "x"), g("camera", "y")]
    models = camera_models(spec)
    if models:  # a lab's few cameras, each on its mount: one calibration each
        c = models[int(rng.integers(len(models)))]
        height, hfov, res = c.height, c.hfov, c.resolution
    else:
        height, hfov = g("camera", "height"), g("camera", "hfov")
        res = spec["camera"].get("resolution", DEFAULT_RESOLUTION)
    cam = {"position": position, "height": height, "hfov": hfov, "resolution": list(res),
           "pan": spec["camera"].get("pan", "mirror")}
    yaw = g("mirror", "yaw")
    centre = np.array([g("mirror", "x"), g("mirror", "y")])
    mirror = {"center": centre.tolist(), "yaw": yaw,
              "size": [g("mirror", "width"), g("mirror", "height")]}
    target = {"position": [g("target", "x"), g("target", "y")],
              "size": list(spec["target"]["size"])}
    # the beacon in front of the mirror (on the camera's side)
    n = np.array([-math.sin(math.radians(yaw)), math.cos(math.radians(yaw))])
    if n @ (np.asarray(cam["position"]) - centre) < 0:
        n = -n
    along = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw))])
    b = centre + g("beacon", "depth") * n + g("beacon", "along") * along
    beacon = {"position": b.tolist(), "height": g("beacon", "height")}
    # a wall across the direct line camera → target, perpendicular to it
    c, t = np.asarray(cam["position"]), np.asarray(target["position"])
    mid = c + g("occluder", "at") * (t - c)
    u = (t - c) / max(np.linalg.norm(t - c), 1e-9)
    half = g("occluder", "length") / 2 * np.array([-u[1], u[0]])
    occ = {"start": (mid - half).tolist(), "end": (mid + half).tolist(),
           "height": g("occluder", "height")}
    return {"board": copy.deepcopy(spec["board"]), "camera": cam, "mirror": mirror,
            "target": target, "beacon": beacon, "occluders": [occ],
            "render": dataclasses.asdict(read_render(Reader(where, SceneError),
                                                     spec.get("render", {}), seed=False))}


def sample_scene(spec: dict, rng: int | np.random.Generator | None, name: str,
                 tries: int | None = None) -> Scene:
    """Draw until a usable scene comes: valid, NLOS, both images whole in the mirror.

    Raises
    ------
    NoValidScene
        If ``tries`` (default: the spec's ``max_tries``) draws give none, saying why the
        draws were refused most often.
    """
    rng = np.random.default_rng(rng)
    tries = int(spec.get("max_tries", 5000)) if tries is None else tries
    reasons: dict[str, int] = {}
    for _ in range(tries):
        d = _draw(spec, rng)
        d["name"] = name
        try:
            s = scene_from_dict(d, source=name, default_name=name)
        except SceneError as exc:
            why = f"the scene's {exc.key or 'file'}"
            reasons[why] = reasons.get(why, 0) + 1
            continue
        if s.warnings:
            why = "an image clipped or the target seen directly"
            reasons[why] = reasons.get(why, 0) + 1
            continue
        if all(optics.visibility(s, o).fraction == 1.0 for o in (s.target, *s.beacons)):
            return s
        why = "an image not whole in the mirror"
        reasons[why] = reasons.get(why, 0) + 1
    common = max(reasons, key=reasons.get) if reasons else "nothing"
    raise NoValidScene(f"no usable scene in {tries} draws (refused most often for "
                       f"{common}: {reasons.get(common, 0)} times); widen the spec's ranges")


def to_yaml(scene: Scene) -> str:
    """The scene as a scene file (INTERFACE.md's format)."""
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
                    "background_spp": scene.render.background_spp}}
    for path, value in as_keys(scene).items():  # the bench's imperfections
        block, key = path.split(".")
        if block.startswith("beacons["):
            d["beacons"][int(block[len("beacons["):-1])][key] = value
        else:
            d.setdefault(block, {})[key] = value
    if len(scene.beacons) == 1:
        d["beacon"] = d.pop("beacons")[0]
    return yaml.safe_dump(d, sort_keys=False)
