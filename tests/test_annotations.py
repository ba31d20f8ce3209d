"""A frame's annotations (masks, keypoints, the mirror's virtual camera) against geometry
worked here, independently of mirrorsim's optics, and the compressed RLE against
pycocotools where it is installed."""

import math

import cv2
import numpy as np
import pytest

from mirrorsim.formats import rle
from mirrorsim.pipelines.frame import render_to_files
from mirrorsim.scene.model import PENCIL_RADIUS, TARGET_THICKNESS, pencil_paint_height
from tests.conftest import small_scene


@pytest.fixture(scope="module")
def default_frame(tmp_path_factory, fast_variant):
    scene = small_scene("default", 640, 364)
    files = render_to_files(scene, tmp_path_factory.mktemp("ann"), variant=fast_variant,
                            progress=False)
    return scene, files.truth


def _masks(seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(60):
        h, w = rng.integers(1, 30, 2)
        yield rng.random((h, w)) < rng.random()
    yield np.zeros((5, 7), bool)
    yield np.ones((5, 7), bool)
    m = np.zeros((40, 50), bool)
    m[3:30, 10:45] = True  # long runs: counts over 32, differences negative
    yield m


def test_rle_round_trips():
    for m in _masks(1):
        back = rle.decode(rle.encode(m))
        assert back.shape == m.shape and (back == m).all()
    assert sum(rle.runs(np.ones((3, 4), bool))) == 12
    assert rle.runs(np.ones((3, 4), bool))[0] == 0  # counts start with zeros


# pycocotools' own code warns under NumPy 2 (its __array__): not ours to fix
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_rle_is_cocos():
    mask_api = pytest.importorskip("pycocotools.mask")
    for m in _masks(2):
        ours = rle.encode(m)
        theirs = mask_api.encode(np.asfortranarray(m.astype(np.uint8)))
        assert ours["counts"] == theirs["counts"].decode()
        assert (mask_api.decode({"size": ours["size"], "counts": ours["counts"]}) == m).all()


def _mirror_reflect(scene, p):
    """A point reflected in the upright mirror's plane (its centre and yaw alone)."""
    m = scene.mirror
    n = np.array([-math.sin(math.radians(m.yaw)), math.cos(math.radians(m.yaw)), 0.0])
    c = np.array([*m.center, 0.0])
    return p - 2.0 * ((p - c) @ n) * n


def _pinhole(truth, p):
    """The level camera's pixel of a 3-D point, from the truth file's camera."""
    cam = truth.camera
    pan = math.radians(cam.pan_deg)
    f = np.array([math.cos(pan), math.sin(pan), 0.0])
    right = np.array([math.sin(pan), -math.cos(pan), 0.0])
    d = p - np.array([*cam.position, cam.height])
    z = d @ f
    return cam.cx + cam.fx * (d @ right) / z, cam.cy + cam.fx * (-d[2]) / z


def test_pencil_keypoints_in_the_mirror_are_exact(default_frame):
    scene, truth = default_frame
    b = scene.beacons[0]
    inst = next(i for i in truth.annotations.instances
                if i.object == "beacons[0]" and i.view == "mirror")
    assert inst.category == "beacon_in_mirror"
    for k, z in zip(inst.keypoints, (b.height, 0.0), strict=True):
        u, v = _pinhole(truth, _mirror_reflect(scene, np.array([*b.position, z])))
        assert math.hypot(k.u - u, k.v - v) < 0.5, (k, u, v)
        assert k.visible == 2
    # the foot stands on the mask's bottom row, the tip above its top (a point)
    x, y, w, h = inst.bbox
    foot, tip = inst.keypoints[1], inst.keypoints[0]
    assert x - 1 <= foot.u <= x + w and abs(foot.v - (y + h - 1)) < 1.5
    assert tip.v < y + 1.0


def test_the_virtual_camera_projects_what_the_mirror_shows(default_frame):
    scene, truth = default_frame
    vc = truth.annotations.virtual_camera
    b = scene.beacons[0]
    tip = np.array([*b.position, b.height, 1.0])
    e = np.asarray(vc.world_to_camera)
    uvw = np.asarray(vc.intrinsics) @ (e[:3] @ tip)
    u, v = _pinhole(truth, _mirror_reflect(scene, tip[:3]))
    assert abs(uvw[0] / uvw[2] - u) < 1e-6 and abs(uvw[1] / uvw[2] - v) < 1e-6
    assert np.linalg.det(e[:3, :3]) == pytest.approx(-1.0)  # a mirrored view
    c = np.array([*truth.camera.position, truth.camera.height])
    assert np.allclose(vc.position, _mirror_reflect(scene, c))


def _outline_bounds(truth, corners, shape):
    """Pixels of the exact outline (the convex hull of the projected corners) shrunk and
    grown by one pixel."""
    uv = np.array([_pinhole(truth, p) for p in corners])
    poly = np.zeros(shape, np.uint8)
    # fillPoly's vertices are integers: 8 bits of subpixel precision
    cv2.fillPoly(poly, [np.round(cv2.convexHull(uv.astype(np.float32)) * 256).astype(np.int32)],
                 1, shift=8)
    k = np.ones((3, 3), np.uint8)
    return int(cv2.erode(poly, k).sum()), int(cv2.dilate(poly, k).sum())


def _pencil_corners(b):
    def ring(r, z):
        return [np.array([b.position[0] + r * math.cos(a), b.position[1] + r * math.sin(a), z])
                for a in np.radians(np.arange(6) * 60.0 + 30.0)]

    lead = min(0.3, 0.1 * b.height)
    return (ring(PENCIL_RADIUS, 0.0) + ring(PENCIL_RADIUS, pencil_paint_height(b.height))
            + ring(0.3 * PENCIL_RADIUS, b.height - lead) + [np.array([*b.position, b.height])])


def _panel_corners(t):
    f = np.array([math.cos(math.radians(t.facing_deg)), math.sin(math.radians(t.facing_deg))])
    a = np.array([-f[1], f[0]])
    c = np.asarray(t.position, float)
    return [np.array([*(c + s * f * TARGET_THICKNESS / 2 + e * a * t.size[0] / 2), z])
            for s in (-1, 1) for e in (-1, 1) for z in (0.0, t.size[1])]


def test_masks_lie_between_the_outline_shrunk_and_grown(default_frame):
    scene, truth = default_frame
    ann = truth.annotations
    shape = (ann.height, ann.width)
    cases = {("beacons[0]", "mirror"): [_mirror_reflect(scene, p)
                                         for p in _pencil_corners(scene.beacons[0])],
             ("beacons[0]", "direct"): _pencil_corners(scene.beacons[0]),
             ("target", "mirror"): [_mirror_reflect(scene, p)
                                    for p in _panel_corners(scene.target)]}
    for (obj, view), corners in cases.items():
        inst = next(i for i in ann.instances if i.object == obj and i.view == view)
        lo, hi = _outline_bounds(truth, corners, shape)
        assert lo <= inst.area <= hi, (obj, view, lo, inst.area, hi)
        assert rle.decode(inst.mask).sum() == inst.area


def test_every_object_is_annotated_once_per_view(default_frame):
    _, truth = default_frame
    seen = [(i.object, i.view) for i in truth.annotations.instances]
    assert sorted(seen) == sorted({*seen})
    assert {("target", "mirror"), ("beacons[0]", "mirror"), ("mirror", "direct")} <= set(seen)
    # the wall hides the target from the camera: no direct view of it
    assert ("target", "direct") not in seen


def test_depth_and_normals_of_the_board(tmp_path, fast_variant):
    from mirrorsim.pipelines.frame import write_aovs

    scene = small_scene("default", 320, 182)
    write_aovs(scene, tmp_path, ("depth", "normals"), variant=fast_variant)
    depth = np.load(tmp_path / "default.depth.npy")
    normals = np.load(tmp_path / "default.normals.npy")
    assert depth.shape == (182, 320) and normals.shape == (182, 320, 3)
    assert depth.dtype == normals.dtype == np.float32
    cam = scene.camera
    pan = math.radians(cam.pan_deg)
    f = np.array([math.cos(pan), math.sin(pan), 0.0])
    right = np.array([math.sin(pan), -math.cos(pan), 0.0])
    for u, v in ((40, 175), (160, 178), (300, 170)):  # the bottom rows see the board
        ray = f + (u - cam.cx) / cam.fx * right + (v - cam.cy) / cam.fx * np.array([0, 0, -1.0])
        expected = cam.height / -ray[2] * np.linalg.norm(ray)  # where it meets z = 0
        # the mean over the pixel's area: the board recedes ~0.5 % across a pixel here
        assert depth[v, u] == pytest.approx(expected, rel=0.005)
        assert normals[v, u] == pytest.approx([0.0, 0.0, 1.0], abs=1e-4)


def test_depth_renders_at_a_seed_beyond_32_bits(tmp_path, fast_variant):
    from mirrorsim.pipelines.frame import write_aovs

    scene = small_scene("default", 64, 36, seed=(1 << 40) + 3)
    write_aovs(scene, tmp_path, ("depth",), variant=fast_variant)
    assert np.load(tmp_path / "default.depth.npy").shape == (36, 64)
    assert not (tmp_path / "default.normals.npy").exists()


def test_a_curved_glass_labels_no_keypoint_in_the_mirror(tmp_path, fast_variant):
    import copy

    from mirrorsim.pipelines.scenes import scene_from_dict
    from tests.conftest import scene_dict

    d = copy.deepcopy(scene_dict("default"))
    d["camera"]["resolution"] = [320, 182]
    d["mirror"]["curvature_radius"] = 700.0
    scene = scene_from_dict(d, source="curved.yaml", default_name="curved")
    truth = render_to_files(scene, tmp_path, variant=fast_variant, progress=False).truth
    inst = [i for i in truth.annotations.instances if i.view == "mirror"]
    assert inst and all(k.visible == 0 and k.u == k.v == 0.0 for i in inst
                        for k in i.keypoints)
    assert all(i.area > 0 for i in inst)  # the masks are the render's, curved glass and all
