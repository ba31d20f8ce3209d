"""Rendering at small resolution: the id pass against exact optics, colours, determinism."""

import json
import math

import numpy as np
import pytest

from mirrorsim.errors import BadParameter
from mirrorsim.pipelines.frame import render_to_files
from mirrorsim.pipelines.scenes import load_scene, scene_from_dict
from mirrorsim.rendering.id_pass import IN_MIRROR
from mirrorsim.rendering.mitsuba_scene import BEACON_LABEL, MIRROR_LABEL, TARGET_LABEL
from mirrorsim.truth import optics

from .conftest import SCENES, small_scene


def _read_png(path):
    import mitsuba as mi

    return np.array(mi.Bitmap(str(path)))


@pytest.fixture(scope="module")
def default_small(tmp_path_factory, fast_variant):
    scene = small_scene("default", 480, 272, spp=4)
    res = render_to_files(scene, tmp_path_factory.mktemp("r"), variant=fast_variant,
                          progress=False)
    return scene, res


def test_files_and_sizes(default_small):
    scene, res = default_small
    img = _read_png(res.image)
    assert img.shape == (272, 480, 3) and img.dtype == np.uint8
    truth = json.loads(res.truth_json.read_text())
    assert truth["scene"] == "default" and truth["render"]["spp"] == 4
    ids = _read_png(res.ids_png)
    assert ids.shape == (272, 480)


@pytest.mark.parametrize("which", ["target", "beacon"])
def test_id_pass_places_image_where_optics_projects_it(default_small, which):
    scene, res = default_small
    ids = _read_png(res.ids_png)
    obj = scene.target if which == "target" else scene.beacons[0]
    label = IN_MIRROR + (TARGET_LABEL if which == "target" else BEACON_LABEL)
    ext = optics.image_extent(scene, obj)
    vs, us = np.nonzero(ids == label)
    assert len(us) > 20
    # the object is symmetric about its upright axis: its pixels centre on that column
    assert abs(us.mean() - ext.u_axis) <= 1.0
    # pixel centres inside the projected extent: first row ≥ top, last row ≤ foot (+1 px)
    assert ext.v_top - 1.0 <= vs.min() <= ext.v_top + 1.0
    assert ext.v_bottom - 1.0 <= vs.max() <= ext.v_bottom + 1.0
    entry = res.truth.target if which == "target" else res.truth.beacons[0]
    assert entry.visible_px == len(us)
    assert entry.bbox_px == (us.min(), vs.min(), us.max(), vs.max())
    on_disk = json.loads(res.truth_json.read_text())
    assert on_disk.pop("sha256")  # the truth file's checksum of itself (test_integrity)
    assert on_disk == res.truth.to_json()


def test_mirror_really_reflects(default_small):
    scene, res = default_small
    ids = _read_png(res.ids_png)
    img = _read_png(res.image).astype(float)
    tgt, pencil = ids == IN_MIRROR + TARGET_LABEL, ids == IN_MIRROR + BEACON_LABEL
    # the target is seen only in the mirror, never directly (the wall hides it) ...
    assert tgt.sum() > 100 and (ids == TARGET_LABEL).sum() == 0
    # ... and all of its pixels lie inside the mirror glass's image region
    glass = ids >= IN_MIRROR
    vs, us = np.nonzero(glass)
    tv, tu = np.nonzero(tgt)
    assert tu.min() >= us.min() and tu.max() <= us.max()
    assert tv.min() >= vs.min() and tv.max() <= vs.max()
    # where the target itself stands, the camera sees the occluder
    p = scene.target.position
    u, v, depth = optics.project(scene.camera, [[p[0], p[1], scene.target.height / 2]])
    occ = BEACON_LABEL + len(scene.beacons)
    assert depth[0] > 0 and ids[int(round(v[0])), int(round(u[0]))] == occ
    # the pencil stands in front of the mirror: seen both directly and in the mirror
    assert (ids == BEACON_LABEL).sum() > 0 and pencil.sum() > 0
    # in the frame, the target's reflection is the grey panel, the pencil's is yellow
    grey = img[tgt].mean(axis=0)
    assert np.ptp(grey) < 0.2 * grey.mean() and 50 < grey.mean() < 200  # lit by a warm room
    yellow = img[pencil].mean(axis=0)
    assert yellow[0] > 1.4 * yellow[2]
    assert (ids == MIRROR_LABEL).sum() == 0  # glass pixels carry the IN_MIRROR offset


