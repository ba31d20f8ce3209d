"""Random valid scenes for datasets, drawn from the ranges of a spec file.

Seeded with the ``int | numpy.random.Generator`` convention; each drawn scene is a normal
scene (it validates, and `to_yaml` writes it as a scene file that `mirrorsim evaluate`
reruns alone).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from mirrorsim.errors import BadParameter, RunFailed, SceneError
from mirrorsim.formats.dataset_table import MAX_BEACONS
from mirrorsim.formats.reader import Reader, read_resolution, read_yaml, show
from mirrorsim.formats.scenefile import (
    DEFAULT_RESOLUTION,
    read_camera_model,
    read_pan,
    read_render,
    scene_document,
)
from mirrorsim.pipelines.random_bench import (
    BENCH_SPEC_KEYS,
    BY_SPEC_PATH,
    OFFSET_IMPERFECTION,
    check_bench_keys,
    draw_bench,
    draw_number,
    range_end,
    set_key,
)
from mirrorsim.pipelines.random_raised import (
    check_3d_keys,
    draw_3d_into,
    drawn_from,
    spec_is_3d,
)
from mirrorsim.pipelines.scenes import scene_from_dict
from mirrorsim.scene.model import MAX_BOARD_CM, Camera, Scene
from mirrorsim.truth import visibility

# the bundled spec, from the package's data (a wheel carries the clone's scenes/)
DEFAULT_SPEC = Path(__file__).resolve().parents[1] / "data" / "scenes" / "dataset_spec.yaml"


MAX_TRIES = 100_000  # a documented bound on a spec's max_tries
PROBE_TRIES = 300  # a spec that gives no valid scene in this many draws is refused at once


class NoValidScene(RunFailed):
    """No draw of a spec gave a usable scene (the scene's own failure in a dataset)."""


@dataclasses.dataclass(frozen=True)
class DatasetSpec:
    """A checked dataset spec: ``data`` as its file gives it (what a dataset's
    ``dataset.json`` keeps), and what other modules read of it."""

    data: dict

    @property
    def max_tries(self) -> int:
        """Draws allowed for one usable scene."""
        return int(self.data.get("max_tries", 5000))

    @property
    def target_size(self) -> tuple[float, float] | None:
        """The target panel's (width, height), cm; None where the spec draws them from
        ranges (each scene then has its own)."""
        size = self.data["target"]["size"]
        return None if any(isinstance(x, list) for x in size) else tuple(size)

    @property
    def beacon_height(self) -> float | list[float]:
        """The pencil's height (cm): a value, or a [lo, hi] range drawn per scene."""
        return self.data["beacon"]["height"]

    @property
    def beacon_count(self) -> int:
        """The fewest beacons a scene has (the spec's ``beacon.count``, a value or a
        [lo, hi] range drawn per scene; default 1): what every scene can carry."""
        count = self.data["beacon"].get("count", 1)
        return int(count[0] if isinstance(count, list) else count)

    @property
    def calibration_error(self) -> float | list[float]:
        """The bench's calibration distance error (cm): a value or a range."""
        bench = self.data.get("bench") or {}
        return (bench.get("calibration") or {}).get("distance_error", 0.0)

    @property
    def is_3d(self) -> bool:
        """Whether its scenes leave the board's plane (:mod:`~.random_raised`)."""
        return spec_is_3d(self.data)

    def with_beacon_count(self, count: int) -> DatasetSpec:
        """The spec with ``count`` beacons a scene (part of the spec, so that a resumed
        dataset checks it).

        Raises
        ------
        BadParameter
            For a count outside 1..MAX_BEACONS.
        """
        if not 1 <= count <= MAX_BEACONS:
            raise BadParameter("beacons", f"{count} must be within 1..{MAX_BEACONS}")
        if count == self.beacon_count:  # the spec as it is: a resumed run compares it
            return self
        data = {**self.data, "beacon": {**self.data["beacon"], "count": count}}
        return dataclasses.replace(self, data=data)

    def with_sampler(self, sampler: str) -> DatasetSpec:
        """The spec with its scenes rendered by ``sampler`` (part of the spec, so that a
        resumed dataset checks it)."""
        data = {**self.data, "render": {**self.data.get("render", {}), "sampler": sampler}}
        return dataclasses.replace(self, data=data)


def load_spec(path: str | Path | None = None) -> DatasetSpec:
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
              optional={"render", "max_tries", "bench"})
    r.mapping(spec["board"], "board", {"size"}, optional={"hole_pitch"})
    r.pair(spec["board"]["size"], "board.size", positive=True, high=MAX_BOARD_CM)
    _check_camera_block(spec, r)
    r.mapping(spec["mirror"], "mirror", {"x", "y", "yaw", "width", "height"},
              optional={"lean"})
    _check_target_and_beacon(spec, r)
    check_3d_keys(spec, r)
    r.mapping(spec["occluder"], "occluder", {"at", "length", "height"})
    read_render(r, spec.get("render", {}), seed=False)
    r.integer(spec.get("max_tries", 5000), "max_tries", low=1, high=MAX_TRIES)
    check_bench_keys(spec, r)
    # draws find range errors (wrong types, lo > hi) with their key, and a spec under
    # which no usable scene exists
    _draw(spec, np.random.default_rng(0), path)
    try:  # the bench's ranges at their ends first, each refused by its own key: a range
        # so wide that no draw is usable says which range, not only that none was
        check_bench_ends(spec, r)
        _sample(spec, 0, "probe", tries=min(PROBE_TRIES, spec.get("max_tries", 5000)))
    except NoValidScene as exc:
        raise r.fail("", str(exc)) from None
    return DatasetSpec(spec)


