"""A frame's depth and normals, from Mitsuba's ``aov`` integrator (``dataset --aov``).

``depth`` is the distance (cm) along each camera ray to the first surface it meets (the
glass, where the pixel sees the mirror: not the reflected object's), and ``normals``
that surface's shading normal in the board's frame (x, y along the board, z up; unit
vectors).  Each pixel's value is the mean of :data:`AOV_SPP` samples over its area, as
the frame's pixels are: at an object's outline, a blend of both surfaces (a normal
there is shorter than 1).  A pixel that sees nothing holds 0.  A distorting lens warps
them as it warps the frame (nearest pixel).
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from mirrorsim.camera.sensor import distort
from mirrorsim.rendering.backend import choose_variant
from mirrorsim.rendering.mitsuba_scene import build_scene_dict
from mirrorsim.rendering.passes import pass_seed, pinhole_scene, variant_scope
from mirrorsim.scene.model import Scene
from mirrorsim.scene.render_settings import AOVS

AOV_SPP = 16  # per pixel: an edge's blend resolved to 1/16 of a pixel's area
AOV_NEAR_CLIP = 1e-4  # cm: the frame's sensor starts its rays 0.1 cm out
AOV_STREAM = 1 << 20  # its seed stream, apart from the frame's passes' and tiles'


__all__ = ["AOVS", "AOV_SPP", "render_aovs"]


def render_aovs(scene: Scene, names: tuple[str, ...], *, variant: str = "auto"
                ) -> dict[str, np.ndarray]:
    """The frame's ``names`` (of :data:`AOVS`) as float32 arrays: depth (H, W) in cm,
    normals (H, W, 3)."""
    k = scene.bench.distortion
    lens = k != (0.0, 0.0)
    pinhole = pinhole_scene(scene)
    with variant_scope(choose_variant(variant)):
        d = build_scene_dict(pinhole)
        d["integrator"] = {"type": "aov", "aovs": "dd:depth,nn:sh_normal"}
        # a ray starts at the near clip plane, and the depth is counted from there: a
        # plane as near as floats allow, so that it is counted from the lens
        d["sensor"] = {**d["sensor"], "near_clip": AOV_NEAR_CLIP}
        image = np.array(mi.render(mi.load_dict(d, optimize=False), spp=AOV_SPP,
                                   seed=pass_seed((scene.render.seed, AOV_STREAM), 0)),
                         dtype=np.float32)
    if lens:
        image = distort(image, scene.camera, k, nearest=True)
    out = dict(zip(AOVS, (image[..., 0], image[..., 1:4]), strict=True))
    return {n: np.ascontiguousarray(out[n]) for n in names}