def test_same_seed_same_bytes_other_seed_differs(tmp_path, fast_variant):
    scene = small_scene("exp1", 160, 92, spp=2)
    a = render_to_files(scene, tmp_path / "a", variant=fast_variant, progress=False)
    b = render_to_files(scene, tmp_path / "b", variant=fast_variant, progress=False)
    c = render_to_files(scene.with_render(seed=7), tmp_path / "c", variant=fast_variant,
                        progress=False)
    assert a.image.read_bytes() == b.image.read_bytes()
    assert a.image.read_bytes() != c.image.read_bytes()
    assert a.ids_png.read_bytes() == c.ids_png.read_bytes()  # geometry, not sampling


def test_scalar_and_jit_id_passes_agree(tmp_path, jit_variant):
    scene = small_scene("exp3", 128, 74, spp=1)
    jit = render_to_files(scene, tmp_path / "jit", variant=jit_variant, progress=False)
    scalar = render_to_files(scene, tmp_path / "scalar", variant="scalar", progress=False)
    assert jit.truth.render.variant == jit_variant
    assert scalar.truth.render.variant == "scalar_rgb"
    a, b = _read_png(jit.ids_png), _read_png(scalar.ids_png)
    assert (a == b).mean() > 0.995
    assert scalar.truth.target.visible_px > 0
    # and the frames look alike (same scene, different samplers)
    fa, fb = _read_png(jit.image).astype(float), _read_png(scalar.image).astype(float)
    assert abs(fa.mean() - fb.mean()) < 0.05 * fa.mean()


def test_refuses_bad_spp(tmp_path):
    scene = small_scene("default", 64, 36)
    # the render settings are checked where they are made, before anything renders
    with pytest.raises(BadParameter, match="spp"):
        render_to_files(scene.with_render(spp=0), tmp_path, progress=False)
    with pytest.raises(BadParameter, match="seed"):
        scene.with_render(seed=-1)
    with pytest.raises(BadParameter, match="sampler"):
        scene.with_render(sampler="stratified")
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize("name", ["exp1", "default"])
def test_full_size_frame(name, tmp_path, fast_variant):
    scene = load_scene(SCENES / f"{name}.yaml")
    res = render_to_files(scene, tmp_path, variant=fast_variant, progress=False)
    img = _read_png(res.image)
    assert img.shape == (1088, 1920, 3)
    ids = _read_png(res.ids_png)
    for entry, obj, label in [(res.truth.target, scene.target, IN_MIRROR + TARGET_LABEL),
                              (res.truth.beacons[0], scene.beacons[0],
                               IN_MIRROR + BEACON_LABEL)]:
        # the truth against the reflection written out here (not the optics that made it)
        cx, cy = scene.camera.position
        mx, my = scene.mirror.center
        nx, ny = -math.sin(math.radians(scene.mirror.yaw)), math.cos(math.radians(scene.mirror.yaw))
        s = (obj.position[0] - mx) * nx + (obj.position[1] - my) * ny
        vx, vy = obj.position[0] - 2 * s * nx, obj.position[1] - 2 * s * ny
        assert entry.alpha_deg == pytest.approx(math.degrees(math.atan2(vy - cy, vx - cx)),
                                                abs=1e-6)
        assert entry.d_total == pytest.approx(math.hypot(vx - cx, vy - cy), abs=1e-6)
        ext = optics.image_extent(scene, obj)
        vs, us = np.nonzero(ids == label)
        assert entry.visible_px > 500
        # the pencil's graphite point is narrower than a pixel for its last ~1.5 px, so
        # pixel-centre rays first meet it a little below the apex
        top_slack = 2.0 if obj in scene.beacons else 1.0
        assert ext.v_top - 1 <= vs.min() <= ext.v_top + top_slack
        assert ext.v_bottom - 1 <= vs.max() <= ext.v_bottom + 1
        if not entry.clipped:
            assert abs(us.mean() - ext.u_axis) <= 1.0


