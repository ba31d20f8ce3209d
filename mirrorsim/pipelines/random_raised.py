"""A dataset spec's 3-D keys (docs/results.md, *Datasets and the error model*): the
target and each beacon raised on a stand (``target.z``, ``beacon.z``: cm of its base
above the board) and the mirror leaning (``mirror.lean``, deg), each a value or a [lo,
hi] range.  A spec with any of
them makes a 3-D dataset: every scene is solved in 3-D
(:func:`~mirrorsim.pipelines.evaluate3d.evaluate_into3`) and its rows carry the
elevations.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from mirrorsim.formats.reader import Reader, show
from mirrorsim.pipelines.random_bench import draw_number
from mirrorsim.scene.model import MAX_LEAN_DEG

# (block, key) of each 3-D key, in the order they are drawn
KEYS_3D = (("mirror", "lean"), ("target", "z"), ("beacon", "z"))


def spec_is_3d(spec: dict) -> bool:
    """Whether the spec (as its file gives it) draws anything off the board's plane."""
    return any(isinstance(spec.get(block), dict) and key in spec[block]
               for block, key in KEYS_3D)


def check_3d_keys(spec: dict, r: Reader) -> None:
    """Each 3-D key's value or range: a height at or above the board, a lean within
    ±MAX_LEAN_DEG (a scene file's bounds; the rest, such as an object under the leaning
    glass, refuses a draw as ``check`` refuses the scene)."""
    for block, key in KEYS_3D:
        raw = spec[block].get(key)
        if raw is None:
            continue
        if isinstance(raw, list) and len(raw) != 2:
            raise r.fail(f"{block}.{key}", f"expected a number or [lo, hi], got {show(raw)}")
        low, high = (0.0, None) if key == "z" else (-MAX_LEAN_DEG, MAX_LEAN_DEG)
        for j, v in enumerate(raw if isinstance(raw, list) else [raw]):
            r.number(v, f"{block}.{key}" + (f"[{j}]" if isinstance(raw, list) else ""),
                     low=low, high=high)


def draw_3d_into(d: dict, spec: dict, rng: np.random.Generator, *, where: Any) -> None:
    """The spec's 3-D keys drawn into the candidate scene ``d`` (the mirror's lean, the
    target's height, each beacon's own): drawn after everything else, so that a planar
    spec draws exactly as before."""
    def drawn(block: str, key: str) -> float:
        return draw_number(spec[block][key], f"{block}.{key}", rng, where=where)

    if "lean" in spec["mirror"]:
        d["mirror"]["lean"] = drawn("mirror", "lean")
    if "z" in spec["target"]:
        d["target"]["position"] = [*d["target"]["position"][:2], drawn("target", "z")]
    if "z" in spec["beacon"]:
        for b in d.get("beacons") or [d["beacon"]]:
            b["position"] = [*b["position"][:2], drawn("beacon", "z")]


def drawn_from(key: str | None) -> str:
    """`` (the spec's <key>)`` for a scene's key that a spec's key of another name draws
    (an object's height above the board: its position's z; ``beacon.`` in a scene of
    one beacon, ``beacons[i].`` of several), else nothing: a spec whose draws that key
    refuses is told by the key it wrote."""
    spec_key = ("target.z" if key == "target.position[2]"
                else "beacon.z" if re.fullmatch(r"beacons?(\[\d+\])?\.position\[2\]",
                                                key or "")
                else None)
    return "" if spec_key is None else f" (the spec's {spec_key})"
