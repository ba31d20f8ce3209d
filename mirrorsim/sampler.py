"""Random valid scenes for datasets, drawn from the ranges of a spec file.

Seeded with the ``int | numpy.random.Generator`` convention; each drawn scene is a normal
scene (it validates, and `to_yaml` writes it as a scene file that `mirrorsim evaluate`
reruns alone).
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mirrorsim import optics
from mirrorsim.errors import RunFailed, SceneError
from mirrorsim.model import PAN_WORDS, SAMPLERS, Camera, RenderSettings, Scene
from mirrorsim.scenefile import MAX_SPP, read_yaml, scene_from_dict
from solver.reader import Reader, show

DEFAULT_SPEC = Path(__file__).resolve().parents[1] / "scenes" / "dataset_spec.yaml"


DEFAULT_RENDER = RenderSettings()
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
            _check_model(r, m, f"camera.models[{k}]")
    _check_model(r, cam, "camera", ranges=True)  # its resolution (the models' default)
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
    if "render" in spec:
        r.mapping(spec["render"], "render", set(), {"spp", "sampler", "background_spp"})
        r.integer(spec["render"].get("spp", DEFAULT_RENDER.spp), "render.spp", low=1,
                  high=MAX_SPP)
        r.integer(spec["render"].get("background_spp", DEFAULT_RENDER.background_spp),
                  "render.background_spp", low=1, high=MAX_SPP)
        r.choice(spec["render"].get("sampler", DEFAULT_RENDER.sampler), "render.sampler",
                 SAMPLERS)
    r.integer(spec.get("max_tries", 5000), "max_tries", low=1, high=MAX_TRIES)
    # draws find range errors (wrong types, lo > hi) with their key, and a spec under
    # which no usable scene exists
    _draw(spec, np.random.default_rng(0), path)
    try:
        sample_scene(spec, 0, "probe", tries=min(PROBE_TRIES, spec.get("max_tries", 5000)))
    except NoValidScene as exc:
        raise r.fail("", str(exc)) from None
    return spec


def _check_model(r: Reader, m: Any, key: str, ranges: bool = False) -> None:
    """A camera model: mount height (cm), hfov (°), resolution; fixed numbers, or (for
    the camera block) ranges, which _value checks when it draws."""
    if not ranges:
        r.mapping(m, key, {"height", "hfov"}, {"resolution"})
        r.number(m["height"], f"{key}.height", positive=True)
        r.number(m["hfov"], f"{key}.hfov", low=1.0, high=179.0)
    res = m.get("resolution", [1920, 1088])
    if not isinstance(res, list) or len(res) != 2:
        raise r.fail(f"{key}.resolution", f"expected [width, height] in px, got {show(res)}")
    r.integer(res[0], f"{key}.resolution[0]", low=2)
    r.integer(res[1], f"{key}.resolution[1]", low=2)


def camera_models(spec: dict) -> list[Camera] | None:
    """The spec's camera models as cameras (position and pan irrelevant: what K depends
    on), or None when the spec draws heights or fields of view from ranges."""
    models = spec["camera"].get("models")
    if models is None:
        return None
    default = spec["camera"].get("resolution", [1920, 1088])
    return [Camera(position=(0.0, 0.0), height=float(m["height"]), hfov=float(m["hfov"]),
                   resolution=tuple(m.get("resolution", default)), pan=0.0, pan_deg=0.0)
            for m in models]


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
    models = spec["camera"].get("models")
    if models:  # a lab's few cameras, each on its mount: one calibration each
        m = models[int(rng.integers(len(models)))]
        height, hfov = float(m["height"]), float(m["hfov"])
        res = m.get("resolution", spec["camera"].get("resolution", [1920, 1088]))
    else:
        height, hfov = g("camera", "height"), g("camera", "hfov")
        res = spec["camera"].get("resolution", [1920, 1088])
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
            "render": _render_block(spec.get("render", {}))}


def _render_block(r: dict) -> dict:
    """A drawn scene's ``render`` block from the spec's (seed set per scene later)."""
    return {"spp": int(r.get("spp", DEFAULT_RENDER.spp)), "seed": 0,
            "sampler": r.get("sampler", DEFAULT_RENDER.sampler),
            "background_spp": int(r.get("background_spp", DEFAULT_RENDER.background_spp))}


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
    if len(scene.beacons) == 1:
        d["beacon"] = d.pop("beacons")[0]
    return yaml.safe_dump(d, sort_keys=False)
