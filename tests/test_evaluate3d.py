"""The 3-D evaluation: which solve a scene gets, what it refuses, the detector's
measurements of a leaning mirror's images against their exact projection, and the
command end to end on ``scenes/raised.yaml``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mirrorsim.errors import BadParameter
from mirrorsim.pipelines.evaluate import evaluate_scene
from mirrorsim.pipelines.evaluate3d import CHI2_3_R95, geometry_of
from mirrorsim.pipelines.scenes import load_scene, scene_from_dict
from mirrorsim.scene.model import pencil_paint_height
from mirrorsim.scene.projection import project
from solver.errors import SolverError
from solver.selfcal import SelfCalibration
from tests.conftest import ROOT, SCENES, scene_dict, small_scene


def test_auto_solves_a_3d_scene_in_3d_and_a_planar_one_in_the_plane():
    raised, default = load_scene(SCENES / "raised.yaml"), load_scene(SCENES / "default.yaml")
    assert geometry_of(raised, "auto") == "3d" and geometry_of(default, "auto") == "planar"
    assert geometry_of(default, "3d") == "3d" and geometry_of(raised, "planar") == "planar"
    with pytest.raises(BadParameter, match="geometry"):
        geometry_of(raised, "2d")


def test_what_the_3d_solve_cannot_carry_is_refused():
    """One beacon and the target give six readings: the plane, the target and a free pan
    are seven unknowns.  With the beacon's plan offset (two more, with their prior's two
    rows) the 3-D solve refuses them in one line, as the count does; with the pan's
    prior it solves."""
    from solver.lsq3 import solve_lsq3

    o, b, t = np.array([0.0, 0.0, 8.0]), np.array([30.0, 50.0, 3.0]), (60.0, 2.0, 80.0)
    seen = (59.0, -1.0, 60.0)
    with pytest.raises(SolverError, match="unknowns"):
        solve_lsq3(o, [(b, seen)], [t], nuisances=("pan",), position_sigma=0.5)
    fit = solve_lsq3(o, [(b, seen)], [t], nuisances=("pan",), priors={"pan": 0.3},
                     position_sigma=0.5)
    assert np.all(np.isfinite(fit.target))


@pytest.fixture(scope="module")
def raised_report(tmp_path_factory):
    # full size: at half size the pencil's image is 9 px wide, and its roll undone moves
    # its axis by half a pixel (0.036°, where σ_α is 0.003°)
    scene = small_scene("raised", 1920, 1088)
    return scene, evaluate_scene(scene, tmp_path_factory.mktemp("raised"), progress=False,
                                 keep=())


@pytest.mark.slow
def test_the_board_pose_corrects_a_3d_scene_elevations_and_all(tmp_path):
    """scenes/raised.yaml on a mount that reads the pan 0.3° high, pitched 0.7° down and
    rolled 0.4°: plain, the pitch passes for a lean (every elevation 0.7° off, the target
    1.9 cm off when written); with ``board_pose`` the pose is measured and in the report,
    every elevation lies within 0.05° of what an exact detector reads at the true
    geometry (the truth's, computed apart from the detector), the pan's prior is the
    board's, and the target's error is under 1 cm and under half the plain one."""
    d = scene_dict("raised")
    d["camera"].update({"pan_error": 0.3, "pitch": -0.7, "roll": 0.4})
    d["render"] = {"spp": 8}
    scene = scene_from_dict(d, source="raised.yaml", default_name="raised")
    plain = evaluate_scene(scene, tmp_path / "run", progress=False, keep=())
    board = evaluate_scene(scene, tmp_path / "run", progress=False, keep=(), board_pose=True)
    pose = board.to_json()["camera_pose"]
    assert pose["pitch_deg"] == pytest.approx(-0.7, abs=0.02)
    assert pose["pan_offset_deg"] == pytest.approx(-0.3, abs=0.01)
    assert plain.to_json()["camera_pose"] is None
    # the pan is then the board's to know (its σ a few thousandths of a degree), not the
    # bench model's tolerance (1.5°/√3, widened by the model's shared α)
    priors = [r.to_json()["self_calibration"]["priors"]["pan"] for r in (plain, board)]
    assert priors[0] >= 1.5 / np.sqrt(3) and priors[1] < 0.01
    for report, near in ((plain, False), (board, True)):
        seen = report.seen
        off = [abs(got[1] - exact[1]) for got, exact in zip(
            [*(b for _, b in seen.beacons), seen.target], report.errors.exact_readings,
            strict=True)]
        assert (max(off) < 0.05) if near else (max(off) > 0.5)
    assert board.errors.target_cm < min(1.0, plain.errors.target_cm / 2)


@pytest.mark.slow
def test_each_image_of_a_leaning_mirror_is_measured_where_it_projects(raised_report):
    """The detector's foot and top (its roll undone) against the exact pinhole projection
    of the reflected foot and top, computed here from the scene's numbers."""
    from mirrorsim.pipelines.frame import render_and_measure

    scene, report = raised_report
    m = render_and_measure(scene, Path(report.frames[0].png).parent, progress=False,
                           reuse=True, ids=False)
    n = np.array([np.cos(np.radians(3)) * -np.sin(np.radians(20)),
                  np.cos(np.radians(3)) * np.cos(np.radians(20)), np.sin(np.radians(3))])
    if n[:2] @ (np.array([0.0, 0.0]) - [30, 62]) < 0:
        n[:2] *= -1
    rho = n @ np.array([30.0, 62.0, 0.0])
    for obj, h, im in [(scene.target, scene.target.size[1], m.detection.target),
                       (scene.beacons[0], pencil_paint_height(scene.beacons[0].height),
                        m.detection.beacons[0][1])]:
        foot, top = (p - 2 * (p @ n - rho) * n for p in (obj.base3, obj.base3 + [0, 0, h]))
        u, v, _ = project(scene.camera, np.array([foot, top]))
        assert any("roll" in note for note in im.notes)
        assert im.v_bottom == pytest.approx(v[0], abs=0.6)
        assert im.v_top == pytest.approx(v[1], abs=0.6)
    # and each reading within 4 of its σ's of what an exact detector reads
    seen = report.seen
    for got, exact, sig in zip([*(b for _, b in seen.beacons), seen.target],
                               report.errors.exact_readings, seen.sigma, strict=True):
        assert abs(got[0] - exact[0]) < 4 * sig[0]
        assert abs(got[1] - exact[1]) < 4 * sig[1]
        assert abs(got[2] - exact[2]) < 4 * sig[2] * exact[2]


@pytest.mark.slow
def test_the_3d_report_is_consistent_and_beats_the_planar_solve(raised_report):
    scene, report = raised_report
    e = report.errors
    assert report.fit.target.shape == (3,)
    # 0.48 cm until the calibration's reference pencil read its top within 0.03 px
    # (it read 0.04 px high): the pencil's K moved by 0.1 %, and this scene's beacon,
    # its image rolled by the lean, reads 0.4 % short (its σ: 0.24 %); 0.63 cm now
    assert e.target_cm < 0.7 and abs(e.mirror_lean_deg) < 0.3
    assert e.planar_target_cm > e.target_cm
    err = report.fit.target - np.r_[scene.target.position, scene.target.z]
    assert e.target_mahalanobis == pytest.approx(
        float(np.sqrt(err @ np.linalg.solve(report.fit.target_covariance, err))), rel=1e-9)
    assert e.inside95 == (e.target_mahalanobis <= CHI2_3_R95)
    doc = json.loads(json.dumps(report.to_json()))
    assert doc["geometry"] == "3d" and len(doc["solution"]["target_covariance"]) == 3
    assert doc["truth"]["mirror"]["lean_deg"] == 3.0
    assert len(doc["measurements"]["beacons"][0]["position"]) == 3
    # detect writes a 3-D capture's frame's measurements in 3-D: solve reads them
    frame = report.frames[0].png
    run = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "detect", frame,
                          "--capture", frame.replace(".png", ".capture.json"),
                          "--json", "-"], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    m3 = json.loads(run.stdout[run.stdout.index("{"):])
    assert len(m3["observer"]) == 3 and "elevation_deg" in m3["target"]
    assert m3["target"]["alpha_deg"] == pytest.approx(report.seen.target[0], abs=1e-9)
    # the table says what the solve took of the bench: an ideal bench's nothing; priors
    # and a position σ where it took them
    from dataclasses import replace

    from mirrorsim.cli.tables3d import report3_table

    assert "with their priors:" not in report3_table(report)
    taken = replace(report, self_calibration=SelfCalibration(("pan",), 0.29, {"pan": 0.5}))
    assert ("estimated with their priors: pan ±0.5°, beacon positions ±0.29 cm"
            in report3_table(taken))


