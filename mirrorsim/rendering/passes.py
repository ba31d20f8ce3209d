"""Rendering with Mitsuba 3: the frame and an object-id pass through the mirror, as arrays.

With :mod:`mirrorsim.rendering.mitsuba_scene` and :mod:`mirrorsim.rendering.backend`, the
only code that touches Mitsuba.  The variant is chosen by
:func:`mirrorsim.rendering.backend.choose_variant` and set only inside
:func:`variant_scope`, never at import.  Writing the frame's files and its ground truth
is :mod:`mirrorsim.rendering.frames`' job.
"""

from __future__ import annotations

import contextlib
import contextvars
import hashlib
import json
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, replace

import mitsuba as mi
import numpy as np

from mirrorsim.camera.sensor import add_noise, distort, distortion_canvas, to_srgb8
from mirrorsim.progress import progress_bar
from mirrorsim.rendering.backend import choose_variant
from mirrorsim.rendering.frozen import frozen_renders, render_call
from mirrorsim.rendering.id_pass import id_pass
from mirrorsim.rendering.mitsuba_scene import (
    aim_tile,
    build_direct_dict,
    build_scene_dict,
)
from mirrorsim.rendering.shapes import COLOURS
from mirrorsim.scene.imperfections import optics_of
from mirrorsim.scene.model import STAND_RADIUS, Beacon, Board, Camera, Scene, Target
from mirrorsim.truth import optics
from mirrorsim.truth.groundtruth import RenderInfo

# samples per render call: one progress step each.  A stratified sampler stratifies
# within a call, so the passes are large; a dataset's few-spp frame is one call.
PASS_SPP = 16
# part of a frame's fingerprint: bump when renders change
RENDER_METHOD = "passes16-ss-glass0-tiles"
# the boxes are rendered in fixed square tiles (one compiled kernel per size for every
# scene): the mirror's box at the frame's spp in tiles of MIRROR_TILE px, each beacon's
# box at beacon_spp (a short image's at more) in tiles of BEACON_TILE px (small: its
# samples are 16× dearer)
MIRROR_TILE, BEACON_TILE = 128, 64
# samples per render call of a tile at most: a beacon's 64² tile takes its 128 spp in
# two calls, not eight (each call costs ~5 ms besides its samples)
TILE_SAMPLES = 1 << 20
MITSUBA_VERSION = mi.__version__


@dataclass(frozen=True)
class RenderedFrame:
    """A rendered frame as arrays.

    ``linear`` is linear RGB (H, W, 3) float32; ``first`` and ``in_mirror`` are the id
    pass's labels (see :func:`id_pass`).
    """

    linear: np.ndarray
    first: np.ndarray
    in_mirror: np.ndarray
    info: RenderInfo  # how it was rendered (the truth file's ``render`` block)


@dataclass(frozen=True)
class _Optics:
    """What Mitsuba rendered of a scene, before the sensor: linear RGB (after the lens),
    the id pass's labels and how it was sampled."""

    linear: np.ndarray
    first: np.ndarray
    in_mirror: np.ndarray
    background_spp: int | None
    beacon_spp: int | None
    seconds: float
    beacon_box_spp: tuple[int, ...] = ()  # each box's, in the beacons' order (off the film: none)


@dataclass
class _Kept:
    """The renders kept by one :func:`reusing_renders` scope, at most ``capacity``."""

    capacity: int
    renders: dict[str, _Optics] = field(default_factory=dict)


# the innermost reusing_renders scope of this thread or task (None: nothing is kept); a
# context variable rather than a module global, so that a scope on one thread does not
# hand its renders to another
_KEPT: contextvars.ContextVar[_Kept | None] = contextvars.ContextVar("kept_renders",
                                                                    default=None)


@contextlib.contextmanager
def reusing_renders(capacity: int) -> Iterator[None]:
    """Within this scope, the first ``capacity`` renders are kept in memory, and a later
    frame whose optics are the same (:func:`~mirrorsim.scene.imperfections.optics_of`: it
    differs only in sensor noise, JPEG, or what the experimenter believes) takes its
    render from there: bit for bit the render it would have made.  The error budget keeps
    the ideal bench's frames, which half of its sources share."""
    token = _KEPT.set(_Kept(capacity))
    try:
        yield
    finally:
        _KEPT.reset(token)