def test_several_beacons_each_get_their_label(tmp_path, fast_variant):
    import copy

    from .conftest import scene_dict

    d = copy.deepcopy(scene_dict("default"))
    d["camera"]["resolution"] = [640, 363]
    d["beacons"] = [d.pop("beacon"), {"position": [28, 57], "height": 5.0}]
    scene = scene_from_dict(d)
    res = render_to_files(scene.with_render(spp=1), tmp_path, variant=fast_variant, progress=False)
    ids = _read_png(res.ids_png)
    for i, b in enumerate(scene.beacons):
        vs, us = np.nonzero(ids == IN_MIRROR + BEACON_LABEL + i)
        assert res.truth.beacons[i].visible_px == len(us) > 0
        # each label sits where the exact projection puts that beacon's image (the two
        # images are ~20 px apart here, so a swapped label fails), its foot and top too
        ext = optics.image_extent(scene, b)
        assert abs(us.mean() - ext.u_axis) <= 1.0
        assert ext.v_bottom - 1 <= vs.max() <= ext.v_bottom + 1
        assert ext.v_top - 1 <= vs.min() <= ext.v_top + 2
    # the occluder's label comes after the beacons'
    assert (ids == BEACON_LABEL + 2).sum() > 0


def test_truth_read_back_from_its_file_is_the_truth(default_small):
    """A reused render scores exactly as a fresh one: the truth survives its JSON."""
    from mirrorsim.truth.groundtruth import GroundTruth

    _, res = default_small
    back = GroundTruth.from_json(json.loads(res.truth_json.read_text()))
    assert back.to_json() == res.truth.to_json()
    assert back.mirror_yaw_deg == res.truth.mirror_yaw_deg
    assert back.target == res.truth.target and back.beacons == res.truth.beacons


