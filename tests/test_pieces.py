"""Known answers, one piece at a time (as Mitsuba's own shape tests do): each test sets
up one object in an otherwise empty set-up, with an answer worked out by hand, so that a
failure names the piece that broke rather than "the default scene changed"."""

import math

import numpy as np
import pytest

from mirrorsim.pipelines.scenes import load_scene
from mirrorsim.scene.model import FRONT_OFFSET, Mirror, pencil_paint_height
from mirrorsim.truth import optics
from solver.sltr import solve_single

from .conftest import SCENES


def test_optics_one_point_in_a_flat_mirror():
    """Camera at the origin, the mirror's line y = 10 (yaw 0), a point at (0, 5): its
    image stands at (0, 15), straight ahead (α = 90°), 15 away: 10 to the glass, 5 back."""
    img = optics.mirror_image((0.0, 0.0), Mirror((0.0, 10.0), 0.0, (20.0, 10.0)), (0.0, 5.0))
    assert tuple(img.virtual) == pytest.approx((0.0, 15.0))
    assert (img.alpha_deg, img.d_total, img.d1, img.d2) == pytest.approx((90, 15, 10, 5))
    assert tuple(img.reflection_point) == pytest.approx((0.0, 10.0))


def test_optics_a_slanted_mirror():
    """The line y = x (through (10, 10), yaw 45°) maps the point (10, 0) to (0, 10); from
    a camera at (20, 0) that image lies √500 away, and the ray to it meets y = x where
    20 − 20t = 10t: at (20/3, 20/3)."""
    img = optics.mirror_image((20.0, 0.0), Mirror((10.0, 10.0), 45.0, (40.0, 10.0)),
                              (10.0, 0.0))
    assert tuple(img.virtual) == pytest.approx((0.0, 10.0))
    assert img.d_total == pytest.approx(math.sqrt(500))
    assert tuple(img.reflection_point) == pytest.approx((20 / 3, 20 / 3))
    assert img.alpha_deg == pytest.approx(math.degrees(math.atan2(10, -20)))


def test_solver_one_beacon_closed_form():
    """Mirror y = 10 seen from the origin; beacon (3, 6) → image (3, 14); target (−4, 2)
    → image (−4, 18).  The closed form returns that line and that target exactly."""
    sol = solve_single((0.0, 0.0), (3.0, 6.0), math.degrees(math.atan2(14, 3)),
                       beacon_d_total=math.hypot(3, 14),
                       target_alpha_deg=math.degrees(math.atan2(18, -4)),
                       target_d_total=math.hypot(4, 18))
    assert sol.mirror.yaw_deg % 180 == pytest.approx(0.0, abs=1e-9) or \
        sol.mirror.yaw_deg % 180 == pytest.approx(180.0, abs=1e-9)
    assert float(np.asarray(sol.mirror.point)[1]) == pytest.approx(10.0)
    assert tuple(sol.target) == pytest.approx((-4.0, 2.0))


def test_render_and_detect_one_pencil_in_direct_view():
    """The pencil alone on a plain board, 100 cm ahead on the optical axis: its painted
    band (3.0 of its 4.2 cm) measures fx·3.0/(100 − its near side's 0.338 cm) px."""
    from mirrorsim.pipelines.calibrate import measure_reference

    scene = load_scene(SCENES / "default.yaml")
    height = scene.beacons[0].height
    expected = scene.camera.fx * pencil_paint_height(height) / (100 - FRONT_OFFSET["beacon"])
    assert measure_reference(scene.camera, "beacon", height) == pytest.approx(expected, abs=0.1)


def test_a_small_reference_pencil_is_measured_on_an_enlarged_film():
    """A 2.2 cm pencil 100 cm ahead of a 960 × 544 camera of 88°: its painted band (1.43
    cm) is fx·1.43/99.66 ≈ 7.2 px, under what the detector finds.  It is rendered on a
    film four times enlarged (same field of view: fx exactly four times) and its height
    divided back, to within 0.05 px of that projection."""
    from mirrorsim.pipelines.calibrate import measure_reference, reference_film
    from mirrorsim.scene.model import Camera

    cam = Camera((0.0, 0.0), 4.5, (960, 544), 87.5, 45.0, 45.0)
    expected = cam.fx * pencil_paint_height(2.19) / (100 - FRONT_OFFSET["beacon"])
    assert expected < 8 and reference_film(cam, "beacon", 2.19) == 4
    assert reference_film(cam, "target", (6.8, 10.7)) == 1
    assert measure_reference(cam, "beacon", 2.19) == pytest.approx(expected, abs=0.05)