def _check_camera_block(spec: dict, r: Reader) -> None:
    """A spec's ``camera`` block: its keys, its models (or its height and field of view
    beside none), its resolution and its pan."""
    cam = r.mapping(spec["camera"], "camera", {"x", "y"},
                    optional={"height", "hfov", "resolution", "pan", "models"})
    if "models" in cam:
        if not isinstance(cam["models"], list) or not cam["models"]:
            raise r.fail("camera.models", f"expected a list of camera models, got "
                         f"{show(cam['models'])}")
        extra = {"height", "hfov"} & set(cam)  # a resolution beside them is their default
        if extra:
            raise r.fail(f"camera.{sorted(extra)[0]}", "give it in each of camera.models, "
                         "not beside them")
        for k, m in enumerate(cam["models"]):
            r.mapping(m, f"camera.models[{k}]", {"height", "hfov"}, optional={"resolution"})
    # the resolution (beside models: their default); heights and fields of view drawn
    # from ranges are checked by _value as it draws
    read_resolution(r, cam.get("resolution", DEFAULT_RESOLUTION), "camera.resolution")
    if "models" in cam:
        _camera_models(spec, r)
    read_pan(r, spec["camera"].get("pan", "mirror"), "camera.pan")


def _check_target_and_beacon(spec: dict, r: Reader) -> None:
    """A spec's ``target`` block (its size a pair of values, each a value or a range) and
    its ``beacon`` block (a count within 1..MAX_BEACONS)."""
    r.mapping(spec["target"], "target", {"x", "y", "size"}, optional={"z"})
    size = spec["target"]["size"]
    if isinstance(size, list) and len(size) == 2 and any(isinstance(x, list) for x in size):
        for k, x in enumerate(size):  # [width, height], each a value or [lo, hi]
            for j, v in enumerate(x if isinstance(x, list) else [x]):
                r.number(v, f"target.size[{k}]" + (f"[{j}]" if isinstance(x, list) else ""),
                         positive=True)
    else:
        r.pair(size, "target.size", positive=True)
    r.mapping(spec["beacon"], "beacon", {"depth", "along", "height"},
              optional={"count", "z"})
    count = spec["beacon"].get("count", 1)
    for k, c in enumerate(count if isinstance(count, list) and len(count) == 2 else [count]):
        r.integer(c, f"beacon.count[{k}]" if isinstance(count, list) else "beacon.count",
                  low=1, high=MAX_BEACONS)


def camera_models(spec: DatasetSpec) -> list[Camera] | None:
    """The spec's camera models as cameras (position and pan irrelevant: what K depends
    on), or None when the spec draws heights or fields of view from ranges.  A
    resolution beside the models is their default."""
    return _camera_models(spec.data)


