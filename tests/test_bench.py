"""Bench imperfections: each rendered effect against an independent first-order (or
exact closed-form) prediction on small renders; the capture record; bad values; the
budget."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
import yaml

from mirrorsim.camera.sensor import add_noise, undistort_points
from mirrorsim.cli.main import main
from mirrorsim.detection.frame_files import read_frame
from mirrorsim.formats.capture import CaptureRecord
from mirrorsim.pipelines.frame import render_and_measure
from mirrorsim.pipelines.scenes import scene_from_dict
from mirrorsim.rendering.frames import scene_fingerprint
from mirrorsim.rendering.id_pass import IN_MIRROR
from mirrorsim.rendering.mitsuba_scene import TARGET_LABEL
from mirrorsim.scene import imperfections
from mirrorsim.scene.model import FRONT_OFFSET, Bench, SensorNoise
from mirrorsim.truth import groundtruth, optics, visibility

from .conftest import scene_dict

W, H = 960, 544  # half size


def bench_dict(camera=None, mirror=None, calibration=None, beacon=None, spp=8) -> dict:
    d = copy.deepcopy(scene_dict("default"))
    d["camera"]["resolution"] = [W, H]
    d["camera"].update(camera or {})
    d["mirror"].update(mirror or {})
    d["beacon"].update(beacon or {})
    if calibration:
        d["calibration"] = calibration
    d["render"] = {"spp": spp}
    return d


def bench_scene(**kw):
    return scene_from_dict(bench_dict(**kw), source="bench.yaml", default_name="default")


def measure(scene, tmp, name):
    """Render, calibrate (as the bench did) and detect: the frame's files and detection."""
    m = render_and_measure(scene, tmp / name, progress=False)
    return m.files, m.detection


@pytest.fixture(scope="module")
def ideal(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bench")
    scene = bench_scene()
    return scene, *measure(scene, tmp, "ideal"), tmp


# ---------------------------------------------------------------- scene files


@pytest.mark.parametrize("where,key,value,message", [
    ("mirror", "curvature_radius", 15.0, "mirror.curvature_radius"),
    ("mirror", "curvature_radius", 0, "mirror.curvature_radius"),
    ("mirror", "tilt", 45, "mirror.tilt"),
    ("mirror", "tilt", -50, "mirror.tilt"),
    ("camera", "noise", {"full_well": 6000, "read_noise": -1}, "camera.noise.read_noise"),
    ("camera", "noise", {"full_well": 0, "read_noise": 4}, "camera.noise.full_well"),
    ("camera", "jpeg_quality", 0, "camera.jpeg_quality"),
    ("camera", "jpeg_quality", 101, "camera.jpeg_quality"),
    ("camera", "distortion", [-0.9, 0.0], "camera.distortion"),
    ("camera", "distortion", [0.1], "camera.distortion"),
    ("camera", "pitch", 25, "camera.pitch"),
    ("camera", "distortion_known", "yes", "camera.distortion_known"),
    ("beacon", "known_position", [95, 40], "beacon.known_position"),
    ("calibration", "distance_error", -60, "calibration.distance_error"),
])
def test_bad_imperfections_refused(tmp_path, capsys, where, key, value, message):
    d = bench_dict()
    d.setdefault(where, {})[key] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(d))
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and message in err


def test_imperfections_read_and_listed():
    s = bench_scene(camera={"pan_error": 0.5, "noise": {"full_well": 6000, "read_noise": 4},
                            "distortion": [-0.05, 0.01], "distortion_known": False},
                    mirror={"curvature_radius": 1500, "tilt": 0.5},
                    calibration={"distance_error": 1.0}, beacon={"known_position": [36.3, 56]})
    assert s.bench == Bench(pan_error=0.5, distortion=(-0.05, 0.01), distortion_known=False,
                            noise=SensorNoise(6000.0, 4.0), curvature_radius=1500.0, tilt=0.5,
                            calibration_distance_error=1.0)
    keys = [src.key for src in imperfections.sources(s)]
    assert keys == ["camera.pan_error", "camera.distortion", "camera.noise",
                    "mirror.curvature_radius", "mirror.tilt", "calibration.distance_error",
                    "beacons[0].known_position"]
    only = imperfections.only(s, "camera.distortion")
    assert only.bench == Bench(distortion=(-0.05, 0.01), distortion_known=False)
    assert only.beacons[0].known_position is None
    assert imperfections.only(s, "beacons[0].known_position").bench == Bench()
    assert imperfections.sources(imperfections.ideal(s)) == []