@pytest.mark.slow
def test_evaluate_solves_the_bundled_3d_scene_at_full_size(tmp_path):
    out = tmp_path / "raised"
    run = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "evaluate",
                          str(SCENES / "raised.yaml"), "--out", str(out), "--quiet"],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "mirror lean (°)" in run.stdout and "95 % ellipsoid" in run.stdout
    doc = json.loads((out / "raised.report.json").read_text())
    e = doc["errors"]
    assert e["target_cm"] < 0.7 and abs(e["target_height_cm"]) < 0.3  # (see above)
    assert e["planar_target_cm"] > e["target_cm"]


@pytest.mark.parametrize("command", ["track"])
def test_commands_in_the_plane_refuse_a_3d_scene_in_one_line(tmp_path, command):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", command,
                          str(SCENES / "raised.yaml"), "--out", str(out)],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1].startswith(
        f"error: {SCENES / 'raised.yaml'}: mirror.lean: 3: {command} works in the board's")
    assert not out.exists()


def test_budget_of_a_3d_bench_is_solved_in_3d(tmp_path, capsys):
    """``budget`` of the bundled 3-D scene with a pan read 0.5° off and the calibration
    2 cm off (both act on beliefs: one render): solved in 3-D, each image's elevation
    delta beside its α's.  The pan moves every α by 0.5° and no elevation; the
    calibration every d_total by its K, no α and next to no elevation; the first-order
    prediction of
    each shift lands within 10 % of the solved one."""
    import yaml

    from mirrorsim.cli.main import main
    from tests.conftest import scene_dict

    d = scene_dict("raised")
    d["camera"] |= {"resolution": [960, 544], "pan_error": 0.5}
    d["calibration"] = {"distance_error": 2.0}
    path = tmp_path / "raised_bench.yaml"
    path.write_text(yaml.safe_dump(d))
    assert main(["budget", str(path), "--out", str(tmp_path / "b"), "--quiet",
                 "--json", str(tmp_path / "b.json")]) == 0
    assert "Δε_t (°)" in capsys.readouterr().out
    doc = json.loads((tmp_path / "b.json").read_text(), parse_constant=pytest.fail)
    assert doc["geometry"] == "3d"
    by = {s["source"]: s for s in doc["sources"]}
    pan, cal = by["camera.pan_error"], by["calibration.distance_error"]
    assert pan["delta"]["target_alpha_deg"] == pytest.approx(0.5, abs=1e-9)
    assert pan["delta"]["beacon_alpha_deg"] == [pytest.approx(0.5, abs=1e-9)]
    assert pan["delta"]["target_elevation_deg"] == pytest.approx(0.0, abs=1e-9)
    assert cal["delta"]["target_alpha_deg"] == pytest.approx(0.0, abs=1e-9)
    # (an elevation takes the d_total into its face's offset from the axis: 0.0004°)
    assert cal["delta"]["beacon_elevation_deg"] == [pytest.approx(0.0, abs=1e-3)]
    assert abs(cal["delta"]["target_d_total_pct"]) > 0.5
    for c in (pan, cal):
        assert c["predicted_shift_cm"] == pytest.approx(c["shift_cm"], rel=0.1)
        assert c["shift_cm"] > 0.1