def _camera_models(spec: dict, r: Reader | None = None) -> list[Camera] | None:
    models = spec["camera"].get("models")
    if models is None:
        return None
    r = r or Reader("<spec>", SceneError)
    default = spec["camera"].get("resolution", DEFAULT_RESOLUTION)
    cams = []
    for k, m in enumerate(models):
        height, hfov, res = read_camera_model(r, m, f"camera.models[{k}]",
                                              default_resolution=default)
        cams.append(Camera(position=(0.0, 0.0), height=height, hfov=hfov, resolution=res,
                           pan=0.0, pan_deg=0.0))
    return cams


def _value(spec: dict, block: str, key: str, rng: np.random.Generator, where) -> Any:
    r = Reader(where, SceneError)
    if not isinstance(spec[block], dict):
        raise r.fail(block, f"expected a mapping, got {show(spec[block])}")
    v = spec[block].get(key)
    if v is None:
        raise r.fail(f"{block}.{key}", "missing required key (a number or [lo, hi])")
    return draw_number(v, f"{block}.{key}", rng, where=where)


def _draw(spec: dict, rng: np.random.Generator, where="<spec>",
          bench_rng: np.random.Generator | None = None) -> dict:
    """One candidate scene dict (not yet validated); the bench imperfections drawn from
    ``bench_rng`` (default: ``rng``)."""
    g = lambda block, key: _value(spec, block, key, rng, where)  # noqa: E731
    cam = _draw_camera(spec, rng, g)
    yaw = g("mirror", "yaw")
    centre = np.array([g("mirror", "x"), g("mirror", "y")])
    mirror = {"center": centre.tolist(), "yaw": yaw,
              "size": [g("mirror", "width"), g("mirror", "height")]}
    target = {"position": [g("target", "x"), g("target", "y")],
              "size": [draw_number(x, f"target.size[{k}]", rng, where=where)
                       for k, x in enumerate(spec["target"]["size"])]}
    # the beacon in front of the mirror (on the camera's side)
    n = np.array([-math.sin(math.radians(yaw)), math.cos(math.radians(yaw))])
    if n @ (np.asarray(cam["position"]) - centre) < 0:
        n = -n
    along = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw))])

    def beacon(height: float | None = None) -> dict:
        b = centre + g("beacon", "depth") * n + g("beacon", "along") * along
        return {"position": b.tolist(),
                "height": g("beacon", "height") if height is None else height}

    beacons = [beacon()]
    # a wall across the direct line camera → target, perpendicular to it
    c, t = np.asarray(cam["position"]), np.asarray(target["position"])
    mid = c + g("occluder", "at") * (t - c)
    u = (t - c) / max(np.linalg.norm(t - c), 1e-9)
    half = g("occluder", "length") / 2 * np.array([-u[1], u[0]])
    occ = {"start": (mid - half).tolist(), "end": (mid + half).tolist(),
           "height": g("occluder", "height")}
    # the other beacons drawn after everything else: a spec of one beacon draws as before
    # (one pencil height for all: the calibration and the detector take one)
    count = draw_number(spec["beacon"].get("count", 1), "beacon.count", rng, where=where,
                         integer=True)
    beacons += [beacon(beacons[0]["height"]) for _ in range(count - 1)]
    # one beacon under the scene file's "beacon" key: a refusal names the key a spec has
    d = {"board": copy.deepcopy(spec["board"]), "camera": cam, "mirror": mirror,
         "target": target, **({"beacon": beacons[0]} if len(beacons) == 1 else
                              {"beacons": beacons}), "occluders": [occ],
         "render": dataclasses.asdict(read_render(Reader(where, SceneError),
                                                  spec.get("render", {}), seed=False))}
    # from their own stream, so that a bench block leaves the geometry drawn as without it
    _draw_bench_into(d, spec, beacons, bench_rng or rng, where)
    draw_3d_into(d, spec, rng, where=where)
    return d


def _draw_camera(spec: dict, rng: np.random.Generator, g: Callable[[str, str], Any]) -> dict:
    """A candidate scene's camera block: its position, and one of the spec's models (a
    lab's few cameras, each on its mount: one calibration each) or a drawn height and
    field of view."""
    position = [g("camera", "x"), g("camera", "y")]
    models = _camera_models(spec)
    if models:
        c = models[int(rng.integers(len(models)))]
        height, hfov, res = c.height, c.hfov, c.resolution
    else:
        height, hfov = g("camera", "height"), g("camera", "hfov")
        res = spec["camera"].get("resolution", DEFAULT_RESOLUTION)
    return {"position": position, "height": height, "hfov": hfov, "resolution": list(res),
            "pan": spec["camera"].get("pan", "mirror")}