def test_capture_record_holds_what_the_experimenter_believes():
    s = bench_scene(camera={"pan_error": -0.7, "distortion": [-0.05, 0.0]},
                    beacon={"known_position": [36.3, 55.8]})
    rec = CaptureRecord.from_scene(s)
    assert rec.camera.pan_deg == pytest.approx(s.camera.pan_deg - 0.7, abs=1e-12)
    assert rec.beacons[0].position == (36.3, 55.8)
    assert rec.distortion == (-0.05, 0.0)
    again = CaptureRecord.from_json(json.loads(json.dumps(rec.to_json())))
    assert again.distortion == rec.distortion and again.beacons == rec.beacons
    unknown = bench_scene(camera={"distortion": [-0.05, 0.0], "distortion_known": False})
    assert CaptureRecord.from_scene(unknown).distortion == (0.0, 0.0)


def test_ideal_keys_change_nothing():
    """Zero-valued imperfections are the ideal bench: same model, same fingerprint."""
    plain = bench_scene()
    zeros = bench_scene(camera={"pan_error": 0, "pitch": 0, "roll": 0, "distortion": [0, 0]},
                        mirror={"tilt": 0}, calibration={"distance_error": 0})
    assert zeros == plain
    assert scene_fingerprint(zeros) == scene_fingerprint(plain)


# ---------------------------------------------------------------- the sensor


def test_undistortion_inverts_the_lens():
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-0.7, 0.7, 1000), rng.uniform(-0.4, 0.4, 1000)
    k = (-0.08, 0.02)
    f = 1 + k[0] * (x**2 + y**2) + k[1] * (x**2 + y**2) ** 2
    xu, yu = undistort_points(x * f, y * f, k)
    assert np.abs(xu - x).max() < 1e-9 and np.abs(yu - y).max() < 1e-9


def test_noise_has_the_sensor_statistics():
    """Shot noise: variance = mean electrons; read noise adds σ²; both in radiance units."""
    lin = np.full((400, 400, 3), 0.2, np.float32)
    noise = SensorNoise(full_well=5000.0, read_noise=10.0)
    out = add_noise(lin, noise, seed=3)
    var_expected = (0.2 * 5000 + 10.0**2) / 5000**2
    assert out.mean() == pytest.approx(0.2, rel=2e-3)
    assert out.var() == pytest.approx(var_expected, rel=0.03)
    assert np.array_equal(out, add_noise(lin, noise, seed=3))
    assert not np.array_equal(out, add_noise(lin, noise, seed=4))


# ---------------------------------------------------------------- rendered effects


def test_pan_error_shifts_every_alpha_by_itself(ideal):
    scene0, files0, det0, tmp = ideal
    scene = bench_scene(camera={"pan_error": 0.5})
    files, det = measure(scene, tmp, "pan")
    # the same photograph: only the mount's report differs
    assert read_frame(files.image).tobytes() == read_frame(files0.image).tobytes()
    assert det.target.alpha_deg - det0.target.alpha_deg == pytest.approx(0.5, abs=1e-9)
    assert det.beacons[0][1].alpha_deg - det0.beacons[0][1].alpha_deg == pytest.approx(
        0.5, abs=1e-9)
    assert det.target.d_total == pytest.approx(det0.target.d_total, rel=1e-12)


def test_known_position_reaches_the_record_not_the_frame(ideal):
    _, files0, det0, tmp = ideal
    scene = bench_scene(beacon={"known_position": [36.4, 55.7]})
    files, det = measure(scene, tmp, "known")
    assert read_frame(files.image).tobytes() == read_frame(files0.image).tobytes()
    assert det.beacons[0][0].position == (36.4, 55.7)
    assert files.truth.beacons[0].position == (36.0, 56.0)  # the truth: where it stands


def _paths(scene, obj):
    img = optics.mirror_image(scene.camera.position, scene.mirror, obj.position)
    rp = img.reflection_point - np.asarray(scene.camera.position)
    n = scene.mirror.normal_towards(scene.camera.position)
    return img, abs(rp @ n) / np.linalg.norm(rp)


