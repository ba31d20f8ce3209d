import copy
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from mirrorsim.pipelines.scenes import scene_from_dict
from mirrorsim.scene.model import MIRROR_LIP, Camera, Mirror
from mirrorsim.truth import groundtruth, optics, visibility
from solver.geometry import signed_distance, unit

from .conftest import scene_dict

coord = st.floats(0, 80, allow_nan=False)


def _camera(pos=(0.0, 0.0), pan=45.0, height=6.0, res=(1920, 1088), hfov=65.2):
    return Camera(position=pos, height=height, resolution=res, hfov=hfov, pan=pan, pan_deg=pan)


@settings(max_examples=300)
@given(coord, coord, coord, coord, st.floats(0, 180), coord, coord)
def test_virtual_image_properties(cx, cy, mx, my, yaw, px, py):
    cam = _camera((cx, cy))
    mirror = Mirror(center=(mx, my), yaw=yaw, size=(18.2, 13.25))
    sc = signed_distance((cx, cy), (mx, my), yaw)
    sp = signed_distance((px, py), (mx, my), yaw)
    assume(abs(sc) > 0.5 and abs(sp) > 0.5 and sc * sp > 0)  # both in front of the mirror
    img = optics.mirror_image(cam.position, mirror, (px, py))
    # the reflection point lies on the mirror line
    assert abs(signed_distance(img.reflection_point, (mx, my), yaw)) < 1e-9
    # |camera → virtual| = d1 + d2 (paper eq 4)
    assert math.isclose(img.d_total, img.d1 + img.d2, rel_tol=0, abs_tol=1e-9)
    assert math.isclose(img.d_total, float(np.hypot(*(img.virtual - (cx, cy)))), abs_tol=1e-9)
    # the path: d1 along alpha, then d2 along the reflected bearing 2·yaw − alpha.
    # (The paper's eq 1 writes alpha − 2·yaw, the negative of that bearing: the two
    # agree only when alpha = 2·yaw mod 180.)
    end = np.array([cx, cy]) + img.d1 * unit(img.alpha_deg) + img.d2 * unit(2 * yaw - img.alpha_deg)
    assert np.allclose(end, (px, py), atol=1e-8)
    # angle of incidence equals angle of reflection at the mirror
    n = unit(yaw + 90.0)
    a_in = np.dot(unit(img.alpha_deg), n)
    a_out = np.dot((np.array([px, py]) - img.reflection_point) / img.d2, n)
    assert math.isclose(a_in, -a_out, abs_tol=1e-9)


def test_ground_truth_matches_interface_figures():
    """The documented contract quotes exp1's geometry: alpha and d_total of target and beacon."""
    s = scene_from_dict(scene_dict("exp1"))
    gt = groundtruth.ground_truth(s).to_json()
    assert gt["target"]["alpha_deg"] == pytest.approx(66.678, abs=1e-3)
    assert gt["target"]["d_total"] == pytest.approx(98.523, abs=1e-3)
    assert gt["beacons"][0]["alpha_deg"] == pytest.approx(69.499, abs=1e-3)
    assert gt["beacons"][0]["d_total"] == pytest.approx(74.702, abs=1e-3)
    assert gt["target"]["reflection_point"] == pytest.approx([28.29, 65.62], abs=5e-3)
    assert gt["camera"]["cx"] == 959.5 and gt["camera"]["cy"] == 543.5


def test_projection_edges_of_field_of_view():
    cam = _camera(pan=30.0)
    # on the optical axis: the principal point
    u, v, z = optics.project(cam, [np.r_[unit(30.0) * 50, 6.0]])
    assert np.allclose([u[0], v[0]], [cam.cx, cam.cy]) and z[0] == pytest.approx(50)
    # a point at bearing pan + hfov/2 lies on the frame's left edge (u = -0.5)
    d = unit(30.0 + cam.hfov / 2) * 40
    u, v, _ = optics.project(cam, [[d[0], d[1], 6.0]])
    assert u[0] == pytest.approx(-0.5, abs=1e-9) and v[0] == pytest.approx(cam.cy)
    # a point above the camera projects above the centre row
    u, v, _ = optics.project(cam, [np.r_[unit(30.0) * 50, 16.0]])
    assert v[0] == pytest.approx(cam.cy - cam.fx * 10 / 50)


def _default_with(**camera):
    d = copy.deepcopy(scene_dict("default"))
    d["camera"].update(camera)
    return d


@pytest.mark.parametrize("height", [4.0, 8.0, 11.0, 14.0, 16.0])
def test_vertical_clipping_by_the_mirror_top(height):
    """The ray to the target's top meets the mirror plane at hc + t·(h − hc), t = d1/d_total."""
    d = _default_with(height=height, pan="target")
    mirror_h = d["mirror"]["size"][1]
    target_h = d["target"]["size"][1]
    s = scene_from_dict(d)
    img = optics.mirror_image(s.camera.position, s.mirror, s.target.position)
    t = img.d1 / img.d_total
    z_cross = height + t * (target_h - height)
    vis = visibility.visibility(s, s.target)
    if z_cross <= mirror_h:
        assert vis.axis_fraction == 1.0
    else:
        # the part of the axis above the height whose ray meets the mirror's top edge is lost
        z_max = height + (mirror_h - height) / t
        expected = (z_max / target_h)
        assert vis.axis_fraction == pytest.approx(expected, abs=1.0 / (visibility.AXIS_SAMPLES - 1))
        assert "above its top edge" in vis.reason


def test_not_nlos_is_a_warning_not_an_error():
    d = copy.deepcopy(scene_dict("default"))
    d["occluders"] = []
    s = scene_from_dict(d)
    assert any("directly" in w for w in s.warnings)
    assert visibility.direct_view_fraction(s, s.target) == 1.0


def test_bundled_scenes_are_nlos():
    for name in ("default", "exp1", "exp2", "exp3"):
        s = scene_from_dict(scene_dict(name))
        assert visibility.direct_view_fraction(s, s.target) == 0.0, name
        for b in s.beacons:
            assert visibility.visibility(s, b).fraction == 1.0, name


@pytest.mark.parametrize("end", [-1.0, 1.0])
def test_the_frame_hides_the_strip_of_glass_beside_it(end):
    """The frame's front stands MIRROR_LIP before the glass, so a path leaving the glass
    within MIRROR_LIP·tan(incidence) of a side edge meets the frame's inner side: at one
    end the path to the object, at the other the path to the camera (independent plan
    geometry: incidence from the camera's bearing to the reflection point)."""
    s = scene_from_dict(scene_dict("default"))
    m, cam = s.mirror, s.camera
    n = np.asarray(m.normal_towards(cam.position))
    half = m.size[0] / 2
    z = 5.0
    for factor, lost in ((0.5, True), (2.0, False)):
        # a point on the glass a little inside its end, and the incidence there
        r0 = np.asarray(m.center) + end * half * unit(m.yaw)
        d_in = r0 - np.asarray(cam.position)
        tan_i = abs(d_in @ unit(m.yaw)) / abs(d_in @ n)
        r = np.asarray(m.center) + end * (half - factor * MIRROR_LIP * tan_i) * unit(m.yaw)
        d_in = (r - np.asarray(cam.position)) / np.linalg.norm(r - cam.position)
        d_out = d_in - 2 * (d_in @ n) * n
        point = r + 25.0 * d_out  # 25 cm on along the reflected ray
        why = visibility._column_failures(s, [], point, np.array([z]))[0]
        assert ("meets the frame" in why) == lost, (factor, why)
