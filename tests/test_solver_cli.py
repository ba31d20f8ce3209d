"""Monte Carlo, the solver's boundaries, and the solve / montecarlo / plan commands."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mirrorsim.cli.main import main
from mirrorsim.pipelines.scenes import load_scene
from mirrorsim.truth import optics
from solver.geometry import reflect
from solver.montecarlo import PAPER_TABLE1, Table1Geometry, run_row, table1
from solver.placement import MirrorPrior
from solver.sltr import closed_form_unchecked, observe, solve_single

from .conftest import SCENES


def _single(x) -> dict:
    """The one-beacon solution's four measurements (beacon α, d; target α, d) by name."""
    return dict(zip(("beacon_alpha_deg", "beacon_d_total", "target_alpha_deg",
                     "target_d_total"), map(float, x), strict=True))


def test_solver_imports_neither_mirrorsim_mitsuba_nor_opencv():
    code = ("import sys, solver.sltr, solver.placement, solver.particle, solver.particle_runs, "
            "solver.montecarlo, solver.montecarlo3, "
            "solver.measurements; bad = [m for m in ('mirrorsim', 'mitsuba', 'drjit', 'cv2') "
            "if m in sys.modules]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _first_order_target_rmse(g, sigma_alpha, sigma_d) -> float:
    """RMS target error predicted by linearizing the exact one-beacon solution with
    central differences (independent of run_row's vectorized closed form)."""
    lay = g.layout()
    x0 = np.array([lay.beacon_alpha, lay.beacon_d, lay.target_alpha, lay.target_d])
    h = np.array([1e-5, 1e-6, 1e-5, 1e-6])
    J = np.empty((2, 4))
    for k in range(4):
        hi, lo = x0.copy(), x0.copy()
        hi[k] += h[k]
        lo[k] -= h[k]
        J[:, k] = (solve_single(np.zeros(2), lay.beacon, **_single(hi)).target
                   - solve_single(np.zeros(2), lay.beacon, **_single(lo)).target) / (2 * h[k])
    sd = np.array([sigma_alpha, sigma_d, sigma_alpha, sigma_d])
    return float(np.sqrt(np.trace(J @ np.diag(sd**2) @ J.T)))


def test_montecarlo_rmse_matches_first_order_prediction():
    """At small noise the Monte Carlo RMSE is the linearized one (within sampling error:
    4000 draws give ≈ 2 % on an RMS); noise-free draws recover the target exactly."""
    g = Table1Geometry()
    for sa, sd in [(0.02, 0.002), (0.05, 0.001)]:
        predicted = _first_order_target_rmse(g, sa, sd)
        row = run_row(sa, sd, 4000, geometry=g, rng=3)
        assert row.failed == 0
        assert row.rmse_tar == pytest.approx(predicted, rel=0.06)
    assert run_row(0.0, 0.0, 10).rmse_tar < 1e-9
    # a beacon further from the mirror conditions the problem better: prediction and
    # simulation agree on it
    near, far = Table1Geometry(beacon_depth=0.3), Table1Geometry(beacon_depth=1.5)
    assert _first_order_target_rmse(far, 0.05, 0.002) < _first_order_target_rmse(near, 0.05, 0.002)
    assert run_row(0.05, 0.002, 2000, geometry=far, rng=2).rmse_tar < run_row(
        0.05, 0.002, 2000, geometry=near, rng=2).rmse_tar


def test_montecarlo_table_is_seeded_and_keeps_the_paper_columns():
    a, b, c = table1(200, rng=4), table1(200, rng=4), table1(200, rng=5)
    assert a == b and a != c
    assert [(r.sigma_alpha_deg, r.sigma_d, r.paper_rmse_ref, r.paper_rmse_tar)
            for r in a.rows] == [tuple(p) for p in PAPER_TABLE1]


def test_closed_form_unchecked_agrees_with_solve_single():
    """Monte Carlo's unchecked batch arithmetic is the checked closed form's."""
    g = Table1Geometry().layout()
    rng = np.random.default_rng(0)
    ab = g.beacon_alpha + rng.normal(0, 0.5, 50)
    db = g.beacon_d + rng.normal(0, 0.02, 50)
    at = g.target_alpha + rng.normal(0, 0.5, 50)
    dt = g.target_d + rng.normal(0, 0.02, 50)
    batch = closed_form_unchecked(np.zeros(2), g.beacon, ab, beacon_d_total=db,
                                  target_alpha_deg=at, target_d_total=dt)
    for k in range(50):
        one = solve_single(np.zeros(2), g.beacon, ab[k], beacon_d_total=db[k],
                           target_alpha_deg=at[k], target_d_total=dt[k])
        assert np.allclose(batch.target[k], one.target, atol=1e-12)
        assert np.allclose(batch.target_reflection_point[k], one.target_reflection_point,
                           atol=1e-12)
        assert abs(batch.yaw_deg[k] - one.mirror.yaw_deg) < 1e-10


def test_solve_exact_measurements_of_exp1(tmp_path):
    meas = tmp_path / "m.json"
    assert main(["check", str(SCENES / "exp1.yaml"), "--measurements", str(meas)]) == 0
    out = tmp_path / "sol.json"
    assert main(["solve", str(meas), "--json", str(out)]) == 0
    sol = json.loads(out.read_text())
    assert np.allclose(sol["target"]["position"], [55, 70], atol=1e-6)
    assert sol["mirror"]["yaw_deg"] == pytest.approx(38.0, abs=1e-6)


def test_solve_with_sigma_reports_covariance(tmp_path, capsys):
    meas = tmp_path / "m.json"
    main(["check", str(SCENES / "exp3.yaml"), "--measurements", str(meas)])
    d = json.loads(meas.read_text())
    d["sigma"] = {"alpha_deg": 0.01, "d_total_rel": 0.002}
    meas.write_text(json.dumps(d))
    assert main(["solve", str(meas), "--json", "-"]) == 0
    printed = capsys.readouterr().out
    sol = json.loads(printed[printed.index("{"):])
    cov = np.array(sol["covariance"]["target"])
    assert np.sqrt(np.trace(cov)) == pytest.approx(2.4, abs=0.1)  # EXP3's figure, fixed in advance


def test_paper_table3_inputs_do_not_reproduce_its_outputs(capsys):
    """Exact geometry on the paper's own measured α, d_total of EXP1 gives a target
    ≈ 20 cm from the true one; the paper reports (52, 65), 5.8 cm off."""
    assert main(["solve", str(SCENES / "measurements" / "exp1_paper.json"), "--json", "-"]) == 0
    printed = capsys.readouterr().out
    sol = json.loads(printed[printed.index("{"):])
    t = np.array(sol["target"]["position"])
    assert np.linalg.norm(t - [55, 70]) > 15
    assert np.linalg.norm(t - [52, 65]) > 10


@pytest.mark.parametrize("content, key", [
    ("{", "malformed JSON"),
    ('{"observer": [0, 0], "target": {"alpha_deg": 60, "d_total": -1}, "beacons": '
     '[{"position": [1, 2], "alpha_deg": 60, "d_total": 50}]}', "target.d_total"),
    ('{"observer": [0, 0], "target": {"alpha_deg": 60, "d_total": 90}, "beacons": []}',
     "beacons"),
    ('{"observer": [0], "target": {"alpha_deg": 60, "d_total": 90}, "beacons": '
     '[{"position": [1, 2], "alpha_deg": 60, "d_total": 50}]}', "observer"),
    ('{"observer": [0, 0], "target": {"alpha_deg": "x", "d_total": 90}, "beacons": '
     '[{"position": [1, 2], "alpha_deg": 60, "d_total": 50}]}', "target.alpha_deg"),
    # a d_total no bench has overflowed the solver; a key given twice was read as its last
    ('{"observer": [0, 0], "target": {"alpha_deg": 60, "d_total": 90}, "beacons": '
     '[{"position": [1, 2], "alpha_deg": 60, "d_total": 1e300}]}', "beacons[0].d_total"),
    ('{"observer": [0, 0], "target": {"alpha_deg": 60, "d_total": 90}, "beacons": '
     '[{"position": [1, 2], "alpha_deg": 60, "d_total": 50}], "observer": [5, 5]}',
     "observer: given twice"),
])
def test_bad_measurements_exit_2(tmp_path, capsys, content, key):
    f = tmp_path / "bad.json"
    f.write_text(content)
    assert main(["solve", str(f)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and key in err[0] and str(f) in err[0]


def test_unsolvable_measurements_exit_1(tmp_path, capsys):
    f = tmp_path / "m.json"
    # the beacon's image would sit on the beacon itself
    f.write_text(json.dumps({"observer": [0, 0], "target": {"alpha_deg": 60, "d_total": 90},
                             "beacons": [{"position": [30, 40], "alpha_deg": 53.13010235415598,
                                          "d_total": 50.0}]}))
    assert main(["solve", str(f)]) == 1
    assert "cannot solve" in capsys.readouterr().err


def test_montecarlo_command(capsys):
    """Noise-free draws recover the truth exactly; small noise gives the RMSE that
    first-order propagation through the checked closed form predicts (an oracle apart
    from the Monte Carlo's batch arithmetic); the JSON is strict (paper columns null)."""
    sa, sd = 0.05, 0.005  # σ_d absolute at d_total 5: --sigma takes it in % of d_total
    assert main(["montecarlo", "--sigma", "0", "0", "--sigma", str(sa), str(100 * sd / 5.0),
                 "--iterations", "4000", "--seed", "9", "--json", "-"]) == 0
    out = capsys.readouterr().out
    res = json.loads(out[out.index("{"):])
    r0, r1 = res["rows"]
    assert r0["rmse_tar"] < 1e-9 and r0["paper_rmse_tar"] is None
    g = Table1Geometry().layout()
    x0 = np.array([g.beacon_alpha, g.beacon_d, g.target_alpha, g.target_d])

    def target(x):
        return solve_single(np.zeros(2), g.beacon, **_single(x)).target

    J = np.column_stack([(target(x0 + h * e) - target(x0 - h * e)) / (2 * h)
                         for e, h in zip(np.eye(4), (1e-5, 1e-6, 1e-5, 1e-6), strict=True)])
    # --sigma's σ_d is relative: each object's absolute σ_d is it times its own d_total
    rel = sd / 5.0
    cov = J @ np.diag([sa**2, (rel * g.beacon_d)**2, sa**2, (rel * g.target_d)**2]) @ J.T
    # 4000 draws: the RMSE's own sampling error is ~1.1 %
    assert r1["rmse_tar"] == pytest.approx(np.sqrt(np.trace(cov)), rel=0.05)
    assert main(["montecarlo", "--iterations", "1"]) == 2


def test_plan_command(tmp_path):
    """The plan's expected error at its best position against a Monte Carlo of the
    closed form over the same mirror poses (sampling, not the plan's first-order
    algebra); the best position beats the scene's own beacon tenfold on exp3."""
    png = tmp_path / "plan.png"
    js = tmp_path / "plan.json"
    assert main(["plan", str(SCENES / "exp3.yaml"), "--out", str(png), "--json", str(js)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    p = json.loads(js.read_text())
    assert p["best_beacon"]["rmse"] < 0.1 * p["scene_beacon"]["rmse"]
    assert p["path_lengths"]["rectangular"] < p["path_lengths"]["linear"]

    scene = load_scene(SCENES / "exp3.yaml")
    o = np.asarray(scene.camera.position, float)
    ta, td = p["target"]["alpha_deg"], p["target"]["d_total"]
    img = optics.mirror_image(o, scene.mirror, scene.target.position)
    poses = MirrorPrior(d1=img.d1, yaw_deg=scene.mirror.yaw, d1_spread=2.0,
                        yaw_spread_deg=3.0, n=5).poses(o, ta)
    beacon = np.asarray(p["best_beacon"]["position"])
    # the default: the shipped error model's typical σ's, the target's and the beacon's
    ts, bs = p["sigma"]["target"], p["sigma"]["beacons"]  # one pair for every beacon
    rng = np.random.default_rng(11)
    sq, k = [], 2000
    for point, yaw in poses:
        b = observe(o, point, yaw, point=beacon)
        virtual = o + td * np.array([np.cos(np.radians(ta)), np.sin(np.radians(ta))])
        target = reflect(virtual, point, yaw)  # the target this pose implies
        est = solve_single(o, beacon, b.alpha_deg + rng.normal(0, bs["alpha_deg"], k),
                           beacon_d_total=b.d_total * (1 + rng.normal(0, bs["d_total_rel"], k)),
                           target_alpha_deg=ta + rng.normal(0, ts["alpha_deg"], k),
                           target_d_total=td * (1 + rng.normal(0, ts["d_total_rel"], k)))
        sq.append(np.mean(np.sum((est.target - target) ** 2, axis=1)))
    assert p["best_beacon"]["rmse"] == pytest.approx(np.sqrt(np.mean(sq)), rel=0.05)


def test_json_to_stdout_pipes_alone(tmp_path, capsys):
    """`--json -` leaves stdout to the JSON (it pipes into jq); the table goes to stderr."""
    meas = tmp_path / "m.json"
    for argv in (["check", str(SCENES / "exp1.yaml"), "--measurements", str(meas), "--json",
                  "-"],
                 ["solve", str(meas), "--json", "-"],
                 ["montecarlo", "--iterations", "20", "--json", "-"]):
        assert main(argv) == 0
        out, err = capsys.readouterr()
        assert isinstance(json.loads(out), dict) and err.strip()
    # another JSON output given as - pipes alike; two outputs to stdout are refused
    assert main(["check", str(SCENES / "exp1.yaml"), "--measurements", "-"]) == 0
    out, err = capsys.readouterr()
    assert "beacons" in json.loads(out) and err.strip()
    assert main(["check", str(SCENES / "exp1.yaml"), "--measurements", "-", "--json",
                 "-"]) == 2
    out, err = capsys.readouterr()
    assert not out and "--json writes to already" in err


def test_an_input_inside_the_runs_own_output_folder_is_refused(tmp_path, capsys):
    """A scene put into a folder mirrorsim marked as its own was overwritten by the
    run's file of the same name (evaluate writes <name>.json there)."""
    import shutil

    from mirrorsim.formats.files import claim_output_folder

    out = claim_output_folder(tmp_path / "o", "--out")
    scene = out / "exp1.json"
    shutil.copy(SCENES / "exp1.yaml", scene)
    before = scene.read_bytes()
    assert main(["evaluate", str(scene), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "holds this run's input SCENE" in err[-1], err
    assert scene.read_bytes() == before and sorted(p.name for p in out.iterdir()) == sorted(
        [scene.name, *(p.name for p in out.iterdir() if p.name.startswith("."))])


def test_track_refuses_a_beacon_sigma_it_would_not_use(tmp_path, capsys):
    """exp1's one beacon is the moving one: --beacon-sigma (for fixed beacons) would
    change nothing, and was silently ignored."""
    argv = ["track", str(SCENES / "exp1.yaml"), "--beacon-sigma", "0.5", "--out",
            str(tmp_path / "t"), "--quiet"]
    assert main(argv) == 2
    assert "no fixed beacon" in capsys.readouterr().err
    assert not (tmp_path / "t").exists()


def test_review_mends_of_the_sweeps(tmp_path, capsys):
    """A budget's lone --beacon-sigma names --calibrate; a dataset's settings digest
    takes numpy numbers; a folder output named - is not stdout; a scene made in memory
    has no file to be found inside an output folder; derived frame names may pass 64."""
    import argparse
    from dataclasses import replace

    import numpy as np

    from mirrorsim.cli.outputs import stdout_output
    from mirrorsim.formats.dataset_folder import settings_digest
    from mirrorsim.formats.files import check_inputs_outside
    from mirrorsim.pipelines.scenes import load_scene

    assert main(["budget", str(SCENES / "exp1.yaml"), "--beacon-sigma", "0.1", "--out",
                 str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: --calibrate:") and not (tmp_path / "b").exists(), err
    assert settings_digest({"seed": np.int64(5), "spp": np.int32(4)}) == \
        settings_digest({"seed": 5, "spp": 4})
    ns = argparse.Namespace(out="-", json=None, outputs=[("out", "--out", "dir"),
                                                         ("json", "--json", "file")])
    assert stdout_output(ns) is None
    ns.json = "-"
    assert stdout_output(ns) == "--json"
    # "<scene>" names no file: the folder holding the working directory, where that name
    # would resolve, does not refuse it
    check_inputs_outside(Path.cwd(), [("scene", "<scene>")], "out")
    scene = load_scene(SCENES / "exp1.yaml")
    assert replace(scene, name="a" * 64 + "_pose000").name.endswith("_pose000")


def test_solve_reads_measurements_from_a_pipe(tmp_path):
    """`check --measurements - | solve -`: the measurements from stdin (it said
    `-: no such file`), solved as from a file; a binary file given for the JSON is one
    line saying so (it quoted the UTF-8 codec)."""
    check = subprocess.run([sys.executable, "-m", "mirrorsim", "check",
                            str(SCENES / "exp1.yaml"), "--measurements", "-"],
                           capture_output=True, text=True, check=True)
    piped = subprocess.run([sys.executable, "-m", "mirrorsim", "solve", "-", "--json", "-"],
                           input=check.stdout, capture_output=True, text=True)
    assert piped.returncode == 0, piped.stderr
    assert json.loads(piped.stdout)["target"]["position"] == pytest.approx([55.0, 70.0], abs=1e-6)
    binary = tmp_path / "table.parquet"
    binary.write_bytes(b"PAR1\xa0\xff\x00" * 20)
    bad = subprocess.run([sys.executable, "-m", "mirrorsim", "solve", str(binary)],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert str(binary) in bad.stderr and "not UTF-8 text" in bad.stderr
    # the same bytes piped (the locale's decoding let them through as escapes)
    piped_bad = subprocess.run([sys.executable, "-m", "mirrorsim", "solve", "-"],
                               input=binary.read_bytes(), capture_output=True)
    assert piped_bad.returncode == 2 and b"<stdin>" in piped_bad.stderr
    assert b"not UTF-8 text" in piped_bad.stderr and piped_bad.stderr.count(b"\n") == 1
    # only solve's measurements come from a pipe: a scene named - is a file name
    scene = subprocess.run([sys.executable, "-m", "mirrorsim", "check", "-"], input="{}",
                           capture_output=True, text=True, cwd=tmp_path)
    assert scene.returncode == 2 and "no such file" in scene.stderr


def test_plan_with_a_wide_prior_falls_back_and_says_so(tmp_path, capsys):
    """At a ±20° yaw prior two positions of the default scene are seen under every pose
    and its real mirror shows neither unobstructed: the plan chose none and stopped
    (exit 1).  Now it proposes the best seen under fewer poses and prints how many."""
    png, js = tmp_path / "plan.png", tmp_path / "plan.json"
    assert main(["plan", str(SCENES / "default.yaml"), "--yaw-spread", "20", "--out", str(png),
                 "--json", str(js)]) == 0
    best = json.loads(js.read_text())["best_beacon"]
    assert 0 < best["seen_fraction"] < 1
    assert f"seen under {100 * best['seen_fraction']:.0f}% of poses" in capsys.readouterr().out


def test_montecarlo_says_where_one_draw_holds_a_rows_rmse(capsys):
    """Table 1's second row at 1000 draws: one draw's reflection point lies far off
    (the reflector's RMSE 17.9 where 200 draws give 0.28), so the RMSE is no measure of
    the σ's; the row's largest draw's share and its median say so.  Small σ's give no
    such draw."""
    heavy = run_row(2.6, 0.29, iterations=1000, rng=np.random.default_rng(0))
    assert heavy.largest_share_ref > 0.5 and heavy.rmse_ref > 2 * heavy.median_ref
    calm = run_row(0.01, 0.005, iterations=1000, rng=np.random.default_rng(0))
    assert calm.largest_share_ref < 0.05 and calm.largest_share_tar < 0.05
    assert calm.rmse_ref == pytest.approx(calm.median_ref, rel=0.5)
    assert main(["montecarlo", "--iterations", "1000"]) == 0
    notes = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("note:")]
    assert len(notes) == 1 and notes[0].startswith("note: row 2: one draw of 1000 holds")


def test_montecarlo_in_3d_prints_both_solves_and_refuses_bad_rises(tmp_path, capsys):
    out = tmp_path / "mc3.json"
    assert main(["montecarlo", "--lean", "2", "--target-z", "0.5", "--iterations", "50",
                 "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "in 3-D" in printed and "planar tar" in printed
    doc = json.loads(out.read_text())
    assert doc["geometry"]["mirror_lean_deg"] == pytest.approx(2.0)
    assert len(doc["rows"]) == 3 and all("rmse_tar_planar" in r for r in doc["rows"])
    for argv, flag in ((["--lean", "11"], "--lean"), (["--target-z", "-1"], "--target-z"),
                       (["--camera-height", "nan"], "--camera-height"),
                       (["--lean", "1", "--sigma-elevation", "99"], "--sigma-elevation")):
        assert main(["montecarlo", *argv]) == 2
        assert flag in capsys.readouterr().err


def test_the_loose_fit_warning_needs_a_distance():
    """The warning of a target barely located: its RMS over a tenth of its distance from
    the lens; none for a target at the lens (a share of nothing: it had divided by
    zero) or within a centimetre of it, none without a covariance."""
    from mirrorsim.cli.tables import loose_fit_warning

    cov = np.diag([4.0, 5.0])  # an RMS of 3 cm
    assert "barely locate" in loose_fit_warning(cov, np.array([20.0, 0.0]), np.zeros(2))
    assert loose_fit_warning(cov, np.array([40.0, 0.0]), np.zeros(2)) is None
    assert loose_fit_warning(cov, np.zeros(2), np.zeros(2)) is None
    assert loose_fit_warning(cov, np.array([1e-9, 0.0]), np.zeros(2)) is None
    assert loose_fit_warning(None, np.array([20.0, 0.0]), np.zeros(2)) is None