def scene_fingerprint(scene: Scene) -> str:
    """What a render depends on: the scene's content with its render settings (not the
    file it came from) and the way frames are rendered."""
    d = asdict(replace(scene, source="", warnings=()))
    # the 3-D fields at their planar values are left out: a planar scene keeps the
    # fingerprint (and the cached frames) it had before there were any
    for block in (d["mirror"], d["target"], *d["beacons"]):
        for key in ("lean", "z"):
            if block.get(key) == 0.0:
                del block[key]
    text = json.dumps(d, sort_keys=True, default=str) + f"|{RENDER_METHOD}"
    # a short beacon image's extra samples (RenderSettings.beacon_box_spp), where it has
    # one: the scenes without keep the fingerprint (and the cached frames) they had
    boxes = [n for _, n, stream, _ in _regions(pinhole_scene(scene), scene.render.spp)[4]
             if stream >= 2]
    if any(n > scene.render.beacon_box_spp() for n in boxes):
        text += f"|beacon boxes {boxes}"
    if scene.is_3d:  # what only a 3-D scene renders: its posts
        text += f"|posts {COLOURS['stand']} {COLOURS['panel_stand']} {STAND_RADIUS}"
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@contextlib.contextmanager
def variant_scope(name: str) -> Iterator[None]:
    """Scope the process-global Mitsuba variant (variant_context needs a previous one)."""
    if mi.variant() is None:
        mi.set_variant(name)
        yield
    else:
        with mi.variant_context(name):
            yield


def render_frame(scene: Scene, *, variant: str = "auto", progress: bool = True
                 ) -> RenderedFrame:
    """Render ``scene``'s frame and its id pass with its render settings.

    Parameters
    ----------
    scene : Scene
    variant : {'auto', 'cuda', 'llvm', 'scalar'} or a Mitsuba variant name
    progress : bool
        Show a progress bar on stderr.
    """
    seed = scene.render.seed
    chosen = choose_variant(variant)
    t0 = time.perf_counter()
    key = f"{scene_fingerprint(optics_of(scene))}|{chosen}"
    kept = _KEPT.get()
    optical = kept.renders.get(key) if kept is not None else None
    if optical is not None:  # this frame rendered nothing: its render time is none
        optical = replace(optical, seconds=0.0)
    else:
        optical = _render_optics(scene, chosen, progress)
        if kept is not None and len(kept.renders) < kept.capacity:
            kept.renders[key] = optical
    linear = optical.linear
    if scene.bench.noise is not None:
        linear = add_noise(linear, scene.bench.noise, seed)
    info = RenderInfo(variant=chosen, spp=scene.render.spp, seed=seed,
                      sampler=scene.render.sampler, background_spp=optical.background_spp,
                      beacon_spp=optical.beacon_spp,
                      beacon_box_spp=optical.beacon_box_spp or None,
                      seconds_render=optical.seconds,
                      seconds_total=round(time.perf_counter() - t0, 3), mitsuba=MITSUBA_VERSION)
    return RenderedFrame(linear=linear, first=optical.first, in_mirror=optical.in_mirror,
                         info=info)