@pytest.mark.parametrize("radius", [600.0, -600.0])
def test_spherical_mirror_magnifies_as_its_focal_lengths_say(ideal, radius):
    """A mirror of power P seen from d1, the object d2 behind it: the object's angular size
    is that of a flat mirror's image at d1 + d2 − d1·d2·P.  Vertical (sagittal) power
    2 cos i / R, horizontal (tangential) 2 / (R cos i): the size-constancy distance shrinks
    by 2 cos i·d1·d2/R and the image's width/height ratio changes (astigmatism)."""
    scene0, _, det0, tmp = ideal
    scene = bench_scene(mirror={"curvature_radius": radius})
    _, det = measure(scene, tmp, f"curved{radius:+.0f}")
    img, cos_i = _paths(scene, scene.target)
    d = img.d_total
    sag = 2 * cos_i * img.d1 * img.d2 / radius
    tan = 2 * img.d1 * img.d2 / (radius * cos_i)
    predicted = -sag / d
    measured = det.target.d_total / det0.target.d_total - 1
    assert measured == pytest.approx(predicted, rel=0.15)
    ratio = lambda m: m.width_px / m.height_px  # noqa: E731
    assert ratio(det.target) / ratio(det0.target) == pytest.approx((d - sag) / (d - tan),
                                                                   rel=0.01)


def _reflect(p3, pivot3, normal3):
    return p3 - 2 * ((p3 - pivot3) @ normal3) * normal3


def test_tilted_mirror_moves_the_image_as_the_reflection_says(ideal):
    """The target's foot and top rows move as the exact reflection across the tilted plane
    (about the mirror's bottom edge) puts them, projected by the ideal pinhole."""
    scene0, _, det0, tmp = ideal
    tilt = 2.0
    scene = bench_scene(mirror={"tilt": tilt})
    _, det = measure(scene, tmp, "tilt")
    m = scene.mirror
    n0 = np.r_[m.normal_towards(scene.camera.position), 0.0]
    t = math.radians(tilt)
    n1 = math.cos(t) * n0 + math.sin(t) * np.array([0, 0, 1.0])
    pivot = np.r_[m.center, 0.0]
    p = np.asarray(scene.target.position)
    pts = np.array([[*p, 0.0], [*p, scene.target.height]])
    _, v_flat, _ = optics.project(scene.camera, [_reflect(q, pivot, n0) for q in pts])
    _, v_tilt, _ = optics.project(scene.camera, [_reflect(q, pivot, n1) for q in pts])
    assert v_tilt[0] - v_flat[0] > 8  # many pixels: a real test
    # the top moves more than the foot: the tilted image leans away, its top farther
    assert v_tilt[1] - v_flat[1] > v_tilt[0] - v_flat[0] + 0.5
    # the foot within 0.4 px: in the tilted glass the board's contact shadow shrinks to
    # about one pixel row and turns to the room's colour, which the foot's level (the
    # first row past it, in the colour across the board's) cannot follow: the flat
    # frame's foot reads 0.001 px from its projection, the tilted one's 0.32
    assert det.target.v_bottom - det0.target.v_bottom == pytest.approx(
        v_tilt[0] - v_flat[0], abs=0.4)
    assert det.target.v_top - det0.target.v_top == pytest.approx(v_tilt[1] - v_flat[1],
                                                                 abs=0.3)


def test_visibility_reflects_in_the_tilted_glass_as_the_closed_form():
    """The visibility checks' reflection (visibility.glass_hits) in a tilted glass: the
    apparent point is the point reflected across the tilted plane (closed form), and the
    reflection point lies on that plane."""
    scene = bench_scene(mirror={"tilt": 3.0})
    m = scene.mirror
    n0 = np.r_[m.normal_towards(scene.camera.position), 0.0]
    t = math.radians(3.0)
    n1 = math.cos(t) * n0 + math.sin(t) * np.array([0, 0, 1.0])
    pivot = np.r_[m.center, 0.0]
    pts = np.array([[*scene.target.position, z] for z in (0.0, 7.0, scene.target.height)])
    a, b, apparent = visibility.glass_hits(scene, pts)
    for q, app in zip(pts, apparent, strict=True):
        assert app == pytest.approx(_reflect(q, pivot, n1), abs=1e-9)
    g, along, up, n = visibility.glass_frame(scene)
    assert n == pytest.approx(n1) and (g - pivot) @ n1 == pytest.approx(0.0, abs=1e-12)