def test_plan_of_a_3d_scene_chooses_each_beacons_post():
    """``plan`` of the bundled 3-D scene: each position (the scene's beacon's, the best)
    gets the posts 0-15 cm its image shows whole, and the best's bound is the least.  The
    bound holds against the 3-D solve itself: 300 draws of exact readings (measured3)
    plus Gaussian noise of those σ's, solved, scatter the target by an RMS within 12 % of
    it.  Under a glass 9 cm tall, the posts that would lift the pencil's image off the
    glass are left out."""
    import math

    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines.planning import plan_scene
    from mirrorsim.pipelines.scenes import edit_scene
    from mirrorsim.scene.model import FRONT_OFFSET
    from mirrorsim.truth import optics
    from solver.lsq3 import solve_lsq3
    from solver.sltr3d import measured3

    scene = load_scene(SCENES / "raised.yaml")
    sigma = default_error_model().typical
    plan = plan_scene(scene, sigma, n_poses=3, step=2.0)
    assert [h.position for h in plan.heights] == [tuple(scene.beacons[0].position),
                                                   tuple(plan.best.position)]
    first = plan.heights[0]
    assert first.heights == tuple(float(z) for z in range(16))
    z, bound = first.best
    assert bound == min(first.rmse)
    assert plan.to_json()["beacon_heights"][0]["best_height"] == z
    # the bound against the solve, at the best post
    cam, plane = scene.camera, optics.mirror_plane(scene.camera, scene.mirror)
    base = np.array([*scene.beacons[0].position, z])
    heights = (pencil_paint_height(scene.beacons[0].height), scene.target.size[1])
    fronts = (FRONT_OFFSET["beacon"], FRONT_OFFSET["target"])
    exact = [measured3(cam.center3, plane, p, height=h, front=f, pan_deg=cam.pan_deg)
             for p, h, f in zip((base, scene.target.base3), heights, fronts, strict=True)]
    t, b = sigma.target, sigma.beacons[0]
    sig = np.array([(b.alpha_deg, b.alpha_deg, b.d_total_rel),
                    (t.alpha_deg, t.alpha_deg, t.d_total_rel)])
    rng = np.random.default_rng(7)
    errs = []
    for _ in range(300):
        seen = [(a + rng.normal(0, sa), e + rng.normal(0, se), d * (1 + rng.normal(0, sd)))
                for (a, e, d), (sa, se, sd) in zip(exact, sig, strict=True)]
        fit = solve_lsq3(cam.center3, [(base, seen[0])], [seen[1]], sigma=sig,
                         heights=heights, fronts=fronts, pan_deg=cam.pan_deg)
        errs.append(fit.target - scene.target.base3)
    rms = math.sqrt(np.mean(np.sum(np.square(errs), axis=1)))
    assert rms == pytest.approx(bound, rel=0.12)
    low = plan_scene(edit_scene(scene, {"mirror": {"size": [24, 9]}}), sigma, n_poses=3,
                     step=2.0)
    assert 0 < len(low.heights[0].heights) < 16


