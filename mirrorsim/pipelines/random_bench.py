"""A dataset spec's ``bench:`` block: each imperfection drawn from its value or its
[lo, hi] range, its keys and its ranges' ends checked; :mod:`mirrorsim.pipelines.random_scenes`
draws the rest of a scene."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mirrorsim.errors import SceneError
from mirrorsim.formats.reader import Reader, show
from mirrorsim.scene.imperfections import REGISTRY
from solver.measurements import is_number

BY_SPEC_PATH = {imp.spec_path: imp for imp in REGISTRY}

# The spec's optional `bench:` block: each imperfection of the registry under its spec key
# path, a value or a [lo, hi] range drawn per scene.  Two are drawn in another form: the
# mirror's `curvature` (1/cm, 0 = flat) instead of its radius, since the effect is linear
# in 1/R and a range of radii would pass through infinity; and the beacon's
# `known_position_offset` (cm, drawn for x and y alike) instead of a position.
BENCH_SPEC_KEYS: dict[str, set[str]] = {}
for _imp in REGISTRY:
    _block, _leaf = _imp.spec_path.split(".")
    BENCH_SPEC_KEYS.setdefault(_block, set()).add(_leaf)


OFFSET_IMPERFECTION = next(imp for imp in REGISTRY if imp.form == "offset")  # a believed position's


def draw_number(raw: Any, key: str, rng: np.random.Generator, *, where: str,
                integer: bool = False) -> float:
    """A spec's value, or a uniform draw from its [lo, hi] (integers for an integer key)."""
    r = Reader(where, SceneError)
    if isinstance(raw, list) and len(raw) == 2:
        lo, hi = r.number(raw[0], f"{key}[0]"), r.number(raw[1], f"{key}[1]")
        if lo > hi:
            raise r.fail(key, f"{raw}: the range's low end exceeds its high end")
        if integer:
            return int(rng.integers(math.ceil(lo), math.floor(hi) + 1))
        return float(rng.uniform(lo, hi))
    return int(r.integer(raw, key, low=-2**31, high=2**31)) if integer else r.number(raw, key)


def draw_bench(bench: dict, rng: np.random.Generator, where: str = "<spec>") -> dict[str, Any]:
    """One draw of the spec's bench block, as scene-file key paths → values."""
    out: dict[str, Any] = {}
    for block in BENCH_SPEC_KEYS:  # a fixed order: same seed, same draws
        raw = bench.get(block) or {}
        for key in sorted(raw):
            imp = BY_SPEC_PATH[f"{block}.{key}"]
            path, v = f"bench.{block}.{key}", raw[key]
            if imp.form == "lens":
                if not isinstance(v, list) or len(v) != 2:
                    raise Reader(where, SceneError).fail(path, f"expected [k1, k2] (each a "
                                                         f"value or [lo, hi]), got {show(v)}")
                out[imp.key] = [draw_number(v[j], f"{path}[{j}]", rng, where=where) for j in (0, 1)]
            elif imp.form == "flag":  # a value (the scene reader checks the bool), or
                # [true, false]: drawn per scene
                out[imp.key] = (bool(rng.integers(2)) if v == [True, False] or v == [False, True]
                                else v)
            elif imp.form == "noise":
                n = Reader(where, SceneError).mapping(v, path, {"full_well", "read_noise"})
                out[imp.key] = {k: draw_number(n[k], f"{path}.{k}", rng, where=where)
                                for k in ("full_well", "read_noise")}
            elif imp.form == "radius":  # drawn as the curvature 1/R
                c = draw_number(v, path, rng, where=where)
                if c != 0.0:
                    out[imp.key] = 1.0 / c
            elif imp.form == "offset":
                out[imp.spec_path] = [draw_number(v, path, rng, where=where) for _ in (0, 1)]
            else:
                out[imp.key] = draw_number(v, path, rng, where=where,
                                            integer=imp.form == "quality")
    return out


def set_key(d: dict, path: str, value: Any) -> None:
    """Set a drawn value in a scene document ``d`` at its key path (a believed position's
    offset: on the first beacon's position)."""
    block, key = path.split(".")
    imp = BY_SPEC_PATH.get(path)
    if imp is not None and imp.form == "offset":  # the first beacon's (_draw: the others')
        first = d["beacons"][0] if "beacons" in d else d["beacon"]
        first["known_position"] = [p + o for p, o in zip(first["position"], value, strict=True)]
    else:
        d.setdefault(block, {})[key] = value


def check_bench_keys(spec: dict, r: Reader) -> None:
    """The bench block's keys (its values are checked as they are drawn)."""
    bench = spec.get("bench")
    if bench is None:
        return
    r.mapping(bench, "bench", set(), optional=set(BENCH_SPEC_KEYS))
    for block, keys in BENCH_SPEC_KEYS.items():
        if block in bench:
            r.mapping(bench[block], f"bench.{block}", set(), optional=keys)


def range_end(raw: Any, end: int) -> Any:
    """A spec value with each [lo, hi] range replaced by its low (0) or high (1) end."""
    if isinstance(raw, dict):
        return {k: range_end(v, end) for k, v in raw.items()}
    if isinstance(raw, list) and len(raw) == 2 and all(is_number(x) for x in raw):
        return raw[end]
    if isinstance(raw, list):
        return [range_end(v, end) for v in raw]
    return raw