def _render_optics(scene: Scene, chosen: str, progress: bool) -> _Optics:
    """Render what the camera's lens puts on the sensor, and the id pass."""
    spp, seed = scene.render.spp, scene.render.seed
    t0 = time.perf_counter()
    k = scene.bench.distortion
    lens = k != (0.0, 0.0)
    pinhole = pinhole_scene(scene)
    box, background, beacon_spp, boxes, passes = _regions(pinhole, spp)
    with variant_scope(chosen):
        tiles = tuple(sorted({t for *_, t in passes}))
        mi_scene = mi.load_dict(build_scene_dict(pinhole, tiles), optimize=False)
        # the bar counts the samples path-traced (millions): the whole film's, then
        # each box's tiles' (a box's pixels take more samples than the film's)
        film = pinhole.camera.width * pinhole.camera.height_px
        total = film * (spp if box is None else background) + sum(
            n * t * t * _tiles(region, t) for region, n, _, t in passes)
        with progress_bar(total=total / 1e6, unit="M samples", enabled=progress,
                          leave=False, desc=f"rendering {scene.name} ({chosen})",
                          bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} M samples "
                                     "[{elapsed}<{remaining}, {rate_fmt}]") as bar:
            linear = _render_regions(mi_scene, pinhole.camera,
                                     spp if box is None else background, passes, seed,
                                     bar.update)
        t_render = time.perf_counter() - t0
        first, in_mirror = id_pass(mi_scene, pinhole)
    if lens:
        linear = distort(linear, scene.camera, k)
        first, in_mirror = (distort(a, scene.camera, k, nearest=True) for a in (first, in_mirror))
    for a in (linear, first, in_mirror):
        a.flags.writeable = False  # a kept render is shared: nobody may draw on it
    return _Optics(linear, first, in_mirror, None if box is None else background,
                   beacon_spp if boxes else None, round(t_render, 3),
                   tuple(n for _, n, stream, _ in passes if stream >= 2))


Region = tuple[int, int, int, int]


def _regions(pinhole: Scene, spp: int) -> tuple[Region | None, int, int, list[Region],
                                                list[tuple[Region, int, int, int]]]:
    """Where the samples go: the mirror's box (None: the whole frame at spp), the spp
    outside it, the beacons' spp and boxes, and the passes after the whole film as
    (region, spp, seed stream, tile size): the mirror's region at the full spp, then
    each beacon's image at beacon_spp, a short one's at more (inside the mirror's region:
    pasted after it)."""
    background = pinhole.render.outside_spp(spp)
    box = optics.mirror_box(pinhole) if background < spp else None
    beacon_spp = pinhole.render.beacon_box_spp(spp)
    boxes = [b for b in optics.beacon_boxes(pinhole) if b is not None] \
        if beacon_spp > spp else []
    # a short image takes more (RenderSettings.beacon_box_spp): its height, board to tip,
    # is its box's less the margins (a box the film clips reads shorter: more samples)
    margins = 2 * optics.BEACON_BOX_MARGIN_PX + 1
    passes = ([(box, spp, 1, MIRROR_TILE)] if box is not None else []) \
        + [(b, pinhole.render.beacon_box_spp(spp, image_px=b[3] - b[1] - margins), 2 + i,
            BEACON_TILE) for i, b in enumerate(boxes)]
    return box, background, beacon_spp, boxes, passes