def test_a_3d_budget_refuses_a_calibration_its_beacons_cannot_carry():
    """One beacon in 3-D: 6 readings (α, elevation, d_total of the beacon's image and of
    the target's) against the plane's 3 unknowns, the target's 3 and a free pan: refused
    in one line naming the counts (before anything is rendered); with a prior on the pan,
    the prior's row carries it."""
    from mirrorsim.pipelines.budget import check_budget_calibration

    scene = load_scene(SCENES / "raised.yaml")
    with pytest.raises(BadParameter, match="at least 2 beacon observations \\(1 given\\): each "
                       "image gives 3 measurements.*7 unknowns"):
        check_budget_calibration(scene, SelfCalibration(("pan",)))
    held = SelfCalibration(("pan",), priors={"pan": 0.5})
    assert check_budget_calibration(scene, held) == held


LEANING_TARGET = np.array([57.0, 50.0, 6.0])


def _leaning_readings(pan_error_deg: float = 0.0, pitch_error_deg: float = 0.0) -> dict:
    """A 3-D measurements document: the exact readings (measured3) of a mirror leaning
    2.5° from a camera 9 cm up, two beacons and LEANING_TARGET, every azimuth turned by
    ``pan_error_deg`` and every elevation by ``pitch_error_deg``."""
    from solver.sltr3d import MirrorPlane, measured3

    cam = np.array([0.0, 0.0, 9.0])
    plane = MirrorPlane.from_pose([35.0, 62.0, 0.0], 18.0, 2.5, toward=cam)
    beacons = [np.array([33.0, 53.0, 4.0]), np.array([42.0, 56.0, 0.0])]
    heights, fronts = (4.8, 4.8, 10.0), (0.338, 0.338, 0.2)
    read = [measured3(cam, plane, p, height=h, front=f)
            for p, h, f in zip([*beacons, LEANING_TARGET], heights, fronts, strict=True)]

    def image(s):
        return {"alpha_deg": s[0] + pan_error_deg, "elevation_deg": s[1] + pitch_error_deg,
                "d_total": s[2]}

    return {"observer": cam.tolist(), "target": image(read[2]),
            "beacons": [{"position": b.tolist(), **image(s)}
                        for b, s in zip(beacons, read, strict=False)],
            "heights": list(heights), "fronts": list(fronts)}


