"""How a scene is rendered: samples per pixel, the sampler and its seed, with the
bounds every consumer holds them to."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mirrorsim.errors import BadParameter

# Mitsuba samplers a scene may name: plain random, or stratified in every dimension
# (any sample count; edges converge faster, see docs/performance.md)
SAMPLERS = ("independent", "multijitter")
MAX_SPP = 1 << 16  # a documented bound: more samples than this is a typo, not a render

# what Mitsuba's aov integrator renders besides a frame, where asked
# (mirrorsim.rendering.aov): each a file beside the frame, <frame>.<name>.npy
AOVS = ("depth", "normals")


@dataclass(frozen=True)
class RenderSettings:
    """Samples per pixel, the sampler and its seed."""

    # chosen by benchmarks/detect.py over 40 random scenes (docs/performance.md): multijitter
    # at 8 spp measures as well as independent sampling at 16, in half the time
    spp: int = 8
    seed: int = 0
    sampler: str = "multijitter"
    # samples per pixel outside the mirror's image (renders use min(this, spp); set it
    # to spp for a uniform frame).  Every measurement is made in the mirror's image, so
    # the samples are spent there (docs/performance.md)
    background_spp: int = 2
    # samples per pixel in each beacon's image (renders use max(this, spp), and more for
    # an image under SMALL_BEACON_PX): its d_total rests on two of its edges, whose
    # render noise at 8 spp was the largest part of its error; the box costs 15 % of a
    # dataset's throughput (docs/results.md, docs/performance.md)
    beacon_spp: int = 128

    def __post_init__(self):
        # the one check of the render settings, wherever they come from (a scene file, a
        # spec, a flag): the scene reader and the CLI name the key or flag it refuses
        for name in ("spp", "background_spp", "beacon_spp"):
            value = getattr(self, name)
            if not (is_whole(value) and 1 <= value <= MAX_SPP):
                raise BadParameter(name, f"{value!r} must be a whole number within 1..{MAX_SPP}")
        if not (is_whole(self.seed) and 0 <= self.seed <= MAX_SEED):
            raise BadParameter("seed", f"{self.seed!r} must be a whole number within "
                               f"0..{MAX_SEED}")
        if self.sampler not in SAMPLERS:
            raise BadParameter("sampler", f"{self.sampler!r}: expected one of "
                               f"{', '.join(SAMPLERS)}")

    # the effective sample counts, declared once (the renderer spends them, a dataset's
    # row records them): never more outside the mirror, never fewer in a beacon's image,
    # than the frame's spp
    def outside_spp(self, spp: int | None = None) -> int:
        """Samples per pixel outside the mirror's image for a frame of ``spp`` (default
        this setting's): ``min(background_spp, spp)``."""
        return min(self.background_spp, self.spp if spp is None else spp)

    def beacon_box_spp(self, spp: int | None = None, image_px: float | None = None) -> int:
        """Samples per pixel in a beacon's image for a frame of ``spp`` (default this
        setting's): ``max(beacon_spp, spp)``, times :func:`small_image_factor` of its
        whole image's height ``image_px`` (board to tip) where a box is rendered
        (beacon_spp above spp)."""
        frame = self.spp if spp is None else spp
        base = max(self.beacon_spp, frame)
        if image_px is None or base <= frame:  # no box rendered: none to add to
            return base
        return min(MAX_SPP, base * small_image_factor(image_px))


# a beacon whose image, board to tip, is shorter than this (px) takes more samples: at
# beacon_spp 128 the render noise of its two edges put a band of 12-20 px (whole images
# of 17-28 px) 0.64 % RMS off in d_total (23 images of two ideal acceptance sets, up to
# 1.16 %); one such scene's two 15-16 px bands read 0.00-0.37 % off at 512 spp over
# three seeds, against 0.31-1.11 % at 128.  The factor is the square of the shortfall,
# rounded up to a power of 2 and at most SMALL_BEACON_MAX: the samples a frame spends on
# a beacon's image then grow as its image shrinks, at most 8 times those of one 64 px
# tile at beacon_spp (its box, margins and all, fits one or two such tiles)
SMALL_BEACON_PX, SMALL_BEACON_MAX = 40.0, 8


def small_image_factor(image_px: float) -> int:
    """How many times beacon_spp a beacon's image ``image_px`` tall takes: 1 from
    SMALL_BEACON_PX up, else (SMALL_BEACON_PX / image_px)² rounded up to a power of 2, at
    most SMALL_BEACON_MAX."""
    if image_px >= SMALL_BEACON_PX:
        return 1
    want = (SMALL_BEACON_PX / max(image_px, 1.0)) ** 2
    return min(SMALL_BEACON_MAX, 1 << max(0, math.ceil(math.log2(want))))


# the largest seed every consumer takes, a render's or a run's: numpy's generators take
# more, and a render hashes its seed into Mitsuba's 32-bit ones (passes._pass_seed), but
# a Parquet int64 column (a dataset's `seed` and `render_seed`) does not
MAX_SEED = 2**63 - 1


def is_whole(v: object) -> bool:
    """An integer (numpy's too), not a bool: a count or a seed, wherever one is taken."""
    return isinstance(v, int | np.integer) and not isinstance(v, bool)
