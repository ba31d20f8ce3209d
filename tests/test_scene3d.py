"""Scenes in 3-D: raised objects (``position: [x, y, z]``), a leaning mirror
(``mirror.lean``) and a raised one (``mirror.center: [x, y, z]``); their checks and
their exact truth, held to geometry written out here, apart from the code under test."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml

from mirrorsim.errors import SceneError
from mirrorsim.formats.scenefile import scene_document
from mirrorsim.pipelines.scenes import scene_from_dict
from mirrorsim.truth.groundtruth import GroundTruth, ground_truth
from tests.conftest import scene_dict

RAISED = {
    "name": "raised",
    "board": {"size": [80, 80]},
    "camera": {"position": [0, 0], "height": 8, "resolution": [1920, 1088], "hfov": 65.2,
               "pan": "mirror"},
    "mirror": {"center": [30, 62], "yaw": 20, "size": [24, 20], "lean": 3},
    "target": {"position": [57, 50, 3], "size": [9.9, 10]},
    "beacon": {"position": [36, 56, 2], "height": 6},
    "occluders": [{"start": [30, 34.5], "end": [38.5, 25], "height": 20}],
}


def raised(**changes) -> dict:
    d = copy.deepcopy(RAISED)
    for path, value in changes.items():
        block, key = path.split("__")
        d[block][key] = value
    return d


def _plane(center3, yaw: float, lean: float, camera3) -> tuple[np.ndarray, float]:
    """The mirror's plane written out: the board normal of the yaw's line, on the
    camera's side, turned up by the lean (its top away from the face)."""
    y = math.radians(yaw)
    n2 = np.array([-math.sin(y), math.cos(y)])
    if n2 @ (np.asarray(camera3[:2]) - np.asarray(center3[:2])) < 0:
        n2 = -n2
    lam = math.radians(lean)
    n = np.array([math.cos(lam) * n2[0], math.cos(lam) * n2[1], math.sin(lam)])
    return n, float(n @ np.asarray(center3, float))


def test_positions_take_a_height_and_the_mirror_a_lean():
    s = scene_from_dict(raised())
    assert (s.target.position, s.target.z) == ((57.0, 50.0), 3.0)
    assert (s.beacons[0].position, s.beacons[0].z) == ((36.0, 56.0), 2.0)
    assert (s.mirror.lean, s.mirror.z) == (3.0, 0.0)
    assert s.is_3d
    s2 = scene_from_dict(raised(mirror__center=[30, 62, 1.5], mirror__lean=0))
    assert s2.mirror.z == 1.5 and s2.is_3d
    assert not scene_from_dict(scene_dict("default")).is_3d


def test_the_document_writes_a_height_and_a_lean_only_where_given():
    doc = scene_document(scene_from_dict(raised()))
    assert doc["target"]["position"] == [57.0, 50.0, 3.0]
    assert doc["mirror"]["lean"] == 3.0 and len(doc["mirror"]["center"]) == 2
    assert scene_from_dict(yaml.safe_load(yaml.safe_dump(doc))) == scene_from_dict(raised())
    plain = scene_document(scene_from_dict(scene_dict("default")))
    assert len(plain["target"]["position"]) == 2 and "lean" not in plain["mirror"]


@pytest.mark.parametrize(("changes", "key", "words"), [
    ({"target__position": [57, 50, -1]}, "target.position[2]", "below the board"),
    ({"beacon__position": [36, 56, 1, 2]}, "beacon.position", "[x, y, z]"),
    ({"mirror__lean": 12}, "mirror.lean", "≤ 10"),
    ({"mirror__lean": -10.5}, "mirror.lean", "≥ -10"),
    ({"beacon__position": [36, 56, 250]}, "beacon.position[2]", "≤ 200"),
    # the glass leans towards its face by 8°: its top stands 2.8 cm before its foot,
    # over a pencil 0.9 cm before the glass
    ({"mirror__lean": -8, "beacon__position": [30, 60.5, 2]}, "beacon.position",
     "under the leaning glass"),
])
def test_bad_3d_values_are_refused_in_one_line(changes, key, words):
    with pytest.raises(SceneError) as exc:
        scene_from_dict(raised(**changes), source="s.yaml")
    assert exc.value.key == key and words in str(exc.value)


