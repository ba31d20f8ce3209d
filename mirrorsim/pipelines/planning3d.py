"""A beacon's height in a 3-D scene (``mirrorsim plan`` of a scene with a raised object or
a leaning mirror): at each planned position, the post (0 to MAX_POST_CM) whose beacon
gives the target the least Cramér–Rao bound of the 3-D solve (:func:`solver.lsq3.crlb3`)
at the scene's mirror plane, its lean counted, among those whose image the glass shows
whole.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from mirrorsim.scene.model import FRONT_OFFSET, Beacon, Scene, pencil_paint_height
from mirrorsim.truth import optics, visibility
from solver.errors import SolverError
from solver.lsq3 import crlb3
from solver.measurements import ObjectSigmas

MAX_POST_CM = 15.0  # the highest post tried (the heights the 3-D results were measured on)
POST_STEP_CM = 1.0  # the posts tried, this far apart


@dataclass(frozen=True)
class HeightChoice:
    """The posts tried for a beacon at ``position``: each height whose image the glass
    shows whole, the target's 3-D RMS bound with that beacon alone (cm; NaN where the
    geometry does not determine the target), and the best of them (None: none shown)."""

    position: tuple[float, float]
    heights: tuple[float, ...]
    rmse: tuple[float, ...]

    @property
    def best(self) -> tuple[float, float] | None:
        """(height, RMS bound) of the best post, or None."""
        ok = [(r, z) for z, r in zip(self.heights, self.rmse, strict=True) if math.isfinite(r)]
        return None if not ok else (min(ok)[1], min(ok)[0])

    def to_json(self) -> dict:
        """One entry of the plan's ``beacon_heights`` (NaN bounds as null)."""
        best = self.best
        return {"position": list(self.position), "heights": list(self.heights),
                "rmse": [r if math.isfinite(r) else None for r in self.rmse],
                "best_height": None if best is None else best[0],
                "best_rmse": None if best is None else best[1]}


def height_choices(scene: Scene, sigma: ObjectSigmas,
                   positions: list[tuple[float, float]]) -> tuple[HeightChoice, ...]:
    """For a beacon like the scene's first at each of ``positions``, the posts 0,
    POST_STEP_CM, … MAX_POST_CM (:class:`HeightChoice`).  Each image's elevation is
    taken to be measured as well as its α (σ_ε = σ_α, as ``montecarlo``'s 3-D rows
    assume), every image's σ's the target's and the beacon's of ``sigma``."""
    pencil = scene.beacons[0].height
    plane = optics.mirror_plane(scene.camera, scene.mirror)
    t, b = sigma.target, sigma.beacons[0]
    sig = np.array([(b.alpha_deg, b.alpha_deg, b.d_total_rel),
                    (t.alpha_deg, t.alpha_deg, t.d_total_rel)])
    posts = np.arange(0.0, MAX_POST_CM + 1e-9, POST_STEP_CM)
    out = []
    for p in positions:
        heights, rmse = [], []
        for z in posts:
            beacon = Beacon((float(p[0]), float(p[1])), pencil, z=float(z))
            moved = replace(scene, beacons=(beacon,))
            if visibility.visibility(moved, beacon).fraction < 1.0:
                continue
            heights.append(float(z))
            rmse.append(_bound(scene, plane, beacon, sig))
        out.append(HeightChoice((float(p[0]), float(p[1])), tuple(heights), tuple(rmse)))
    return tuple(out)


def _bound(scene: Scene, plane, beacon: Beacon, sig: np.ndarray) -> float:
    """The target's 3-D RMS bound (cm) with ``beacon`` alone, or NaN."""
    try:
        bound = crlb3(scene.camera.center3, [beacon.base3], plane, target=scene.target.base3,
                      sigma=sig, heights=(pencil_paint_height(beacon.height),
                                          scene.target.size[1]),
                      fronts=(FRONT_OFFSET["beacon"], FRONT_OFFSET["target"]),
                      pan_deg=scene.camera.pan_deg)
    except SolverError:
        return math.nan
    return float(np.sqrt(np.trace(bound[3:6, 3:6])))