def test_solve_takes_3d_measurements(tmp_path):
    """A measurement file with an observer's height and elevations is solved in 3-D: the
    exact readings of a leaning mirror (written out here with measured3) give back its
    plane and the target."""
    doc, target = _leaning_readings(), LEANING_TARGET
    f = tmp_path / "m3.json"
    f.write_text(json.dumps(doc))
    run = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "solve", str(f),
                          "--json", "-"], cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    sol = json.loads(run.stdout[run.stdout.index("{"):])
    np.testing.assert_allclose(sol["target"], target, atol=1e-5)
    assert sol["mirror"]["lean_deg"] == pytest.approx(2.5, abs=1e-6)
    assert len(sol["target_covariance"]) == 3
    doc["beacons"][0]["elevation_deg"] = 95
    f.write_text(json.dumps(doc))
    bad = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "solve", str(f)],
                         cwd=ROOT, capture_output=True, text=True)
    assert bad.returncode == 2 and "beacons[0].elevation_deg" in bad.stderr


def test_the_3d_solve_takes_what_the_user_asks_of_pan_and_scale():
    """What the 3-D solve estimates (nuisances3): nothing on an ideal bench asked
    nothing; the pan and scale asked, a stated prior winning over the bench model's
    (σ = half-width/√3 of its tolerances: pan 1.5°, scale 3 cm in 100, power
    0.00143/cm), a pan asked without a prior left free; and a shared α error widening
    the pan's prior."""
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines.evaluate3d import nuisances3
    from solver.measurements import ObjectSigmas, Sigma

    ideal, bench = default_error_model("ideal"), default_error_model("bench")
    sig = ObjectSigmas(Sigma(0.01, 0.005), (Sigma(0.01, 0.005),))

    def taken(*args):
        cal = nuisances3(*args)[0]
        return cal.nuisances, cal.priors, cal.position_sigma

    assert taken(ideal, sig) == ((), {}, 0.0)
    assert taken(ideal, sig, SelfCalibration(("pan", "scale"), 0.2, {"scale": 0.01})) \
        == (("pan", "scale"), {"scale": 0.01}, 0.2)
    names, priors, position = taken(bench, sig, SelfCalibration(("scale",),
                                                                priors={"scale": 0.002}))
    assert names == ("scale", "pan", "power")  # the model's tolerances: 1/R to 0.00143/cm
    assert priors == pytest.approx({"scale": 0.002, "pan": 1.5 / np.sqrt(3),
                                    "power": 0.00143 / np.sqrt(3)})
    # and the beacons' believed positions, to the tolerance's σ (a stated one wins)
    assert position == pytest.approx(bench.tolerances.beacon_position_cm / np.sqrt(3))
    assert taken(bench, sig, SelfCalibration((), 0.05))[2] == 0.05
    shared = ObjectSigmas(sig.target, sig.beacons, shared_alpha_deg=0.2)
    assert taken(ideal, shared)[:2] == (("pan",), {"pan": pytest.approx(0.2)})
    assert taken(ideal, shared, SelfCalibration(("pan",)))[:2] == (("pan",), {})