def _draw_bench_into(d: dict, spec: dict, beacons: list[dict], bench_rng: np.random.Generator,
                     where: str) -> None:
    """The spec's bench block drawn into the candidate ``d`` (its ``beacons``), each
    further beacon's believed position off by its own draw."""
    for path, value in draw_bench(spec.get("bench") or {}, bench_rng, where).items():
        set_key(d, path, value)
    block, key = OFFSET_IMPERFECTION.spec_path.split(".")
    offset = ((spec.get("bench") or {}).get(block) or {}).get(key)
    if offset is not None:
        key_path = f"bench.{OFFSET_IMPERFECTION.spec_path}"
        for b in beacons[1:]:
            b["known_position"] = [p + draw_number(offset, key_path, bench_rng, where=where)
                                   for p in b["position"]]


def sample_scene(spec: DatasetSpec, rng: int | np.random.Generator | None, name: str,
                 *, tries: int | None = None) -> Scene:
    """Draw until a usable scene comes: valid, NLOS, both images whole in the mirror.

    Raises
    ------
    NoValidScene
        If ``tries`` (default: the spec's ``max_tries``) draws give none, saying why the
        draws were refused most often.
    """
    return _sample(spec.data, rng, name, spec.max_tries if tries is None else tries)


def _sample(spec: dict, rng: int | np.random.Generator | None, name: str,
            tries: int | None = None) -> Scene:
    rng = np.random.default_rng(rng)
    bench_rng = rng.spawn(1)[0]  # spawning leaves rng's own stream as it was
    tries = int(spec.get("max_tries", 5000)) if tries is None else tries
    reasons: dict[str, int] = {}
    for _ in range(tries):
        d = _draw(spec, rng, bench_rng=bench_rng)
        d["name"] = name
        try:
            s = scene_from_dict(d, source=name, default_name=name)
        except SceneError as exc:
            why = f"the scene's {exc.key or 'file'}{drawn_from(exc.key)}"
            reasons[why] = reasons.get(why, 0) + 1
            continue
        if s.warnings:
            why = "an image clipped or the target seen directly"
            reasons[why] = reasons.get(why, 0) + 1
            continue
        if all(visibility.visibility(s, o).fraction == 1.0 for o in (s.target, *s.beacons)):
            return s
        why = "an image not whole in the mirror"
        reasons[why] = reasons.get(why, 0) + 1
    common = sorted(reasons, key=reasons.get, reverse=True)[:2] or ["nothing"]
    why = ", then ".join(f"{c}: {reasons.get(c, 0)} times" for c in common)
    raise NoValidScene(f"no usable scene in {tries} draws (refused most often for {why}); "
                       "widen the spec's ranges")


def to_yaml(scene: Scene) -> str:
    """The scene as a scene file (docs/scenes.md's format)."""
    return yaml.safe_dump(scene_document(scene), sort_keys=False)


def check_bench_ends(spec: dict, r: Reader) -> None:
    """Each of the bench block's ranges at both ends, as a scene file would take it (a
    tilt range reaching 45° is refused here, not thinned out silently by the draws)."""
    bench = spec.get("bench")
    if bench is None:
        return
    ideal = _sample({**spec, "bench": None}, 0, "probe",
                         tries=min(PROBE_TRIES, spec.get("max_tries", 5000)))
    base = yaml.safe_load(to_yaml(ideal))
    for block in BENCH_SPEC_KEYS:
        for key, raw in (bench.get(block) or {}).items():
            for end in (0, 1):  # each range's low end, then its high end
                lens = BY_SPEC_PATH[f"{block}.{key}"].form == "lens"
                pick = ([range_end(x, end) for x in raw] if lens and isinstance(raw, list)
                        else range_end(raw, end))
                d = copy.deepcopy(base)
                for path, value in draw_bench({block: {key: pick}},
                                               np.random.default_rng(0), r.source).items():
                    set_key(d, path, value)
                try:
                    scene_from_dict(d, source=str(r.source), default_name="probe")
                except SceneError as exc:  # named by the spec's key, with the reason
                    raise r.fail(f"bench.{block}.{key}", f"{show(raw)}: {exc.key}: "
                                 f"{exc.message}") from None
