"""Self-calibrating SLTR: a pan offset and a range scale shared by every measurement,
estimated with the mirror from several beacons at known positions."""

import numpy as np
import pytest

from solver.errors import SolverError
from solver.lsq import BeaconMeasurement, ObjectSigmas, Sigma, crlb, solve_measurements
from solver.sltr import observe

OBS = np.zeros(2)
MIRROR = (np.array([40.0, 40.0]), 20.0)
TARGET = np.array([52.0, 20.0])
BEACONS = [np.array([30.0, 25.0]), np.array([45.0, 28.0]), np.array([20.0, 30.0])]
SIG = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
RHO = float(np.array([-np.sin(np.radians(20)), np.cos(np.radians(20))]) @ MIRROR[0])


def _measure(rng, delta=0.0, scale=1.0, beacons=BEACONS):
    """Exact images, then the bench's pan offset and range scale, then detector noise."""
    bs = []
    for b in beacons:
        o = observe(OBS, *MIRROR, b)
        bs.append(BeaconMeasurement(tuple(b), float(o.alpha_deg) + delta + rng.normal(0, 0.003),
                                    float(o.d_total) * scale * (1 + rng.normal(0, 0.002))))
    o = observe(OBS, *MIRROR, TARGET)
    return bs, [(float(o.alpha_deg) + delta + rng.normal(0, 0.002),
                 float(o.d_total) * scale * (1 + rng.normal(0, 0.0005)))]


def test_self_calibration_removes_a_pan_offset_and_a_range_scale():
    """δ = 0.4°, s = 1.008 on three beacons: plain least squares is biased by them; the
    self-calibrated estimate's median error is under a third of it, its δ and s come
    out within 3 of their own σ's, and its error is what its CRLB says (RMS within 25 %)."""
    rng = np.random.default_rng(3)
    plain, cal, z = [], [], []
    for _ in range(300):
        bs, ts = _measure(rng, 0.4, 1.008)
        plain.append(np.linalg.norm(solve_measurements(OBS, bs, ts, SIG).target - TARGET))
        sol = solve_measurements(OBS, bs, ts, SIG, nuisances=("pan", "scale"))
        cal.append(np.linalg.norm(sol.target - TARGET))
        sd = np.sqrt(np.diag(sol.covariance))
        z.append([(sol.nuisances["pan_offset_deg"] - 0.4) / sd[4],
                  (sol.nuisances["range_scale"] - 1.008) / sd[5]])
    assert np.median(cal) < np.median(plain) / 3
    assert np.mean(np.abs(np.array(z)) < 3, axis=0).min() > 0.97
    bound = crlb(OBS, BEACONS, 20.0, RHO, TARGET, SIG, nuisances=("pan", "scale"))
    assert np.sqrt(np.mean(np.square(cal))) == pytest.approx(
        np.sqrt(np.trace(bound[2:4, 2:4])), rel=0.25)


def test_the_bound_with_nuisances_is_never_below_the_bound_without():
    plain = crlb(OBS, BEACONS, 20.0, RHO, TARGET, SIG)[2:4, 2:4]
    cal = crlb(OBS, BEACONS, 20.0, RHO, TARGET, SIG, nuisances=("pan", "scale"))[2:4, 2:4]
    assert np.all(np.linalg.eigvalsh(cal - plain) > -1e-12)


def test_self_calibration_refuses_what_it_cannot_observe():
    rng = np.random.default_rng(0)
    bs, ts = _measure(rng)
    with pytest.raises(SolverError, match="at least 2 beacon observations"):
        solve_measurements(OBS, bs[:1], ts, SIG, nuisances=("pan", "scale"))
    with pytest.raises(SolverError, match="unknown or repeated"):
        solve_measurements(OBS, bs, ts, SIG, nuisances=("roll",))
    # two beacons standing at one place: their images cannot separate δ and s
    same = [bs[0], BeaconMeasurement(bs[0].position, bs[0].alpha_deg, bs[0].d_total)]
    with pytest.raises(SolverError, match="do not separate"):
        solve_measurements(OBS, same, ts, SIG, nuisances=("pan", "scale"))


def test_plan_places_several_beacons_and_says_what_each_buys(tmp_path):
    """plan --beacons 3 --calibrate pan,scale: three positions; after one beacon the
    nuisances are not observable (null), after two and three the expected error equals
    the CRLB of that set computed independently (solver.lsq.crlb averaged over the same
    mirror poses), and the third beacon lowers it."""
    import json

    from mirrorsim.cli.main import main
    from mirrorsim.formats.scenefile import load_scene
    from mirrorsim.truth import optics
    from solver.placement import MirrorPrior

    from .conftest import SCENES

    js = tmp_path / "p.json"
    assert main(["plan", str(SCENES / "exp1.yaml"), "--beacons", "3", "--calibrate",
                 "pan,scale", "--step", "2", "--out", str(tmp_path / "p.png"),
                 "--json", str(js)]) == 0
    bs = json.loads(js.read_text())["beacon_set"]["beacons"]
    assert len(bs) == 3 and bs[0]["rmse_after"] is None
    assert bs[2]["rmse_after"] < bs[1]["rmse_after"]
    scene = load_scene(SCENES / "exp1.yaml")
    o = np.asarray(scene.camera.position, float)
    img = optics.mirror_image(o, scene.mirror, scene.target.position)
    poses = MirrorPrior(d1=img.d1, yaw_deg=scene.mirror.yaw, d1_spread=2.0,
                        yaw_spread_deg=3.0, n=5).poses(o, img.alpha_deg)
    sig = json.loads(js.read_text())["sigma"]
    s = ObjectSigmas(Sigma(**sig["target"]), (Sigma(**sig["beacons"]),))  # one for all
    pos = np.array([b["position"] for b in bs])
    var = []
    for point, yaw in poses:
        n = np.array([-np.sin(np.radians(yaw)), np.cos(np.radians(yaw))])
        vt = o + img.d_total * np.array([np.cos(np.radians(img.alpha_deg)),
                                         np.sin(np.radians(img.alpha_deg))])
        t = vt - 2.0 * (n @ vt - n @ point) * n
        bound = crlb(o, pos, yaw, n @ point, t, s, nuisances=("pan", "scale"))
        var.append(np.trace(bound[2:4, 2:4]))
    assert bs[2]["rmse_after"] == pytest.approx(np.sqrt(np.mean(var)), rel=1e-6)


def test_commands_refuse_self_calibration_they_cannot_do(tmp_path, capsys):
    from mirrorsim.cli.main import main

    from .conftest import SCENES

    for argv in (["evaluate", str(SCENES / "exp1.yaml"), "--calibrate", "pan,scale", "--out",
                  str(tmp_path / "e")],
                 ["budget", str(SCENES / "bench" / "exp1.yaml"), "--calibrate", "pan", "--out",
                  str(tmp_path / "b")],
                 ["evaluate", str(SCENES / "exp1.yaml"), "--calibrate", "roll", "--out",
                  str(tmp_path / "e")]):
        assert main(argv) == 2
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
        assert len(err) == 1 and "--calibrate" in err[0], err
    assert not (tmp_path / "e").exists() and not (tmp_path / "b").exists()
    # the moving-beacon filter cannot use several beacons: refused, not the first taken
    assert main(["track", str(SCENES / "bench" / "exp1_3beacons.yaml"), "--out",
                 str(tmp_path / "t")]) == 2
    assert "3 beacons" in capsys.readouterr().err
    assert not (tmp_path / "t").exists()