def test_solve_calibrates_3d_measurements_on_the_command_line(tmp_path):
    """Exact readings of a leaning mirror with every azimuth turned by a 0.4° pan error:
    plain, the target comes out off; with --calibrate pan it comes back to 1e-5 cm and the
    pan to 1e-6°; with the beacons' positions known to 0.5 cm, to 1e-4 cm."""
    target = LEANING_TARGET
    f = tmp_path / "m3.json"
    f.write_text(json.dumps(_leaning_readings(pan_error_deg=0.4)))

    def solve(*extra):
        return subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "solve", str(f),
                               *extra], cwd=ROOT, capture_output=True, text=True)

    def target_of(run):
        assert run.returncode == 0, run.stderr
        return json.loads(run.stdout[run.stdout.index("{"):])

    plain = target_of(solve("--json", "-"))
    assert np.linalg.norm(np.array(plain["target"]) - target) > 0.05
    cal = target_of(solve("--calibrate", "pan", "--json", "-"))
    np.testing.assert_allclose(cal["target"], target, atol=1e-5)
    assert cal["nuisances"]["pan"] == pytest.approx(0.4, abs=1e-6)
    # the beacons' positions known to 0.5 cm: estimated (exact readings: still exact),
    # and the target's ellipsoid wider for it
    run = solve("--calibrate", "pan", "--beacon-sigma", "0.5", "--json", "-")
    loose = target_of(run)
    np.testing.assert_allclose(loose["target"], target, atol=1e-4)
    assert np.trace(loose["target_covariance"]) > np.trace(cal["target_covariance"])
    assert "barely locate" not in run.stderr
    # positions known to 10 cm and every nuisance estimated under a loose prior: the fit
    # is held by its priors, its ellipsoid wider than a tenth of the target's distance,
    # and one warning says so
    run = solve("--calibrate", "pan,pitch,scale,power", "--prior",
                "pan=5,pitch=5,scale=0.5,power=0.01", "--beacon-sigma", "10", "--json", "-")
    rms = np.sqrt(np.trace(target_of(run)["target_covariance"]))
    far = np.linalg.norm(np.array(target) - np.array(_leaning_readings()["observer"]))
    assert rms > 0.1 * far
    assert run.stderr.count("warning: the measurements barely locate the target") == 1