def test_srgb_encoding_matches_the_transfer_curve():
    """to_srgb8's lookup against IEC 61966-2-1 evaluated and rounded directly, on random
    values and just either side of every code's edge."""
    from mirrorsim.rendering.passes import to_srgb8

    def curve(x):
        x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
        s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
        return np.round(s * 255.0).astype(np.uint8)

    rng = np.random.default_rng(3)
    s = (np.arange(1, 256) - 0.5) / 255.0
    edges = np.where(s <= 0.04045, s / 12.92, ((s + 0.055) / 1.055) ** 2.4).astype(np.float32)
    x = np.concatenate([rng.random(200_000), rng.random(200_000) ** 4 * 0.05,
                        rng.normal(0.5, 0.7, 50_000), [0.0, -0.0, 1.0, 7.0, -2.0],
                        edges, np.nextafter(edges, np.float32(-1)),
                        np.nextafter(edges, np.float32(2))]).astype(np.float32)
    x = x[: len(x) // 3 * 3].reshape(-1, 1, 3)
    assert np.array_equal(to_srgb8(x), curve(x))
    assert to_srgb8(x).shape == x.shape and to_srgb8(x).dtype == np.uint8


@pytest.mark.parametrize("name", ["default", "exp3"])
def test_fewer_samples_outside_the_mirror(name, fast_variant):
    """background_spp: outside the mirror's box the frame is exactly a render at the
    background's spp (same seed stream), inside it converges to the full-spp frame;
    the box holds every pixel of the mirror (its id pass, not the box's geometry)."""
    from dataclasses import replace

    from mirrorsim.rendering.passes import render_frame

    scene = small_scene(name, 480, 272)
    scene = replace(scene, render=replace(scene.render, beacon_spp=1))  # not tested here
    low = replace(scene, render=replace(scene.render, background_spp=1))
    mixed = render_frame(low.with_render(spp=16, seed=2), variant=fast_variant, progress=False)
    uniform = replace(scene, render=replace(scene.render, background_spp=16))
    plain1 = render_frame(uniform.with_render(spp=1, seed=2), variant=fast_variant, progress=False)
    plain16 = render_frame(uniform.with_render(spp=16, seed=2), variant=fast_variant,
                           progress=False)
    assert plain16.info.background_spp is None  # uniform: no mirror box rendered apart
    u0, v0, u1, v1 = optics.mirror_box(scene)
    vs, us = np.nonzero(plain16.first == MIRROR_LABEL)
    assert u0 <= us.min() and us.max() < u1 and v0 <= vs.min() and vs.max() < v1
    inside = np.zeros(plain1.first.shape, bool)
    inside[v0:v1, u0:u1] = True
    assert np.array_equal(mixed.linear[~inside], plain1.linear[~inside])
    box_mixed, box16 = mixed.linear[inside], plain16.linear[inside]
    assert not np.array_equal(box_mixed, plain1.linear[inside])
    assert abs(box_mixed.mean() / box16.mean() - 1) < 0.01
    # 16 samples inside: per-pixel scatter about the 16-spp frame well under 1 spp's
    assert (np.abs(box_mixed - box16).mean()
            < 0.6 * np.abs(plain1.linear[inside] - box16).mean())
    assert mixed.info.background_spp == 1 and np.array_equal(mixed.first, plain16.first)


def test_the_mirrors_box_does_not_depend_on_the_background(fast_variant):
    """Every measurement is made in the mirror's box, whose tiles take their own seed
    streams: its pixels are the same, bit for bit, whatever the background's spp (why a
    dataset spec can spend 1 there)."""
    from dataclasses import replace

    from mirrorsim.rendering.passes import render_frame

    scene = small_scene("default", 480, 272).with_render(spp=8, seed=5)
    frames = [render_frame(replace(scene, render=replace(scene.render, background_spp=b)),
                           variant=fast_variant, progress=False) for b in (1, 2)]
    u0, v0, u1, v1 = optics.mirror_box(scene)
    box = [f.linear[v0:v1, u0:u1] for f in frames]
    assert np.array_equal(box[0], box[1])
    assert not np.array_equal(frames[0].linear, frames[1].linear)  # outside it differs


def test_more_samples_in_the_beacons_image(fast_variant):
    """beacon_spp: the beacon's image box is rendered at beacon_spp or more (its own
    seed stream), the rest of the frame exactly as without it; the box holds every pixel of
    the beacon's mirror image (its id pass), and inside it the frame is closer to a
    64-spp frame than the 4-spp render is."""
    from dataclasses import replace

    from mirrorsim.rendering.mitsuba_scene import BEACON_LABEL
    from mirrorsim.rendering.passes import render_frame

    scene = small_scene("default", 480, 272)
    with_box = replace(scene, render=replace(scene.render, background_spp=4, beacon_spp=64))
    without = replace(with_box, render=replace(with_box.render, beacon_spp=1))
    boxed = render_frame(with_box.with_render(spp=4, seed=3), variant=fast_variant, progress=False)
    plain = render_frame(without.with_render(spp=4, seed=3), variant=fast_variant, progress=False)
    ref = render_frame(without.with_render(spp=64, seed=9), variant=fast_variant, progress=False)
    (u0, v0, u1, v1), = optics.beacon_boxes(scene)
    vs, us = np.nonzero(plain.in_mirror == BEACON_LABEL)
    assert len(us) > 20
    assert u0 <= us.min() and us.max() < u1 and v0 <= vs.min() and vs.max() < v1
    inside = np.zeros(plain.first.shape, bool)
    inside[v0:v1, u0:u1] = True
    assert np.array_equal(boxed.linear[~inside], plain.linear[~inside])
    err = lambda f: np.abs(f.linear[inside] - ref.linear[inside]).mean()  # noqa: E731
    assert err(boxed) < 0.5 * err(plain)
    assert boxed.info.beacon_spp == 64 and plain.info.beacon_spp is None
    # its image, under 40 px tall in the id pass, took more than beacon_spp
    assert vs.max() - vs.min() + 1 < 40 and boxed.info.beacon_box_spp[0] > 64


def test_a_short_beacon_image_takes_more_samples():
    """A beacon's image under 40 px takes beacon_spp times the square of its shortfall,
    rounded up to a power of 2, at most 8 times (values worked by hand); none where no
    box is rendered (beacon_spp not above spp)."""
    from mirrorsim.scene.render_settings import RenderSettings, small_image_factor

    assert [small_image_factor(h) for h in (100.0, 40.0, 35.0, 30.0, 25.0, 20.0, 15.0, 5.0)] \
        == [1, 1, 2, 2, 4, 4, 8, 8]
    r = RenderSettings(spp=8, beacon_spp=128)
    assert r.beacon_box_spp(image_px=15.0) == 1024 and r.beacon_box_spp(image_px=60.0) == 128
    assert RenderSettings(spp=8, beacon_spp=4).beacon_box_spp(image_px=15.0) == 8


def test_mirror_image_lies_where_the_mirror_puts_it(tmp_path, fast_variant):
    """The panel's side edges in the mirror, full size, against the exact projection of
    its reflected front face.  Mitsuba starts each reflected ray (1 + max|p|)·8.9e-5
    world units off the glass; with the board's origin for the world's, the glass stood
    ~60 cm out and both edges sat +0.06 to +0.07 px right (the scene is now centred on
    the glass).  At 64 spp the edges' noise is ~0.005 px."""
    import copy

    from mirrorsim.detection.detector import measure_object
    from mirrorsim.detection.frame_files import read_frame
    from mirrorsim.scene.model import TARGET_THICKNESS
    from solver.geometry import reflect, unit

    from .conftest import scene_dict

    d = copy.deepcopy(scene_dict("default"))
    d["render"] = {"sampler": "multijitter", "spp": 64, "background_spp": 1, "beacon_spp": 1}
    s = scene_from_dict(d, default_name="centred")
    res = render_to_files(s, tmp_path, variant=fast_variant, progress=False, ids=False)
    t = s.target
    m = measure_object(read_frame(res.image), "target", t.size[0] / t.size[1])
    front = np.asarray(t.position) + unit(t.facing_deg) * TARGET_THICKNESS / 2
    across = unit(t.facing_deg + 90)
    u, _, _ = optics.project(s.camera, np.array(
        [[*reflect(front + k * across * t.size[0] / 2, s.mirror.center, s.mirror.yaw),
          t.size[1] / 2] for k in (-1, 1)]))
    assert abs(m.u_left - u.min()) < 0.025 and abs(m.u_right - u.max()) < 0.025


def test_a_tile_renders_its_window_as_a_crop_of_the_film_does(fast_variant):
    """The tile sensor aimed at a window (its principal point) sees exactly what a crop
    of the full film there sees: the same pixels, at the same seed, to float rounding."""
    import mitsuba as mi

    from mirrorsim.rendering.mitsuba_scene import _cropped, aim_tile, build_scene_dict
    from mirrorsim.rendering.passes import variant_scope

    scene = small_scene("default", 480, 272)
    u0, v0 = optics.mirror_box(scene)[:2]
    with variant_scope(fast_variant):
        d = build_scene_dict(scene, tiles=(64,))
        d["sensor_crop"] = _cropped(d["sensor"], (u0, v0, u0 + 64, v0 + 64))
        ms = mi.load_dict(d, optimize=False)
        sensors = {s.id(): s for s in ms.sensors()}
        aim_tile(mi.traverse(sensors["sensor_tile64"]), scene.camera, 64, u0=u0, v0=v0)
        tile, crop = (np.array(mi.render(ms, sensor=sensors[k], spp=16, seed=7))
                      for k in ("sensor_tile64", "sensor_crop"))
    assert crop.shape == tile.shape == (64, 64, 3) and crop.mean() > 0.01
    assert np.abs(tile - crop).max() < 1e-5


def test_a_new_scene_compiles_no_new_kernel(jit_variant):
    """Dr.Jit's kernel history: after one scene, a scene with its mirror, target and
    beacon elsewhere (by amounts drawn afresh each run, so that no earlier run's kernel
    cache serves them) and another seed renders with kernels already compiled (the
    light is a mesh; the boxes are rendered in fixed tiles, aimed by parameters)."""
    import copy

    import drjit as dr

    from mirrorsim.rendering.passes import render_frame

    from .conftest import scene_dict

    rng = np.random.default_rng()
    shift = rng.uniform(-1.0, 1.0, 3)

    def scene(dx: float, dy: float, db: float):
        d = copy.deepcopy(scene_dict("default"))
        d["camera"]["resolution"] = [480, 272]
        d["mirror"]["center"] = [d["mirror"]["center"][0] + dx, d["mirror"]["center"][1] + dy]
        d["target"]["position"][0] += dx
        d["beacon"]["position"][1] += db
        return scene_from_dict(d, "shifted.yaml", "shifted")

    render_frame(scene(0.0, 0.0, 0.0), variant=jit_variant, progress=False)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # emptied
        render_frame(scene(*shift).with_render(seed=int(rng.integers(1 << 30))),
                     variant=jit_variant, progress=False)
        new = [h for h in dr.kernel_history()
               if h["type"] == dr.KernelType.JIT and not h["cache_hit"]]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert new == [], (shift, [h["size"] for h in new])


def test_the_id_preview_colours_each_label_apart():
    """The preview gives each label its own colour, what the mirror shows lighter than
    the same object seen directly, and the labels file stays the labels."""
    from mirrorsim.rendering.id_pass import IN_MIRROR
    from mirrorsim.rendering.id_preview import colourise_ids

    labels = np.array([[0, 2, IN_MIRROR + 2, 3, IN_MIRROR + 3, 4, IN_MIRROR, 7]], np.uint8)
    rgb = colourise_ids(labels, n_beacons=2)[0]
    assert len({tuple(c) for c in rgb}) == len(labels[0])  # all apart
    assert rgb[2].sum() > rgb[1].sum() and rgb[4].sum() > rgb[3].sum()  # mirror: lighter
    assert tuple(rgb[7]) == (128, 128, 128)  # an occluder (label 3 + beacons): grey
    # the preview file: the same colours above a legend strip naming each of them
    from mirrorsim.rendering.id_preview import id_preview

    big = np.repeat(np.repeat(labels, 40, axis=0), 60, axis=1)
    shown = id_preview(big, n_beacons=2)
    assert shown.shape[1] == big.shape[1] and shown.shape[0] > big.shape[0]
    assert (shown[:40] == colourise_ids(big, 2)).all()
    strip = shown[40:].reshape(-1, 3)
    for colour in map(tuple, colourise_ids(labels, 2)[0]):  # every colour has a swatch
        assert (strip == colour).all(axis=1).any(), colour


def test_a_seed_beyond_32_bits_renders(fast_variant):
    """A render hashes its seed into Mitsuba's 32-bit ones: a seed of 2⁴⁰ (a track of
    seed 8649690 renders pose k with 8649690·1000 + k) renders, and differs from seed 0;
    the bound is a Parquet int64's, 2⁶³ − 1."""
    from mirrorsim.errors import BadParameter
    from mirrorsim.rendering.passes import render_frame
    from mirrorsim.scene.render_settings import MAX_SEED

    scene = small_scene("default", 160, 92, spp=2)
    big = render_frame(scene.with_render(seed=2**40), variant=fast_variant, progress=False)
    zero = render_frame(scene.with_render(seed=0), variant=fast_variant, progress=False)
    assert big.linear.shape == zero.linear.shape and (big.linear != zero.linear).any()
    with pytest.raises(BadParameter, match="seed"):
        scene.with_render(seed=MAX_SEED + 1)


def test_frozen_renders_are_the_traced_ones_bit_for_bit(monkeypatch, jit_variant):
    """Frames rendered with recorded kernels replayed (Dr.Jit's freeze) and traced
    afresh (MIRRORSIM_FREEZE=0) are the same bits: for a scene, the same scene with its
    mirror and target elsewhere and another seed, and a scene of other objects and
    another film size; and a frame's tiles replay: fewer recordings than renders."""
    import copy

    from mirrorsim.rendering import frozen, passes
    from mirrorsim.rendering.passes import render_frame

    from .conftest import scene_dict

    def shifted(d: dict, dx: float, seed: int):
        d = copy.deepcopy(d)
        d["mirror"]["center"][0] += dx
        d["target"]["position"][0] += dx
        d["render"] = {**d.get("render", {}), "seed": seed}
        return scene_from_dict(d, "shifted.yaml", "shifted")

    base = copy.deepcopy(scene_dict("default"))
    base["camera"]["resolution"] = [960, 544]  # the mirror's box: several 128-px tiles
    scenes = [shifted(base, 0.0, 1), shifted(base, 1.3, 2), small_scene("exp1", 400, 228)]
    calls, made = [], []

    def counted(*args, **kwargs):
        calls.append(frozen._CURRENT.get() is not None)  # a call that may replay
        return frozen.render_call(*args, **kwargs)

    def kept():  # each scene's frozen function, to count its recordings
        f = make()
        made.append(f)
        return f

    make = frozen._frozen
    monkeypatch.setattr(passes, "render_call", counted)
    monkeypatch.setattr(frozen, "_frozen", kept)
    for scene in scenes:
        frames = {}
        for freeze in ("1", "0"):
            monkeypatch.setenv("MIRRORSIM_FREEZE", freeze)
            frames[freeze] = render_frame(scene, variant=jit_variant, progress=False).linear
        assert np.array_equal(frames["1"], frames["0"]), scene.name
    assert made and sum(f.n_recordings for f in made) < sum(calls)