def test_the_truth_of_a_raised_scene_is_the_reflection_in_the_leaning_plane():
    s = scene_from_dict(raised())
    t = ground_truth(s)
    cam = np.array([0.0, 0.0, 8.0])
    n, rho = _plane([30.0, 62.0, 0.0], 20.0, 3.0, cam)
    for obj, base in ((t.target, [57.0, 50.0, 3.0]), (t.beacons[0], [36.0, 56.0, 2.0])):
        b = np.array(base)
        v = b - 2 * (b @ n - rho) * n
        rel = v - cam
        assert obj.position == tuple(base)
        np.testing.assert_allclose(obj.virtual, v, atol=1e-8)
        assert obj.d_total == pytest.approx(np.linalg.norm(rel), abs=1e-8)
        assert obj.alpha_deg == pytest.approx(math.degrees(math.atan2(rel[1], rel[0])), abs=1e-8)
        assert obj.elevation_deg == pytest.approx(
            math.degrees(math.asin(rel[2] / np.linalg.norm(rel))), abs=1e-8)
        # the reflection point lies on the plane and on the camera's ray to the image
        r = np.asarray(obj.reflection_point)
        assert r @ n == pytest.approx(rho, abs=1e-8)
        assert np.linalg.norm(np.cross(r - cam, rel)) == pytest.approx(0.0, abs=1e-6)
        assert obj.d1 + obj.d2 == pytest.approx(obj.d_total, abs=1e-8)
    # a planar scene's truth keeps two coordinates and no elevation
    p = ground_truth(scene_from_dict(scene_dict("default")))
    assert len(p.target.position) == 2 and p.target.elevation_deg is None


@pytest.mark.parametrize("lean", [-4.0, 2.5, 4.0])
def test_a_leaning_mirror_leans_the_image_by_twice_its_lean(lean):
    """The scene's mirror plane (the truth's and the renderer's glass) reflects an upright
    pencil into one leaning by 2λ, away from the camera for a positive lean (its top
    tipped away from the face): the glass's frame (what is rendered) and the truth's
    plane agree."""
    from mirrorsim.truth import optics, visibility

    s = scene_from_dict(raised(mirror__lean=lean))
    plane = optics.mirror_plane(s.camera, s.mirror)
    b = s.beacons[0]
    foot, top = plane.reflect(np.array([b.base3, b.base3 + [0, 0, b.height]]))
    axis = (top - foot) / b.height
    assert math.degrees(math.acos(axis[2])) == pytest.approx(2 * abs(lean), abs=1e-9)
    n, rho = _plane([30.0, 62.0, 0.0], 20.0, lean, [0, 0, 8])
    np.testing.assert_allclose(plane.normal, n, atol=1e-12)
    assert plane.rho == pytest.approx(rho, abs=1e-9)
    _, _, _, glass_n = visibility.glass_frame(s)
    np.testing.assert_allclose(glass_n, n, atol=1e-12)
    # a positive lean tips the image's top away from the camera's side of the glass
    assert np.sign(axis[:2] @ n[:2]) == -np.sign(lean)


def test_a_truth_of_a_3d_scene_reads_back_as_written():
    t = ground_truth(scene_from_dict(raised(mirror__center=[30, 62, 1.5])))
    doc = t.to_json()
    assert doc["mirror"]["lean_deg"] == 3.0 and doc["mirror"]["center"] == [30.0, 62.0, 1.5]
    back = GroundTruth.from_json(doc)
    assert back.mirror.lean == 3.0 and back.mirror.z == 1.5
    assert back.target == t.target and back.beacons == t.beacons
