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

from solver.sltr import observe, solve_single

from .conftest import SCENES

# (mirror point, yaw, beacon, beacon's image, target, target's image): worked by hand
CASES = [
    # the line y = 50: a point's image is (x, 100 − y)
    ((0.0, 50.0), 0.0, (30.0, 40.0), (30.0, 60.0), (60.0, 45.0), (60.0, 55.0)),
    # the line y = x + 40: relative to (0, 40) a point (u, v) has the image (v, u)
    ((0.0, 40.0), 45.0, (30.0, 50.0), (10.0, 70.0), (50.0, 70.0), (30.0, 90.0)),
]


def _seen(image):
    """α (deg) and d_total of an image seen from the origin: its bearing and length."""
    return math.degrees(math.atan2(image[1], image[0])), math.hypot(*image)


@pytest.mark.parametrize("mirror, yaw, beacon, b_image, target, t_image", CASES)
def test_the_forward_model_gives_the_hand_worked_images(mirror, yaw, beacon, b_image,
                                                        target, t_image):
    for point, image in ((beacon, b_image), (target, t_image)):
        o = observe((0.0, 0.0), mirror, yaw, point)
        alpha, d = _seen(image)
        assert o.virtual == pytest.approx(image, abs=1e-12)
        assert float(o.alpha_deg) == pytest.approx(alpha, abs=1e-12)
        assert float(o.d_total) == pytest.approx(d, abs=1e-12)
        assert float(o.d1 + o.d2) == pytest.approx(d, abs=1e-12)


def test_hand_worked_values_are_what_they_claim():
    """The first case's numbers, as a reader can check them: α = atan(60/30), d_total =
    √4500, the reflection point where the ray to (30, 60) crosses y = 50: (25, 50)."""
    o = observe((0.0, 0.0), (0.0, 50.0), 0.0, (30.0, 40.0))
    assert float(o.alpha_deg) == pytest.approx(63.43494882292201, abs=1e-12)
    assert float(o.d_total) == pytest.approx(math.sqrt(4500.0), abs=1e-12)
    assert o.reflection_point == pytest.approx((25.0, 50.0), abs=1e-12)
    assert float(o.d1) == pytest.approx(math.sqrt(3125.0), abs=1e-12)
    assert float(o.d2) == pytest.approx(math.sqrt(125.0), abs=1e-12)


@pytest.mark.parametrize("mirror, yaw, beacon, b_image, target, t_image", CASES)
def test_sltr_recovers_the_hand_worked_mirror_and_target(mirror, yaw, beacon, b_image,
                                                         target, t_image):
    sol = solve_single((0.0, 0.0), beacon, *_seen(b_image), *_seen(t_image))
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