def _tiles(region: Region, t: int) -> int:
    """How many tiles of t px cover ``region``."""
    u0, v0, u1, v1 = region
    return -(-(u1 - u0) // t) * -(-(v1 - v0) // t)


def _render_regions(mi_scene, cam: Camera, whole_spp: int,
                    passes: list[tuple[Region, int, int, int]], seed: int,
                    step: Callable[[float], object]) -> np.ndarray:
    """The whole film at ``whole_spp``, then each pass's region over it, tile by tile
    (each tile with its own seed stream)."""
    sensors = {s.id(): s for s in mi_scene.sensors()}
    H, W = cam.height_px, cam.width
    linear = _accumulate(mi_scene, sensors["sensor"], whole_spp, (seed, 0),
                         lambda m: step(m * W * H / 1e6))
    # the boxes' tiles of one size replay one recording (the whole film, rendered once
    # a frame, is traced as usual: recording it would cost more than it saves)
    with frozen_renders():
        for region, n, stream, t in passes:
            _render_tiles(mi_scene, sensors[f"sensor_tile{t}"], cam, linear,
                          region=region, spp=n, seed=(seed, stream), step=step)
    return linear


def _render_tiles(mi_scene, sensor, cam: Camera, linear: np.ndarray, *,
                  region: Region, spp: int, seed: tuple[int, int],
                  step: Callable[[float], object]) -> None:
    """A box of the film rendered over ``linear`` in square tiles of ``sensor``'s size,
    each with its own seed stream."""
    (u0, v0, u1, v1), t = region, int(sensor.film().crop_size()[0])
    H, W = cam.height_px, cam.width
    params = mi.traverse(sensor)
    corners = [(u, v) for v in range(v0, v1, t) for u in range(u0, u1, t)]
    for k, (u, v) in enumerate(corners):
        aim_tile(params, cam, t, u0=u, v0=v)
        img = _accumulate(mi_scene, sensor, spp, (*seed, k),
                          lambda m, px=t * t: step(m * px / 1e6), _tile_pass(spp, t))
        # the tile's part inside the region (a tile may reach past it, or the film)
        h, w = min(t, v1 - v, H - v), min(t, u1 - u, W - u)
        linear[v:v + h, u:u + w] = img[:h, :w]


def render_direct(board: Board, camera: Camera, obj: Target | Beacon, *, spp: int,
                  crop: tuple[int, int, int, int], variant: str = "auto") -> np.ndarray:
    """One object on the board seen directly, only the film's ``crop`` (u0, v0, u1, v1);
    returns it as 8-bit sRGB (calibration's reference, :mod:`mirrorsim.pipelines.calibrate`)."""
    with variant_scope(choose_variant(variant)):
        d = build_direct_dict(board, camera, obj, spp=spp, crop=crop)
        mi_scene = mi.load_dict(d, optimize=False)
        return to_srgb8(_accumulate(mi_scene, mi_scene.sensors()[0], spp, (0, 0),
                                    lambda _n: None))


def _tile_pass(spp: int, t: int) -> int:
    """Samples per call for a t × t tile: PASS_SPP times a power of 4 (a multijitter
    sampler rounds other counts up) that divides ``spp``, within TILE_SAMPLES."""
    per = PASS_SPP
    while per * 4 * t * t <= TILE_SAMPLES and spp % (per * 4) == 0:
        per *= 4
    return per


def pass_seed(seed: tuple[int, ...], k: int) -> int:
    """Mitsuba's 32-bit seed of pass k of a render (seed, stream[, tile]): hashed by a
    SeedSequence, so that any seed ≥ 0 works (Mitsuba refuses seeds ≥ 2³²) and passes
    of different renders, streams or tiles do not share one."""
    return int(np.random.SeedSequence([*seed, k]).generate_state(1)[0])


def _accumulate(mi_scene, sensor, spp: int, seed: tuple[int, ...],
                step: Callable[[int], object], per_pass: int = PASS_SPP) -> np.ndarray:
    """Linear RGB, averaged over passes of ``per_pass`` samples (one progress step
    each); ``seed`` is (the render's seed, a stream number[, a tile])."""
    passes = [per_pass] * (spp // per_pass) + ([spp % per_pass] if spp % per_pass else [])
    if len(passes) == 1:  # the common case in datasets: no float64 sum to make
        img = np.array(render_call(mi_scene, sensor, spp=spp, seed=pass_seed(seed, 0)),
                       dtype=np.float32)
        step(spp)
        return img
    acc = None
    for k, n in enumerate(passes):
        img = np.asarray(render_call(mi_scene, sensor, spp=n, seed=pass_seed(seed, k)),
                         dtype=np.float64)
        acc = img * n if acc is None else acc + img * n
        step(n)
    return (acc / spp).astype(np.float32)


def pinhole_scene(scene: Scene) -> Scene:
    """What Mitsuba renders of ``scene``: itself, or under a distorting lens the pinhole
    render of a wider canvas (:func:`~mirrorsim.camera.sensor.distortion_canvas`), which
    :func:`~mirrorsim.camera.sensor.distort` warps onto the sensor."""
    k = scene.bench.distortion
    if k == (0.0, 0.0):
        return scene
    return replace(scene, camera=distortion_canvas(scene.camera, k)[0])


def render_ids(scene: Scene, *, variant: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """The id pass of ``scene``'s frame alone (no path tracing): :func:`id_pass`'s
    labels as :func:`render_frame` makes them, a distorting lens's warp included."""
    k = scene.bench.distortion
    lens = k != (0.0, 0.0)
    pinhole = pinhole_scene(scene)
    with variant_scope(choose_variant(variant)):
        first, in_mirror = id_pass(mi.load_dict(build_scene_dict(pinhole), optimize=False),
                                   pinhole)
    if lens:
        first, in_mirror = (distort(a, scene.camera, k, nearest=True) for a in (first, in_mirror))
    return first, in_mirror