def test_visibility_sees_the_curved_glass_where_the_render_does(ideal):
    """The image of the target's axis through a concave glass (R = 600): where
    visibility.glass_hits puts its foot and top and the column of its axis, against the
    detector's measurement on the render, both as shifts from the flat mirror."""
    scene0, _, det0, tmp = ideal
    scene = bench_scene(mirror={"curvature_radius": 600.0})
    _, det = measure(scene, tmp, "curved_for_visibility")
    pts = np.array([[*scene.target.position, 0.0], [*scene.target.position,
                                                     scene.target.height]])
    u0, v0, _ = optics.project(scene0.camera, visibility.glass_hits(scene0, pts)[2])
    u1, v1, _ = optics.project(scene.camera, visibility.glass_hits(scene, pts)[2])
    assert abs(u1[0] - u0[0]) + abs(v1[1] - v0[1]) > 2  # the glass moves it: a real test
    assert det.target.u_axis - det0.target.u_axis == pytest.approx(u1[0] - u0[0], abs=0.5)
    assert det.target.v_bottom - det0.target.v_bottom == pytest.approx(v1[0] - v0[0],
                                                                       abs=0.5)
    assert det.target.v_top - det0.target.v_top == pytest.approx(v1[1] - v0[1], abs=0.5)


def test_pitch_moves_rows_as_a_rotated_pinhole(ideal):
    """A camera pitched up by p sees the direction (x, y, 1) at
    ((x, y cos p + sin p) / (cos p − y sin p)) (v down): closed form, no Mitsuba."""
    scene0, _, det0, tmp = ideal
    pitch = 3.0
    scene = bench_scene(camera={"pitch": pitch})
    _, det = measure(scene, tmp, "pitch")
    cam, p = scene.camera, math.radians(pitch)
    for v0, v1 in ((det0.target.v_bottom, det.target.v_bottom),
                   (det0.target.v_top, det.target.v_top)):
        x = (det0.target.u_axis - cam.cx) / cam.fx
        y = (v0 - cam.cy) / cam.fx
        z = math.cos(p) - y * math.sin(p)
        assert abs(x) < 0.5  # the target stands near the middle column (x enters u only)
        assert v1 - v0 == pytest.approx(cam.fx * (y * math.cos(p) + math.sin(p)) / z
                                        + cam.cy - v0, abs=0.3)


def test_roll_turns_the_image_about_the_principal_point(ideal):
    """Rolled clockwise (seen from behind), the camera sees the image turned
    counter-clockwise on screen about the principal point: the target's image (its
    pixels in the id pass) turned by the roll, centroid and orientation alike."""
    scene0, files0, _, tmp = ideal
    roll = 4.0
    scene = bench_scene(camera={"roll": roll})
    files, _ = measure(scene, tmp, "roll")
    cam = scene.camera
    r = math.radians(roll)
    turn = np.array([[math.cos(r), math.sin(r)], [-math.sin(r), math.cos(r)]])

    def pixels(files):
        ids = read_frame(files.ids_png)[..., 0]
        vs, us = np.nonzero(ids == IN_MIRROR + TARGET_LABEL)
        return np.column_stack([us - cam.cx, vs - cam.cy])

    def orientation(cov):
        return math.degrees(0.5 * math.atan2(2 * cov[0, 1], cov[0, 0] - cov[1, 1]))

    p0, p1 = pixels(files0), pixels(files)
    expect = turn @ p0.mean(axis=0)
    assert p1.mean(axis=0) == pytest.approx(expect, abs=0.5)
    cov_expect = turn @ np.cov(p0.T) @ turn.T
    assert orientation(np.cov(p1.T)) == pytest.approx(orientation(cov_expect), abs=0.3)
    # the roll is really there: the image's orientation moved by several degrees
    assert abs(orientation(np.cov(p1.T)) - orientation(np.cov(p0.T))) > 3.0


@pytest.fixture(scope="module")
def offaxis_ideal(ideal):
    """The ideal bench panned 12° off the mirror: the target's image well off-centre,
    where a lens distorts."""
    scene0, _, _, tmp = ideal
    pan = scene0.camera.pan_deg - 12.0
    scene = bench_scene(camera={"pan": pan})
    return pan, *measure(scene, tmp, "offaxis")[1:]