def test_solve_calibrates_the_pitch_of_3d_measurements_and_a_planar_solve_refuses_it(
        tmp_path):
    """Exact readings with every elevation raised 0.3° (a mount's pitch reading): plain,
    the target comes out off; with --calibrate pitch it comes back to 1e-5 cm and the
    pitch to 1e-6°, and with pan, pitch and scale on the two beacons to 1e-4 cm.  A
    planar solve (the same beacons' α and d_total alone), a planar scene's evaluation
    and its plan refuse the pitch in one line, exit 2, before any folder, and so does a
    3-D evaluation with the board's pose (which measures the pitch).  The estimate is
    printed with its σ; a bench model's σ's bring its shared errors' priors."""
    from solver.lsq import solve_measurements
    from solver.measurements import BeaconMeasurement

    f = tmp_path / "m3.json"
    f.write_text(json.dumps(_leaning_readings(pitch_error_deg=0.3)))

    def solve(path, *extra):
        return subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "solve", str(path),
                               *extra], cwd=ROOT, capture_output=True, text=True)

    def target_of(run):
        assert run.returncode == 0, run.stderr
        return json.loads(run.stdout[run.stdout.index("{"):])

    plain = target_of(solve(f, "--json", "-"))
    assert np.linalg.norm(np.array(plain["target"]) - LEANING_TARGET) > 0.05
    run = solve(f, "--calibrate", "pitch", "--json", "-")
    cal = target_of(run)
    np.testing.assert_allclose(cal["target"], LEANING_TARGET, atol=1e-5)
    assert cal["nuisances"]["pitch"] == pytest.approx(0.3, abs=1e-6)
    assert cal["nuisance_sd"]["pitch"] > 0 and "pitch offset 0.3000°" in run.stderr
    # a bench model's σ's bring its shared errors with their priors, as in the plane
    bench = target_of(solve(f, "--error-model", "mirrorsim/data/error_model_bench.json",
                            "--json", "-"))
    assert set(bench["nuisances"]) == {"pan", "scale", "power"}
    # three nuisances on two beacons: 3-D images give three readings each (9 for 9)
    three = target_of(solve(f, "--calibrate", "pan,pitch,scale", "--json", "-"))
    np.testing.assert_allclose(three["target"], LEANING_TARGET, atol=1e-4)
    beacons = [BeaconMeasurement((30.0, 50.0), 60.0, 80.0),
               BeaconMeasurement((40.0, 55.0), 55.0, 90.0)]
    with pytest.raises(SolverError, match="pitch"):
        solve_measurements((0.0, 0.0), beacons, [(58.0, 100.0)],
                           calibration=SelfCalibration(("pan", "pitch")))
    out = tmp_path / "out"
    with pytest.raises(BadParameter, match="pitch"):
        evaluate_scene(load_scene(SCENES / "default.yaml"), out,
                       calibration=SelfCalibration(("pitch",), priors={"pitch": 0.5}))
    assert not out.exists()
    bad = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "evaluate",
                          str(SCENES / "default.yaml"), "--calibrate", "pitch", "--prior",
                          "pitch=0.5", "--out", str(out)], cwd=ROOT, capture_output=True,
                         text=True)
    assert bad.returncode == 2 and "pitch" in bad.stderr and not out.exists()
    assert len(bad.stderr.strip().splitlines()) == 1
    alone = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "evaluate",
                            str(SCENES / "default.yaml"), "--calibrate", "pitch", "--out",
                            str(out)], cwd=ROOT, capture_output=True, text=True)
    assert alone.returncode == 2 and "planar solve does not read" in alone.stderr  # not a count
    posed = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "evaluate",
                            str(SCENES / "raised.yaml"), "--calibrate", "pitch", "--prior",
                            "pitch=0.5", "--board-pose", "--out", str(out)], cwd=ROOT,
                           capture_output=True, text=True)
    assert posed.returncode == 2 and "board" in posed.stderr and not out.exists()
    plan = subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "plan",
                           str(SCENES / "exp3.yaml"), "--calibrate", "pitch", "--prior",
                           "pitch=0.5"], cwd=ROOT, capture_output=True, text=True)
    assert plan.returncode == 2 and len(plan.stderr.strip().splitlines()) == 1
    assert "--calibrate" in plan.stderr and "pitch" in plan.stderr


def test_a_3d_capture_record_reads_back_as_written():
    from mirrorsim.formats.capture import CaptureRecord

    rec = CaptureRecord.from_scene(load_scene(SCENES / "raised.yaml"))
    doc = json.loads(json.dumps(rec.to_json()))
    assert doc["geometry"] == "3d" and doc["beacons"][0]["position"] == [36.0, 56.0, 2.0]
    back = CaptureRecord.from_json(doc)
    assert back.geometry == "3d" and back.beacons[0].z == 2.0
    assert "geometry" not in CaptureRecord.from_scene(load_scene(SCENES / "default.yaml")).to_json()


