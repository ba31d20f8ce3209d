"""Independent oracles: geometry worked by hand, not by the code under test.

The solver's own tests take their truth from ``optics.mirror_image``, the solver's
forward model, so a mistake shared by both would pass.  Here the numbers are worked out
on paper (a mirror along y = 50 and one at 45°, each with a beacon and a target whose
images and distances are exact square roots), and the scenes' ground truth is held to a
reflection written out in the test from the scene file's own numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from solver.sltr import locate, observe, solve_single

from .conftest import SCENES

# (mirror point, yaw, beacon, beacon's image, target, target's image): worked by hand
CASES = [
    # the line y = 50: a point's image is (x, 100 − y)
    ((0.0, 50.0), 0.0, (30.0, 40.0), (30.0, 60.0), (60.0, 45.0), (60.0, 55.0)),
    # the line y = x + 40: relative to (0, 40) a point (u, v) has the image (v, u)
    ((0.0, 40.0), 45.0, (30.0, 50.0), (10.0, 70.0), (50.0, 70.0), (30.0, 90.0)),
]


def _single(x) -> dict:
    """The one-beacon solution's four measurements (beacon α, d; target α, d) by name."""
    return dict(zip(("beacon_alpha_deg", "beacon_d_total", "target_alpha_deg",
                     "target_d_total"), map(float, x), strict=True))


def _seen(image):
    """α (deg) and d_total of an image seen from the origin: its bearing and length."""
    return math.degrees(math.atan2(image[1], image[0])), math.hypot(*image)


@pytest.mark.parametrize("mirror, yaw, beacon, b_image, target, t_image", CASES)
def test_the_forward_model_gives_the_hand_worked_images(mirror, yaw, beacon, b_image,
                                                        target, t_image):
    for point, image in ((beacon, b_image), (target, t_image)):
        o = observe((0.0, 0.0), mirror, yaw, point=point)
        alpha, d = _seen(image)
        assert o.virtual == pytest.approx(image, abs=1e-12)
        assert float(o.alpha_deg) == pytest.approx(alpha, abs=1e-12)
        assert float(o.d_total) == pytest.approx(d, abs=1e-12)
        assert float(o.d1 + o.d2) == pytest.approx(d, abs=1e-12)


def test_hand_worked_values_are_what_they_claim():
    """The first case's numbers, as a reader can check them: α = atan(60/30), d_total =
    √4500, the reflection point where the ray to (30, 60) crosses y = 50: (25, 50)."""
    o = observe((0.0, 0.0), (0.0, 50.0), 0.0, point=(30.0, 40.0))
    assert float(o.alpha_deg) == pytest.approx(63.43494882292201, abs=1e-12)
    assert float(o.d_total) == pytest.approx(math.sqrt(4500.0), abs=1e-12)
    assert o.reflection_point == pytest.approx((25.0, 50.0), abs=1e-12)
    assert float(o.d1) == pytest.approx(math.sqrt(3125.0), abs=1e-12)
    assert float(o.d2) == pytest.approx(math.sqrt(125.0), abs=1e-12)


@pytest.mark.parametrize("mirror, yaw, beacon, b_image, target, t_image", CASES)
def test_sltr_recovers_the_hand_worked_mirror_and_target(mirror, yaw, beacon, b_image,
                                                         target, t_image):
    sol = solve_single((0.0, 0.0), beacon, **_single((*_seen(b_image), *_seen(t_image))))
    assert np.asarray(sol.target) == pytest.approx(target, abs=1e-9)
    assert (sol.mirror.yaw_deg - yaw + 90.0) % 180.0 - 90.0 == pytest.approx(0.0, abs=1e-9)
    # the hand's mirror point lies on the line found: n·x = n·(a point of it)
    t = math.radians(sol.mirror.yaw_deg)
    normal = np.array([-math.sin(t), math.cos(t)])
    assert normal @ np.asarray(mirror) == pytest.approx(normal @ sol.mirror.point, abs=1e-9)


@pytest.mark.parametrize("name", ["default", "exp1", "exp2", "exp3"])
def test_each_bundled_scenes_truth_is_the_reflection_of_its_file_numbers(name):
    """The ground truth of each bundled scene against a reflection written out here from
    the scene file's own numbers (p′ = p − 2((p − c)·n) n, n the mirror's normal), and
    α and d_total as the image's bearing and distance from the camera."""
    import yaml

    import mirrorsim as ms

    d = yaml.safe_load((SCENES / f"{name}.yaml").read_text())
    c = np.asarray(d["mirror"]["center"], float)
    yaw = math.radians(d["mirror"]["yaw"])
    n = np.array([-math.sin(yaw), math.cos(yaw)])
    cam = np.asarray(d["camera"]["position"], float)
    truth = ms.check(ms.load_scene(SCENES / f"{name}.yaml"))
    beacons = d["beacons"] if "beacons" in d else [d["beacon"]]
    for obj, position in ((truth.target, d["target"]["position"]),
                          *zip(truth.beacons, (b["position"] for b in beacons), strict=True)):
        p = np.asarray(position, float)
        image = p - 2.0 * np.dot(p - c, n) * n
        ray = image - cam
        assert obj.virtual == pytest.approx(tuple(image), abs=1e-9)
        assert obj.d_total == pytest.approx(float(np.hypot(*ray)), abs=1e-9)
        assert obj.alpha_deg % 360 == pytest.approx(
            math.degrees(math.atan2(ray[1], ray[0])) % 360, abs=1e-9)