@pytest.mark.parametrize("known", [True, False])
def test_lens_distortion(offaxis_ideal, tmp_path, known):
    """Known to the detector, a lens changes nothing but resampling; unknown, the target's
    α (the mean bearing of its two side edges) is off by the Brown–Conrady shifts of
    those edges: x_d = x·(1 + k1 r² + k2 r⁴)."""
    pan, det0 = offaxis_ideal
    k = (-0.1, 0.0)
    scene = bench_scene(camera={"pan": pan, "distortion": list(k), "distortion_known": known})
    _, det = measure(scene, tmp_path, "lens")
    da = det.target.alpha_deg - det0.target.alpha_deg
    if known:
        assert abs(da) < 0.01
        assert det.target.d_total == pytest.approx(det0.target.d_total, rel=0.003)
    else:
        cam = scene.camera
        y = ((det0.target.v_top + det0.target.v_bottom) / 2 - cam.cy) / cam.fx
        x = np.array([det0.target.u_left, det0.target.u_right]) - cam.cx
        x = x / cam.fx
        xd = x * (1 + k[0] * (x * x + y * y) + k[1] * (x * x + y * y) ** 2)
        predicted = -math.degrees(np.mean(np.arctan(xd)) - np.mean(np.arctan(x)))
        assert abs(predicted) > 0.05
        assert da == pytest.approx(predicted, rel=0.1, abs=0.005)


def test_calibration_distance_scales_every_d_total(ideal):
    """The reference stood at 100 + e while 100 was assumed: every K, so every d_total,
    shrinks by (100 − f)/(100 + e − f), f the measured face's offset."""
    scene0, _, det0, tmp = ideal
    e = 5.0
    scene = bench_scene(calibration={"distance_error": e})
    _, det = measure(scene, tmp, "caldist")
    ft, fb = FRONT_OFFSET["target"], FRONT_OFFSET["beacon"]
    # d_total = (K/s + f)/cos φ: the K part scales, the face offset does not
    kt = det.target.d_total - ft / math.cos(math.radians(det.target.alpha_deg
                                                          - scene.camera.pan_deg))
    kt0 = det0.target.d_total - ft / math.cos(math.radians(det0.target.alpha_deg
                                                            - scene.camera.pan_deg))
    assert kt / kt0 == pytest.approx((100 - ft) / (100 + e - ft), rel=0.003)
    b, b0 = det.beacons[0][1].d_total, det0.beacons[0][1].d_total
    assert b / b0 == pytest.approx((100 - fb) / (100 + e - fb), rel=0.015)


