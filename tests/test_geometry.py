import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from solver.geometry import (
    bearing_deg,
    reflect,
    segment_crossing,
    segment_distance,
    signed_distance,
    wrap_bearing,
    wrap_yaw,
)

coord = st.floats(-200, 200, allow_nan=False)
angle = st.floats(-720, 720, allow_nan=False)


@given(coord, coord, coord, coord, angle)
def test_reflect_twice_is_identity(px, py, cx, cy, yaw):
    p = np.array([px, py])
    back = reflect(reflect(p, (cx, cy), yaw), (cx, cy), yaw)
    assert np.allclose(back, p, atol=1e-9)


@given(coord, coord, coord, coord, angle)
def test_reflection_flips_side_and_keeps_distance(px, py, cx, cy, yaw):
    p = np.array([px, py])
    q = reflect(p, (cx, cy), yaw)
    assert np.isclose(signed_distance(q, (cx, cy), yaw), -signed_distance(p, (cx, cy), yaw),
                      atol=1e-9)
    # the midpoint lies on the line
    assert abs(signed_distance((p + q) / 2, (cx, cy), yaw)) < 1e-9


def test_reflect_across_x_axis_by_hand():
    assert np.allclose(reflect([3.0, 2.0], [0, 0], 0.0), [3.0, -2.0])
    assert np.allclose(reflect([3.0, 2.0], [0, 0], 90.0), [-3.0, 2.0])
    assert np.allclose(reflect([1.0, 0.0], [0, 0], 45.0), [0.0, 1.0])


@given(angle)
def test_wraps(a):
    b = wrap_bearing(a)
    assert -180.0 < b <= 180.0
    # the same direction: cosine and sine both (a bearing wrapped to −a has the cosine)
    assert np.isclose(np.cos(np.deg2rad(a)), np.cos(np.deg2rad(b)), atol=1e-9)
    assert np.isclose(np.sin(np.deg2rad(a)), np.sin(np.deg2rad(b)), atol=1e-9)
    y = wrap_yaw(a)
    assert 0.0 <= y < 180.0
    assert np.isclose(abs(np.sin(np.deg2rad(a - y))), 0.0, atol=1e-9)


def test_bearing_quadrants():
    assert bearing_deg([0, 0], [1, 0]) == 0.0
    assert np.isclose(bearing_deg([0, 0], [0, 1]), 90.0)
    assert bearing_deg([0, 0], [-1, 0]) == 180.0
    assert np.isclose(bearing_deg([1, 1], [0, 0]), -135.0)


def test_segment_distance_and_crossing():
    assert segment_distance([0, 0], [2, 0], [1, -1], q1=[1, 1]) == 0.0
    assert np.isclose(segment_distance([0, 0], [2, 0], [3, 1], q1=[3, 5]), np.sqrt(2))
    assert np.isclose(segment_distance([0, 0], [0, 0], [1, -1], q1=[1, 1]), 1.0)
    assert np.isclose(segment_crossing([0, 0], [4, 0], [1, -1], q1=[1, 1]), 0.25)
    assert segment_crossing([0, 0], [4, 0], [5, -1], q1=[5, 1]) is None