# pyroomacoustics holds its image sources in float32 (7 digits): within 1 µm on a board
# of 80 cm, where a wrong sign or a wrong normal is off by centimetres
PRA_CM, PRA_DEG = 1e-4, 1e-4


def _image_sources(mirror_point, yaw_deg: float, camera, points) -> np.ndarray:
    """Each point's first-order image source across the mirror's line, by
    pyroomacoustics' image-source model (an acoustics library, written apart from this
    code): a 2-D room whose one wall lies along the mirror, the camera's side inside."""
    pra = pytest.importorskip("pyroomacoustics")
    c, cam = np.asarray(mirror_point, float), np.asarray(camera, float)
    u = np.array([math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))])
    n = np.array([-u[1], u[0]])
    n = n if (cam - c) @ n > 0 else -n  # the room stands on the camera's side
    span = 1000.0
    corners = np.array([c - span * u, c + span * u, c + span * u + span * n,
                        c - span * u + span * n])
    area = sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(corners, np.roll(corners, -1, 0),
                                                          strict=True))
    if area < 0:  # pyroomacoustics takes the corners anticlockwise
        corners = corners[::-1]
    mirror_wall = [i for i in range(4) if {tuple(corners[i]), tuple(corners[(i + 1) % 4])}
                   == {tuple(c - span * u), tuple(c + span * u)}][0]
    out = []
    for p in points:
        room = pra.Room.from_corners(corners.T, fs=8000, max_order=1)
        room.add_source(np.asarray(p, float))
        room.add_microphone(cam)
        room.image_source_model()
        src = room.sources[0]
        out.append(src.images[:, list(src.walls).index(mirror_wall)])
    return np.array(out)


# mirrors and points drawn at random over an 80 cm board, the camera at its corner
_RNG = np.random.default_rng(20261206)
RANDOM_MIRRORS = [((float(x), float(y)), float(yaw)) for x, y, yaw in zip(
    _RNG.uniform(20, 70, 6), _RNG.uniform(40, 75, 6), _RNG.uniform(-60, 60, 6), strict=True)]


@pytest.mark.parametrize("case", range(len(RANDOM_MIRRORS)))
def test_the_forward_model_agrees_with_pyroomacoustics_image_sources(case):
    """The solver's forward model (``observe``: the virtual image, α, d_total and the
    reflection point) against the image sources of an acoustics library for the same
    wall: the image, its bearing and distance from the camera, and the point where the
    camera's ray to the image crosses the wall."""
    mirror_point, yaw = RANDOM_MIRRORS[case]
    rng = np.random.default_rng((20261206, case))  # each case its own points, in any order
    cam = np.zeros(2)
    u = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw))])
    n = np.array([-u[1], u[0]])
    n = n if (cam - mirror_point) @ n > 0 else -n
    # points in front of the glass, on the camera's side
    points = [np.asarray(mirror_point) + a * u + b * n
              for a, b in zip(rng.uniform(-20, 20, 5), rng.uniform(2, 30, 5), strict=True)]
    images = _image_sources(mirror_point, yaw, cam, points)
    for p, image in zip(points, images, strict=True):
        o = observe(cam, mirror_point, yaw, point=p)
        ray = image - cam
        assert np.asarray(o.virtual) == pytest.approx(image, abs=PRA_CM)
        assert float(o.d_total) == pytest.approx(float(np.hypot(*ray)), abs=PRA_CM)
        assert float(o.alpha_deg) % 360 == pytest.approx(
            math.degrees(math.atan2(ray[1], ray[0])) % 360, abs=PRA_DEG)
        # the reflection point: on the wall's line, on the ray from the camera
        rp = np.asarray(o.reflection_point)
        assert (rp - mirror_point) @ n == pytest.approx(0.0, abs=1e-9)
        assert ray[0] * (rp - cam)[1] - ray[1] * (rp - cam)[0] == pytest.approx(0.0, abs=1e-2)
        # and the solver's inverse gives back the point from the library's image
        back = locate(cam, mirror_point, yaw, alpha_deg=math.degrees(math.atan2(ray[1], ray[0])),
                      d_total=float(np.hypot(*ray)))
        assert np.asarray(back) == pytest.approx(p, abs=PRA_CM)


@pytest.mark.parametrize("name", ["default", "exp1", "exp2", "exp3"])
def test_each_bundled_scenes_images_are_pyroomacoustics_image_sources(name):
    """Each bundled scene's ground truth (target and beacons) against the image sources
    pyroomacoustics finds for its mirror's wall, camera and objects."""
    import mirrorsim as ms

    scene = ms.load_scene(SCENES / f"{name}.yaml")
    truth = ms.check(scene)
    objects = [(truth.target, scene.target.position),
               *zip(truth.beacons, (b.position for b in scene.beacons), strict=True)]
    images = _image_sources(scene.mirror.center, scene.mirror.yaw, scene.camera.position,
                            [p for _, p in objects])
    for (obj, _), image in zip(objects, images, strict=True):
        ray = image - np.asarray(scene.camera.position)
        assert obj.virtual == pytest.approx(tuple(image), abs=PRA_CM)
        assert obj.d_total == pytest.approx(float(np.hypot(*ray)), abs=PRA_CM)