def test_sensor_noise_moves_the_bearing_as_first_order_predicts(ideal):
    """Shot and read noise alone, against a prediction made from the ideal frame's own
    levels either side of the panel's edges (from the id pass's box, not the detector):
    per row an edge found from the coverage of 3 pixels errs by √3·σ_I/ΔI px (σ_I the
    noise of the channels' mean at the edge's level), the median of N rows by
    1.25·that/√N, the bearing (the mean angle of two edges) by half their quadrature sum;
    the measured shift stays within 4σ of it."""
    from mirrorsim.camera.sensor import srgb8_to_linear

    scene0, files0, det0, tmp = ideal
    fw, rn = 6000.0, 4.0
    files, det = measure(bench_scene(camera={"noise": {"full_well": fw, "read_noise": rn}}),
                         tmp, "noise_only")
    lin = srgb8_to_linear(read_frame(files0.image)).mean(axis=2)
    u0, v0, u1, v1 = files0.truth.target.bbox_px
    rows = slice(v0 + (v1 - v0) // 4, v1 - (v1 - v0) // 4)
    inside = float(np.median(lin[rows, u0 + 4:u1 - 4]))

    def sigma_edge(outside: float) -> float:
        level = (inside + outside) / 2
        s_i = math.sqrt(level / fw + (rn / fw) ** 2) / math.sqrt(3)
        return 1.2533 * math.sqrt(3) * s_i / abs(inside - outside) / math.sqrt(v1 - v0)

    left = float(np.median(lin[rows, u0 - 7:u0 - 3]))
    right = float(np.median(lin[rows, u1 + 3:u1 + 7]))
    sigma_alpha = math.degrees(math.hypot(sigma_edge(left), sigma_edge(right)) / 2
                               / scene0.camera.fx)
    assert abs(det.target.alpha_deg - det0.target.alpha_deg) < 4 * sigma_alpha


def test_noise_and_jpeg_frames_still_measure(ideal):
    # a loose check that a noisy JPEG frame still measures; the noise's effect on the
    # bearing is held to its first-order prediction above.  Its effect on d_total is not
    # first order (benchmarks/sensor_noise.py: 3σ of the first-order spread at a full
    # well of 6000, 12σ at 1500), hence 1 % here
    scene0, _, det0, tmp = ideal
    scene = bench_scene(camera={"noise": {"full_well": 6000, "read_noise": 4},
                                "jpeg_quality": 90})
    with pytest.warns(RuntimeWarning, match="JPEG"):
        files, det = measure(scene, tmp, "noisy")
        img = read_frame(files.image).astype(float)
    assert files.image.suffix == ".jpg" and files.image.read_bytes()[:3] == b"\xff\xd8\xff"
    assert abs(det.target.alpha_deg - det0.target.alpha_deg) < 0.05
    assert det.target.d_total == pytest.approx(det0.target.d_total, rel=0.01)
    # the noise is there: the frame differs from the ideal one everywhere, not by a code
    assert np.abs(img - read_frame(ideal[1].image).astype(float)).mean() > 1.0


# ---------------------------------------------------------------- the budget


def test_budget_measures_each_source_and_predicts_it(tmp_path, capsys):
    d = bench_dict(camera={"pan_error": 0.5}, beacon={"known_position": [36.4, 56.0]},
                   mirror={"curvature_radius": 1500})
    path = tmp_path / "bench.yaml"
    path.write_text(yaml.safe_dump(d))
    out = tmp_path / "budget"
    assert main(["budget", str(path), "--out", str(out), "--quiet",
                 "--json", str(tmp_path / "b.json")]) == 0
    printed = capsys.readouterr().out
    assert "camera.pan_error" in printed and "mirror.curvature_radius" in printed
    doc = json.loads((tmp_path / "b.json").read_text(), parse_constant=pytest.fail)
    assert doc == json.loads((out / "budget.json").read_text())
    assert (out / "budget.png").read_bytes()[:4] == b"\x89PNG"
    by = {s["source"]: s for s in doc["sources"]}
    assert list(by) == ["camera.pan_error", "mirror.curvature_radius",
                        "beacons[0].known_position"]
    pan = by["camera.pan_error"]["delta"]
    assert pan["target_alpha_deg"] == pytest.approx(0.5, abs=1e-9)
    assert pan["beacon_alpha_deg"] == [pytest.approx(0.5, abs=1e-9)]
    assert by["beacons[0].known_position"]["delta"]["beacon_position_cm"] == [
        pytest.approx(0.4, abs=1e-9)]
    # sources that move the measurements by known amounts: the first-order prediction
    # (Jacobian × delta) lands within 10 % of the solved estimate's shift
    for key in ("camera.pan_error", "beacons[0].known_position"):
        assert by[key]["predicted_shift_cm"] == pytest.approx(by[key]["shift_cm"], rel=0.1)
        assert by[key]["shift_cm"] > 0.3
    # the curved mirror shrinks the target's d_total by about 2 cos i d1 d2 / R
    scene = bench_scene(mirror={"curvature_radius": 1500})
    img, cos_i = _paths(scene, scene.target)
    predicted = -100 * 2 * cos_i * img.d1 * img.d2 / 1500 / img.d_total
    assert by["mirror.curvature_radius"]["delta"]["target_d_total_pct"] == pytest.approx(
        predicted, rel=0.2)
    # the ideal bench within the detector's few millimetres; every imperfection beyond it
    assert doc["ideal"]["target_cm"] < 1.0 < doc["all"]["target_cm"]
    for name in ("ideal", "camera.pan_error", "beacons0.known_position", "all"):
        assert (out / name / "default.png").exists()
        assert not (out / name / "default.annotated.png").exists()  # only with --keep


def test_truth_names_the_bench_it_was_rendered_with(ideal):
    scene0, files0, _, tmp = ideal
    assert "bench" not in files0.truth.to_json()  # the ideal bench's truth as before
    scene = bench_scene(camera={"pan_error": 0.5, "distortion": [-0.05, 0.0],
                                "distortion_known": False})
    truth = groundtruth.ground_truth(scene).to_json()
    assert truth["bench"] == {"camera.pan_error": 0.5, "camera.distortion": [-0.05, 0.0],
                              "camera.distortion_known": False}
    # and the truth is the ideal geometry: the pan error is not in it
    assert truth["camera"]["pan_deg"] == files0.truth.to_json()["camera"]["pan_deg"]


def test_a_bench_scene_written_as_a_file_reads_back_the_same():
    """`to_yaml` (the dataset's scene files) keeps every imperfection."""
    from mirrorsim.pipelines.random_scenes import to_yaml

    s = bench_scene(camera={"pan_error": 0.5, "pitch": 1.0, "roll": -0.5,
                            "distortion": [-0.05, 0.01], "distortion_known": False,
                            "noise": {"full_well": 6000, "read_noise": 4},
                            "jpeg_quality": 85},
                    mirror={"curvature_radius": -1500, "tilt": 0.5},
                    calibration={"distance_error": 1.0}, beacon={"known_position": [36.3, 56]})
    again = scene_from_dict(yaml.safe_load(to_yaml(s)), source="again.yaml")
    assert again.bench == s.bench and again.beacons == s.beacons
    assert yaml.safe_load(to_yaml(bench_scene())).get("calibration") is None


# ---------------------------------------------------------------- shared renders

SMALL = {"resolution": [480, 272]}


def test_every_imperfection_says_where_it_acts():
    stages = {imp.field: imp.stage for imp in imperfections.REGISTRY}
    assert set(stages.values()) <= {"optics", "sensor", "record"}
    # fixed in advance from what each one is on a bench: light paths, the sensor, beliefs
    assert stages == {"pan_error": "record", "pitch": "optics", "roll": "optics",
                      "distortion": "optics", "distortion_known": "record",
                      "noise": "sensor", "jpeg_quality": "sensor",
                      "curvature_radius": "optics", "tilt": "optics",
                      "calibration_distance_error": "record", "known_position": "record"}


def test_frames_that_differ_after_the_render_share_it_bit_for_bit(monkeypatch):
    from mirrorsim.rendering import passes

    after = bench_scene(camera={**SMALL, "pan_error": 0.7, "jpeg_quality": 80,
                                "noise": {"full_well": 3000, "read_noise": 5}},
                        calibration={"distance_error": 2.0},
                        beacon={"known_position": [36.4, 56.0]})
    tilted = bench_scene(camera=SMALL, mirror={"tilt": 1.0})
    fresh = passes.render_frame(after, progress=False)  # outside the scope: its own render
    rendered = []
    real = passes._render_optics
    monkeypatch.setattr(passes, "_render_optics",
                        lambda s, *a: rendered.append(s.name) or real(s, *a))
    with passes.reusing_renders(1):
        passes.render_frame(imperfections.ideal(after), progress=False)
        shared = passes.render_frame(after, progress=False)
        other = passes.render_frame(tilted, progress=False)
    assert len(rendered) == 2  # the ideal bench's and the tilted mirror's, not `after`'s
    assert shared.info.seconds_render == 0.0 and fresh.info.seconds_render > 0
    for a, b in ((shared.linear, fresh.linear), (shared.first, fresh.first),
                 (shared.in_mirror, fresh.in_mirror)):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(other.in_mirror, fresh.in_mirror)  # the glass moved
    with pytest.raises(ValueError):
        shared.first[0, 0] = 1  # a kept render cannot be drawn on by one of its users
    assert passes._KEPT.get() is None  # nothing kept past the scope


def test_a_frame_measured_while_it_is_written_matches_one_read_back(tmp_path):
    from mirrorsim.pipelines.frame import measure_frame, render_to_files

    scene = bench_scene(camera=SMALL)
    m = render_and_measure(scene, tmp_path / "a", progress=False)
    files = render_to_files(scene, tmp_path / "b", progress=False)
    for name in ("default.png", "default.capture.json", "default.ids.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    back = measure_frame(files.image, files.capture)  # decoded from the file
    assert back.detection.to_json() == m.detection.to_json()
    again = render_and_measure(scene, tmp_path / "a", progress=False)  # reused, verified
    assert again.files.reused and again.detection.to_json() == m.detection.to_json()


def test_budget_renders_once_per_optics(tmp_path, monkeypatch):
    from mirrorsim.pipelines.budget import run_budget
    from mirrorsim.rendering import passes

    scene = bench_scene(camera={**SMALL, "pan_error": 0.5}, mirror={"tilt": 0.5},
                        calibration={"distance_error": 1.0})
    rendered = []
    real = passes._render_optics
    monkeypatch.setattr(passes, "_render_optics",
                        lambda s, *a: rendered.append(s.name) or real(s, *a))
    budget = run_budget(scene, tmp_path / "b", progress=False)
    # ideal, pan and calibration share the ideal's optics; tilt and all have their own
    assert len(rendered) == 3
    assert [c.source for c in budget.sources] == ["camera.pan_error", "mirror.tilt",
                                                  "calibration.distance_error"]
    assert budget.sources[0].delta.target_alpha_deg == pytest.approx(0.5, abs=1e-9)
    assert budget.all is not None and budget.all.target_cm > 0


def test_budget_says_when_the_ideal_bench_cannot_be_measured(tmp_path, monkeypatch):
    from mirrorsim.errors import DetectionError
    from mirrorsim.pipelines import budget

    def refuse(*_a, **_k):
        raise DetectionError("no target (grey upright panel) found in the frame")

    monkeypatch.setattr(budget, "evaluate_into", refuse)
    scene = bench_scene(camera={**SMALL, "pan_error": 0.5}, mirror={"tilt": 0.5})
    with pytest.raises(DetectionError, match="^the ideal bench: no target"):
        budget.run_budget(scene, tmp_path / "b", progress=False)


@pytest.mark.parametrize("hfov", [65.2, 60.0])
def test_a_jpeg_frame_is_measured_its_own_way(tmp_path, hfov):
    """JPEG keeps luma at full resolution and chroma at half: the tops and feet measured
    on linear chroma move by up to 2.5 px (benchmarks/jpeg_edges.py).  The same render,
    stored both ways: measured the JPEG way (edges.measure_region), the JPEG's d_total's
    stay near the lossless frame's."""
    from mirrorsim.detection.detector import detect_frame
    from mirrorsim.pipelines.frame import calibration_for

    lossless = bench_scene(camera={"hfov": hfov})
    jpeg = bench_scene(camera={"hfov": hfov, "jpeg_quality": 90})
    _, det0 = measure(lossless, tmp_path, "png")
    with pytest.warns(RuntimeWarning, match="JPEG"):
        files, det = measure(jpeg, tmp_path, "jpg")
    with pytest.warns(RuntimeWarning, match="JPEG"):
        pixels = read_frame(files.image)

    def errors(d):
        return (100 * abs(d.target.d_total / det0.target.d_total - 1),
                100 * abs(d.beacons[0][1].d_total / det0.beacons[0][1].d_total - 1))

    target, beacon = errors(det)
    assert target < 0.15 and beacon < 1.0
    # measured on chroma as a lossless frame is, the same JPEG errs more
    chroma = detect_frame(pixels, files.capture, calibration_for(files.capture),
                          subsampled=False)
    assert max(errors(chroma)) > 2.0
    assert det.target.alpha_deg == pytest.approx(det0.target.alpha_deg, abs=0.005)


def test_jpeg_frames_have_their_own_calibration():
    from mirrorsim.pipelines.calibrate import calibration_key

    cam = bench_scene().camera
    keys = {calibration_key(cam, (9.9, 15.25), 4.2, distance_error=0.0,
                            subsampled=sub) for sub in (False, True)}
    assert len(keys) == 2


def test_a_frame_and_its_kind_come_from_one_read(tmp_path):
    import cv2

    from mirrorsim.detection.frame_files import read_stored_frame

    rgb = np.zeros((16, 24, 3), np.uint8)
    rgb[4:12, 6:18] = (200, 180, 40)
    ok_j, jpg = cv2.imencode(".jpg", rgb[..., ::-1])
    ok_p, png = cv2.imencode(".png", rgb[..., ::-1])
    assert ok_j and ok_p
    (tmp_path / "named.png").write_bytes(jpg.tobytes())  # a JPEG whatever its name
    (tmp_path / "named.jpg").write_bytes(png.tobytes())
    with pytest.warns(RuntimeWarning, match="JPEG"):
        j = read_stored_frame(tmp_path / "named.png", (24, 16))
    p = read_stored_frame(tmp_path / "named.jpg", (24, 16))
    assert j.subsampled and not p.subsampled
    assert np.array_equal(p.pixels, rgb)