@pytest.mark.slow
def test_a_3d_scene_solved_in_the_plane_is_scored_in_plan(raised_report, tmp_path):
    scene, report3 = raised_report
    planar = evaluate_scene(scene, tmp_path / "planar", progress=False, keep=(),
                            geometry="planar")
    t = planar.truth.target
    assert len(t.position) == 2 and t.elevation_deg is None
    elev = report3.truth.target.elevation_deg
    assert t.d_total == pytest.approx(report3.truth.target.d_total * np.cos(np.radians(elev)),
                                      abs=1e-8)
    # the same frames: its error is the 3-D report's planar solve's
    assert planar.errors.target_cm == pytest.approx(report3.errors.planar_target_cm, abs=1e-9)


def test_a_3d_model_weighs_the_3d_solve_with_its_own_laws():
    """With a 3-D model's elevation σ's the solve takes its σ's as they are; a planar
    model's are widened by SIGMA3_FACTORS, the elevation's from the d_total's (one edge
    of two: σ_d·s/(√2 f))."""
    import math

    from mirrorsim.pipelines.evaluate3d import SIGMA3_FACTORS, sigma3
    from solver.measurements import Sigma

    s = [Sigma(0.002, 0.001), Sigma(0.003, 0.002)]  # a beacon's, the target's
    own = sigma3(s, [100.0, 200.0], fx=1500.0, elevations=(0.004, 0.009))
    assert own == [(0.002, 0.004, 0.001), (0.003, 0.009, 0.002)]
    fb, ft = SIGMA3_FACTORS["beacon"], SIGMA3_FACTORS["target"]
    wide = sigma3(s, [100.0, 200.0], fx=1500.0, elevations=None)
    assert wide[0] == pytest.approx((0.002 * fb[0], fb[1] * math.degrees(
        0.001 * 100 / math.sqrt(2) / 1500), 0.001 * fb[2]))
    assert wide[1][0] == pytest.approx(0.003 * ft[0])


def test_solve_takes_a_3d_model_s_elevation_sigma_and_its_ellipsoid(tmp_path):
    """3-D measurements solved with a 3-D model (fitted here on synthetic rows, its
    ellipsoid scale set to 2): its typical elevation σ's, not the azimuth's, and a
    covariance four times the unscaled one's."""
    from dataclasses import replace

    from mirrorsim.pipelines import errormodel
    from tests.conftest import synthetic_columns

    n = 400
    rng = np.random.default_rng(2)
    cols = synthetic_columns(n, 1, geometry=["3d"] * n,
                             target_elevation_err=rng.normal(0, 0.01, n),
                             beacon_elevation_err=rng.normal(0, 0.004, n))
    model = errormodel.fit(cols)
    f = tmp_path / "m3.json"
    f.write_text(json.dumps(_leaning_readings(pan_error_deg=0.0)))
    runs = []
    for scale in (1.0, 2.0):
        path = tmp_path / f"model{scale:g}.json"
        errormodel.write_model(replace(model, ellipsoid_scale=scale), path)
        runs.append(subprocess.run([sys.executable, "-m", "mirrorsim.cli.main", "solve",
                                    str(f), "--error-model", str(path), "--json", "-"],
                                   cwd=ROOT, capture_output=True, text=True))
    for run in runs:
        assert run.returncode == 0, run.stderr
        assert "typical σ's" in run.stderr and "azimuth" not in run.stderr
    cov = [np.array(json.loads(r.stdout[r.stdout.index("{"):])["target_covariance"])
           for r in runs]
    np.testing.assert_allclose(cov[1], 4 * cov[0], rtol=1e-9)
