"""Self-calibrating SLTR: a pan offset and a range scale shared by every measurement,
and the mirror's power, estimated with the mirror from several beacons at known
positions."""

import numpy as np
import pytest

from solver.errors import BadParameter, SolverError
from solver.geometry import line_normal, unit
from solver.lsq import crlb, solve_measurements
from solver.measurements import BeaconMeasurement, ObjectSigmas, Sigma
from solver.selfcal import SelfCalibration
from solver.sltr import observe

OBS = np.zeros(2)
MIRROR = (np.array([40.0, 40.0]), 20.0)
TARGET = np.array([52.0, 20.0])
BEACONS = [np.array([30.0, 25.0]), np.array([45.0, 28.0]), np.array([20.0, 30.0])]
SIG = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
RHO = float(line_normal(MIRROR[1]) @ MIRROR[0])


def _measure(rng, delta=0.0, scale=1.0, beacons=BEACONS):
    """Exact images, then the bench's pan offset and range scale, then detector noise."""
    bs = []
    for b in beacons:
        o = observe(OBS, *MIRROR, point=b)
        bs.append(BeaconMeasurement(tuple(b), float(o.alpha_deg) + delta + rng.normal(0, 0.003),
                                    float(o.d_total) * scale * (1 + rng.normal(0, 0.002))))
    o = observe(OBS, *MIRROR, point=TARGET)
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
        plain.append(np.linalg.norm(solve_measurements(OBS, bs, ts, sigma=SIG).target - TARGET))
        sol = solve_measurements(OBS, bs, ts, sigma=SIG,
                                 calibration=SelfCalibration(("pan", "scale")))
        cal.append(np.linalg.norm(sol.target - TARGET))
        sd = np.sqrt(np.diag(sol.covariance))
        z.append([(sol.nuisances["pan_offset_deg"] - 0.4) / sd[4],
                  (sol.nuisances["range_scale"] - 1.008) / sd[5]])
    assert np.median(cal) < np.median(plain) / 3
    assert np.mean(np.abs(np.array(z)) < 3, axis=0).min() > 0.97
    bound = crlb(OBS, BEACONS, 20.0, mirror_rho=RHO, target=TARGET, sigma=SIG,
                 nuisances=("pan", "scale"))
    assert np.sqrt(np.mean(np.square(cal))) == pytest.approx(
        np.sqrt(np.trace(bound[2:4, 2:4])), rel=0.25)


def test_the_bound_with_nuisances_is_never_below_the_bound_without():
    plain = crlb(OBS, BEACONS, 20.0, mirror_rho=RHO, target=TARGET, sigma=SIG)[2:4, 2:4]
    cal = crlb(OBS, BEACONS, 20.0, mirror_rho=RHO, target=TARGET, sigma=SIG,
               nuisances=("pan", "scale"))[2:4, 2:4]
    assert np.all(np.linalg.eigvalsh(cal - plain) > -1e-12)


def test_self_calibration_refuses_what_it_cannot_observe():
    rng = np.random.default_rng(0)
    bs, ts = _measure(rng)
    with pytest.raises(SolverError, match="at least 2 beacon observations"):
        solve_measurements(OBS, bs[:1], ts, sigma=SIG,
                           calibration=SelfCalibration(("pan", "scale")))
    with pytest.raises(BadParameter, match="^nuisances: unknown nuisance"):
        SelfCalibration(("roll",))
    with pytest.raises(BadParameter, match=r"^nuisances: pan given twice"):
        SelfCalibration(("pan", "pan"))
    # two beacons standing at one place: their images cannot separate δ and s
    same = [bs[0], BeaconMeasurement(bs[0].position, bs[0].alpha_deg, bs[0].d_total)]
    with pytest.raises(SolverError, match="do not separate"):
        solve_measurements(OBS, same, ts, sigma=SIG, calibration=SelfCalibration(("pan", "scale")))


def test_plan_places_several_beacons_and_says_what_each_buys(tmp_path):
    """plan --beacons 3 --calibrate pan,scale: three positions; after one beacon the
    nuisances are not observable (null), after two and three the expected error equals
    the CRLB of that set computed independently (solver.lsq.crlb averaged over the same
    mirror poses), and the third beacon lowers it."""
    import json

    from mirrorsim.cli.main import main
    from mirrorsim.pipelines.scenes import load_scene
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

    def expected(beacons, prior_information) -> float:
        """√ of the target block's trace of the bound at the planned positions,
        averaged over the poses: the Fisher information of the measurements (from
        solver.lsq.crlb) plus the priors'."""
        pos = np.array([b["position"] for b in beacons])
        var = []
        for point, yaw in poses:
            n = np.array([-np.sin(np.radians(yaw)), np.cos(np.radians(yaw))])
            vt = o + img.d_total * np.array([np.cos(np.radians(img.alpha_deg)),
                                             np.sin(np.radians(img.alpha_deg))])
            t = vt - 2.0 * (n @ vt - n @ point) * n
            info = np.linalg.inv(crlb(o, pos, yaw, mirror_rho=n @ point, target=t, sigma=s,
                                      nuisances=("pan", "scale")))
            var.append(np.trace(np.linalg.inv(info + prior_information)[2:4, 2:4]))
        return float(np.sqrt(np.mean(var)))

    assert bs[2]["rmse_after"] == pytest.approx(expected(bs, 0.0), rel=1e-6)
    # with priors on the nuisances (--prior): the bound of the set it chose is the
    # information above plus 1/σ² on each nuisance (the Bayesian bound), between the
    # free set's and a bench without those errors
    assert main(["plan", str(SCENES / "exp1.yaml"), "--beacons", "3", "--calibrate",
                 "pan,scale", "--prior", "pan=0.3,scale=0.006", "--step", "2", "--out",
                 str(tmp_path / "q.png"), "--json", str(js)]) == 0
    planned = json.loads(js.read_text())["beacon_set"]
    assert planned["priors"] == {"pan": 0.3, "scale": 0.006}
    bp = planned["beacons"]
    prior = np.diag([0, 0, 0, 0, 0.3**-2, 0.006**-2])
    assert bp[2]["rmse_after"] == pytest.approx(expected(bp, prior), rel=1e-5)
    assert bp[2]["rmse_after_plain"] <= bp[2]["rmse_after"] < bs[2]["rmse_after"]
    # with one beacon the priors do not make the nuisances observable to the plan: it
    # chooses the first by the error without them, as without priors
    assert bp[0]["rmse_after"] is None


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
    # every command that self-calibrates takes --prior, and refuses a bad one first
    for argv in (["budget", str(SCENES / "bench" / "exp1.yaml"), "--prior", "power=0.001",
                  "--out", str(tmp_path / "b")],
                 ["evaluate", str(SCENES / "exp1.yaml"), "--prior", "pan=0.3", "--out",
                  str(tmp_path / "e")],
                 ["plan", str(SCENES / "exp1.yaml"), "--calibrate", "scale", "--prior",
                  "scale=-1", "--out", str(tmp_path / "p.png")],
                 ["dataset", "--n", "1", "--seed", "1", "--beacons", "3", "--calibrate",
                  "pan,scale", "--prior", "pan=0.3,pan=0.2", "--out", str(tmp_path / "d")]):
        assert main(argv) == 2
        err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("error:")]
        assert len(err) == 1 and "--prior" in err[0], err
    for made in ("e", "b", "p.png", "d"):
        assert not (tmp_path / made).exists()


def test_a_budgets_document_says_how_it_self_calibrated():
    from mirrorsim.pipelines.budget import Budget

    cal = SelfCalibration(("pan", "scale"), 0.1, {"pan": 0.3})
    doc = Budget("s", 1.0, None, (), cal, 0.5).to_json()
    assert doc["self_calibration"] == {"nuisances": ["pan", "scale"],
                                       "beacon_position_sigma_cm": 0.1,
                                       "priors": {"pan": 0.3}}
    assert doc["ideal"]["calibrated_target_cm"] == 0.5
    assert "self_calibration" not in Budget("s", 1.0, None, ()).to_json()


def _flat_reflection_points(pts) -> np.ndarray:
    return np.array([observe(OBS, *MIRROR, point=p).reflection_point for p in pts])


def _cos_incidence(o) -> float:
    """cos of the angle between the camera's ray to an image and MIRROR's normal."""
    return abs(float(line_normal(MIRROR[1]) @ unit(o.alpha_deg)))


def _arc(p, vertex, radius):
    """The bearing (deg) at which the camera sees ``p`` in a circular mirror of
    ``radius`` (> 0 concave) tangent to MIRROR's line at ``vertex``, and the light's path
    length: the reflection point found by Fermat's principle (the path's length
    stationary), not by the first-order formula under test."""
    from scipy.optimize import brentq

    a, n = unit(MIRROR[1]), line_normal(MIRROR[1])
    nc = n if (OBS - MIRROR[0]) @ n > 0 else -n  # toward the camera
    centre = vertex + radius * nc

    def point(phi):
        return centre - radius * (np.cos(phi) * nc - np.sin(phi) * a)

    def length(phi):
        return np.hypot(*(point(phi) - OBS)) + np.hypot(*(p - point(phi)))

    def slope(phi, h=1e-7):
        return (length(phi + h) - length(phi - h)) / (2 * h)

    flat = observe(OBS, *MIRROR, point=p).reflection_point
    phi0 = ((flat - vertex) @ a) / radius
    phi = brentq(slope, phi0 - 0.01, phi0 + 0.01, xtol=1e-15)
    x = point(phi) - OBS
    return float(np.degrees(np.arctan2(x[1], x[0]))), float(length(phi))


@pytest.mark.parametrize("radius", [2000.0, -2000.0, 5000.0])
@pytest.mark.parametrize("shift", [10.0, -10.0])
def test_the_mirror_power_moves_each_image_as_a_curved_mirror_does(radius, shift):
    """power_terms against Fermat's reflection off a circular arc (the vertex 5–15 cm
    from the reflection points): the α change, and d_total's change less the sagittal
    magnification's (the light's shorter path), equal to first order, the rest within
    80/|R| of them (second order in c: 4 % at R = 2000 cm)."""
    from solver.fit_model import power_terms

    pts = np.vstack([*BEACONS, TARGET])
    vertex = _flat_reflection_points(pts).mean(axis=0) + shift * unit(MIRROR[1])
    dalpha, dd = power_terms((MIRROR[1], RHO), OBS, pts, vertex=vertex)
    for k, p in enumerate(pts):
        o = observe(OBS, *MIRROR, point=p)
        alpha, path = _arc(p, vertex, radius)
        magnified = -2.0 * _cos_incidence(o) * o.d1 * o.d2
        assert abs(alpha - o.alpha_deg) > 0.002  # the effects are there to be measured
        assert abs(path - o.d_total) > 0.001
        assert dalpha[k] / radius == pytest.approx(alpha - o.alpha_deg, rel=80 / abs(radius))
        assert (dd[k] - magnified) / radius == pytest.approx(path - o.d_total,
                                                             rel=80 / abs(radius))


def _sphere_elevation(p3, vertex, radius, camera_z, vertex_z):
    """tan of the elevation at which a camera at OBS, ``camera_z`` high, sees the point
    ``p3`` (x, y, z) in a spherical mirror of ``radius`` (> 0 concave) tangent to
    MIRROR's plane at ``vertex`` (``vertex_z`` high): the reflection point found by
    Fermat's principle on the sphere (the path's length stationary in both angles)."""
    from scipy.optimize import root

    a, n = unit(MIRROR[1]), line_normal(MIRROR[1])
    nc = n if (OBS - MIRROR[0]) @ n > 0 else -n
    a3, n3, z3 = np.r_[a, 0.0], np.r_[nc, 0.0], np.array([0.0, 0.0, 1.0])
    centre = np.r_[vertex, vertex_z] + radius * n3
    cam = np.r_[OBS, camera_z]

    def point(q):
        phi, psi = q
        return centre - radius * (np.cos(phi) * np.cos(psi) * n3
                                  - np.sin(phi) * np.cos(psi) * a3 + np.sin(psi) * z3)

    def length(q):
        s = point(q)
        return np.linalg.norm(s - cam) + np.linalg.norm(p3 - s)

    def slope(q, h=1e-6):
        return [(length(q + h * e) - length(q - h * e)) / (2 * h) for e in np.eye(2)]

    flat = observe(OBS, *MIRROR, point=p3[:2]).reflection_point
    s = point(root(slope, [((flat - vertex) @ a) / radius, 0.0], tol=1e-14).x)
    return (s[2] - camera_z) / np.hypot(*(s[:2] - OBS))


@pytest.mark.parametrize("radius", [2000.0, -2000.0, 5000.0])
def test_the_mirror_power_magnifies_each_image_as_a_spherical_mirror_does(radius):
    """power_terms' whole d_total change (path and sagittal magnification) against a
    vertical segment seen in a spherical mirror, in 3-D by Fermat's principle: the
    segment's apparent distance, its height over the difference of its ends' elevation
    tangents (d_total for a flat mirror), moves as predicted within 0.5 % where the
    segment, camera and vertex are near one height (0–1 cm).  With them 0–10, 6 and 8 cm
    high, as on the bench, a term the line model leaves out appears: the sphere's tilt
    at the reflection point's height deflects each ray vertically, and tan's slope turns
    that into a size change, first order in c too (measured up to 15 % of the
    predicted change here, about 0.01 cm)."""
    from solver.fit_model import power_terms

    pts = np.vstack([*BEACONS, TARGET])
    vertex = _flat_reflection_points(pts).mean(axis=0)
    _, dd = power_terms((MIRROR[1], RHO), OBS, pts, vertex=vertex)
    for height, camera_z, vertex_z, rel in ((1.0, 0.5, 0.5, 0.005), (10.0, 6.0, 8.0, 0.16)):
        for k, p in enumerate(pts):
            top, foot = (_sphere_elevation(np.r_[p, z], vertex, radius, camera_z, vertex_z)
                         for z in (height, 0.0))
            seen = height / (top - foot) - observe(OBS, *MIRROR, point=p).d_total
            assert abs(seen) > 0.03  # the effect is there to be measured
            assert seen == pytest.approx(dd[k] / radius, rel=rel)


def test_the_powers_vertex_changes_the_mirror_not_the_target():
    """To first order a vertex elsewhere on the line is a turn and a shift of the line:
    the target's Cramér–Rao bound with pan, scale and power is the same for vertices
    10 and 30 cm apart (the plan's vertex, the pose's point, and the solver's, the
    middle of the reflection points, then agree)."""
    from solver.beacon_set import _information

    o = observe(OBS, *MIRROR, point=TARGET)
    along = unit(MIRROR[1])
    bounds = []
    for shift in (0.0, 10.0, -30.0):
        info_b, info_t, _ = _information(OBS, np.array(BEACONS), float(o.alpha_deg),
                                         float(o.d_total), MIRROR[0] + shift * along,
                                         MIRROR[1], SIG, ("pan", "scale", "power"))
        cov = np.linalg.inv(info_t + info_b.sum(axis=0))
        bounds.append(np.trace(cov[2:4, 2:4]))
    # the power costs information (its bound above pan and scale's), the same at each
    # vertex, and the solver's vertex (crlb: the middle of the reflection points) agrees
    two = crlb(OBS, BEACONS, 20.0, mirror_rho=RHO, target=TARGET, sigma=SIG,
               nuisances=("pan", "scale"))[2:4, 2:4]
    three = crlb(OBS, BEACONS, 20.0, mirror_rho=RHO, target=TARGET, sigma=SIG,
                 nuisances=("pan", "scale", "power"))[2:4, 2:4]
    assert np.all(np.linalg.eigvalsh(three - two) > -1e-12)
    assert bounds[0] > 1.5 * np.trace(two)
    assert bounds[1] == pytest.approx(bounds[0], rel=1e-6)
    assert bounds[2] == pytest.approx(bounds[0], rel=1e-6)
    assert np.trace(three) == pytest.approx(bounds[0], rel=1e-6)


def test_self_calibration_removes_a_curved_mirrors_error():
    """A curved mirror (R = 1500 cm), a pan offset and a range scale on three beacons,
    the images seen as the arc reflects them (bearing and path) and magnified by the
    sagittal mirror equation:
    with the power estimated too, the target comes out within a tenth of the error pan
    and scale alone leave (1.2 cm), and the power within 5 % of 1/R."""
    radius, delta, scale = 1500.0, 0.3, 1.006
    pts = [*BEACONS, TARGET]
    # the solver's vertex: the middle of the reflection points
    vertex = _flat_reflection_points(pts).mean(axis=0)
    meas = []
    for p in pts:
        o = observe(OBS, *MIRROR, point=p)
        alpha, path = _arc(p, vertex, radius)
        d = path - 2.0 * _cos_incidence(o) * o.d1 * o.d2 / radius  # the sagittal image's
        meas.append((alpha + delta, d * scale))
    bs = [BeaconMeasurement(tuple(b), *m) for b, m in zip(BEACONS, meas[:3], strict=True)]
    two = solve_measurements(OBS, bs, meas[3:], sigma=SIG,
                             calibration=SelfCalibration(("pan", "scale")))
    three = solve_measurements(OBS, bs, meas[3:], sigma=SIG,
                               calibration=SelfCalibration(("pan", "scale", "power")))
    e2, e3 = (np.linalg.norm(s.target - TARGET) for s in (two, three))
    assert e2 > 0.5
    assert e3 < e2 / 10
    assert three.nuisances["mirror_power_per_cm"] == pytest.approx(1 / radius, rel=0.05)
    # δ takes the images' second-order part (0.03°, a tenth of its own σ here)
    assert three.nuisances["pan_offset_deg"] == pytest.approx(delta, abs=0.05)


def test_the_powers_covariance_holds_and_too_few_beacons_are_refused():
    """Images moved by a power of 1/2000 cm (the first-order model) and detector noise:
    the estimated power lies within 2 of its own σ in about 95 % of 300 draws; two
    beacons cannot carry pan, scale and power (7 unknowns, 6 measurements)."""
    from solver.fit_model import power_terms

    rng = np.random.default_rng(11)
    c = 1 / 2000
    pts = np.vstack([*BEACONS, TARGET])
    A, D = power_terms((MIRROR[1], RHO), OBS, pts, vertex=_flat_reflection_points(pts).mean(axis=0))
    z = []
    for _ in range(300):
        bs, ts = _measure(rng)
        moved = [BeaconMeasurement(b.position, b.alpha_deg + c * A[k], b.d_total + c * D[k])
                 for k, b in enumerate(bs)]
        ts = [(ts[0][0] + c * A[3], ts[0][1] + c * D[3])]
        sol = solve_measurements(OBS, moved, ts, sigma=SIG,
                                 calibration=SelfCalibration(("pan", "scale", "power")))
        z.append((sol.nuisances["mirror_power_per_cm"] - c) / np.sqrt(sol.covariance[6, 6]))
    assert 0.92 < np.mean(np.abs(z) < 2) < 0.98
    with pytest.raises(SolverError, match="at least 3 beacon observations"):
        solve_measurements(OBS, moved[:2], ts, sigma=SIG,
                           calibration=SelfCalibration(("pan", "scale", "power")))


PRIORS = {"pan": 0.3, "scale": 0.006, "power": 0.0003}


def test_priors_on_the_nuisances_help_where_the_bench_draws_them_from_the_priors():
    """Pan, scale and power drawn from N(neutral, σ²) of PRIORS each draw, three beacons:
    with those priors the target's RMS error is smaller than free self-calibration's,
    and its 95 % ellipse holds about 95 % of the errors (the posterior's covariance)."""
    from solver.fit_model import power_terms

    rng = np.random.default_rng(29)
    pts = np.vstack([*BEACONS, TARGET])
    A, D = power_terms((MIRROR[1], RHO), OBS, pts, vertex=_flat_reflection_points(pts).mean(axis=0))
    free, known, inside = [], [], []
    for _ in range(300):
        delta, s, c = (rng.normal(0, PRIORS["pan"]), 1 + rng.normal(0, PRIORS["scale"]),
                       rng.normal(0, PRIORS["power"]))
        bs, ts = _measure(rng, delta, s)
        bs = [BeaconMeasurement(b.position, b.alpha_deg + c * A[k], b.d_total + s * c * D[k])
              for k, b in enumerate(bs)]
        ts = [(ts[0][0] + c * A[3], ts[0][1] + s * c * D[3])]
        nu = ("pan", "scale", "power")
        free.append(solve_measurements(OBS, bs, ts, sigma=SIG,
                                       calibration=SelfCalibration(nu)).target - TARGET)
        sol = solve_measurements(OBS, bs, ts, sigma=SIG,
                                 calibration=SelfCalibration(nu, priors=PRIORS))
        e = sol.target - TARGET
        known.append(e)
        inside.append(e @ np.linalg.solve(sol.covariance[2:4, 2:4], e) < 5.991)
    rms = [np.sqrt(np.mean(np.sum(np.square(v), axis=1))) for v in (free, known)]
    assert rms[1] < 0.9 * rms[0], rms
    assert 0.92 < np.mean(inside) < 0.98


def test_a_prior_tight_enough_is_the_plain_fit_and_a_wide_one_the_free_fit():
    """σ → 0 pins each nuisance at its neutral value (plain least squares); σ → ∞ lets
    it free (self-calibration without priors)."""
    rng = np.random.default_rng(5)
    bs, ts = _measure(rng, 0.2, 1.004)
    nu = ("pan", "scale")
    plain = solve_measurements(OBS, bs, ts, sigma=SIG).target
    free = solve_measurements(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(nu)).target
    tight = solve_measurements(OBS, bs, ts, sigma=SIG,
                               calibration=SelfCalibration(nu, priors={"pan": 1e-6,
                                                                       "scale": 1e-6})).target
    wide = solve_measurements(OBS, bs, ts, sigma=SIG,
                              calibration=SelfCalibration(nu,
                                                          priors={"pan": 1e6, "scale": 1e6})).target
    assert np.linalg.norm(free - plain) > 0.05  # the case tells the two apart
    assert tight == pytest.approx(plain, abs=1e-4)
    assert wide == pytest.approx(free, abs=1e-4)


def test_priors_are_refused_for_nuisances_not_estimated_and_when_not_positive(tmp_path,
                                                                                capsys):
    from mirrorsim.cli.main import main

    rng = np.random.default_rng(0)
    bs, ts = _measure(rng)
    with pytest.raises(BadParameter, match="^priors: .*not estimated"):
        SelfCalibration(("pan",), priors={"scale": 0.01})
    with pytest.raises(BadParameter, match="^priors: .*must be a number ≥ 1e-06"):
        SelfCalibration(("pan",), priors={"pan": 0.0})
    with pytest.raises(BadParameter, match="^priors: .* is not a mapping of strings to numbers"):
        SelfCalibration(("pan",), priors={"pan": True})
    with pytest.raises(BadParameter, match="^position_sigma: nan is not a finite number"):
        SelfCalibration(("pan",), np.nan)
    # named once, by the caller (the flag, on the command line)
    with pytest.raises(BadParameter, match=r"^position_sigma: -1\.0 must be 0 \(known "):
        SelfCalibration(("pan",), -1.0)
    # numpy numbers are numbers, kept as plain floats (a dataset writes them as text)
    cal = SelfCalibration(("pan",), np.int64(1), {"pan": np.float32(0.25)})
    assert type(cal.position_sigma) is float and type(cal.priors["pan"]) is float
    from solver.selfcal import parse_priors, priors_text

    assert parse_priors(priors_text(cal.priors)) == {"pan": 0.25}
    path = tmp_path / "m.json"
    import json
    path.write_text(json.dumps({
        "observer": [0, 0], "target": {"alpha_deg": ts[0][0], "d_total": ts[0][1]},
        "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                     "d_total": b.d_total} for b in bs]}))
    for prior, says in (("scale=0.01", "not estimated"), ("pan=-1", "≥ 1e-06"),
                        ("pan", "NAME=SIGMA"), ("pan=x", "NAME=SIGMA"), ("pan=nan", "≥ 1e-06"),
                        ("pan=1e-320", "≥ 1e-06"),
                        ("pan=0.3,pan=0.4", "twice"), ("roll=1", "unknown nuisance")):
        assert main(["solve", str(path), "--calibrate", "pan", "--prior", prior]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--prior" in err[0] and says in err[0], err
    assert main(["solve", str(path), "--calibrate", "pan,scale", "--prior",
                 "pan=0.3,scale=0.006"]) == 0
    assert "with priors (pan ±0.3°, scale ±0.6 %)" in capsys.readouterr().out
    # the priors travel with the solution's document and back
    from solver.sltr import Solution

    sol = solve_measurements(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(
        ("pan", "scale"), priors={"pan": 0.3, "scale": 0.006}))
    assert Solution.from_json(sol.to_json()).priors == {"pan": 0.3, "scale": 0.006}


def test_a_pan_prior_adds_to_the_shared_alpha_offset_of_the_sigmas():
    """σ's with a shared α offset of 0.05° and a pan prior of 0.2°: the same fit as a
    shared offset of hypot(0.05, 0.2) alone (their variances add), and a looser pan
    than the shared offset alone gives."""
    from dataclasses import replace

    rng = np.random.default_rng(8)
    bs, ts = _measure(rng, 0.1, 1.003)
    shared = replace(SIG, shared_alpha_deg=0.05)
    both = solve_measurements(OBS, bs, ts, sigma=shared,
                              calibration=SelfCalibration(("pan", "scale"), priors={"pan": 0.2}))
    wider = replace(SIG, shared_alpha_deg=float(np.hypot(0.05, 0.2)))
    added = solve_measurements(OBS, bs, ts, sigma=wider,
                               calibration=SelfCalibration(("pan", "scale")))
    alone = solve_measurements(OBS, bs, ts, sigma=shared,
                               calibration=SelfCalibration(("pan", "scale")))
    assert both.target == pytest.approx(added.target, abs=1e-9)
    assert both.covariance[4, 4] == pytest.approx(added.covariance[4, 4], rel=1e-6)
    assert both.covariance[4, 4] > alone.covariance[4, 4]


def test_sigmas_too_small_to_weigh_are_refused_before_the_solve(tmp_path, capsys):
    """σ's of 1e-320 (a prior, a beacon position, a measurement's, the shared α offset,
    an error model's) made every weighted residual infinite: a traceback.  Each is now
    refused in one line, exit 2, naming its flag or key; the least σ's allowed solve."""
    import json
    from pathlib import Path

    from mirrorsim.cli.main import main

    bs, ts = _measure(np.random.default_rng(1))
    doc = {"observer": [0, 0], "target": {"alpha_deg": ts[0][0], "d_total": ts[0][1]},
           "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                        "d_total": b.d_total} for b in bs]}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    for extra, says in ((["--prior", "pan=1e-320"], "--prior"),
                        (["--beacon-sigma", "1e-320"], "--beacon-sigma"),
                        (["--prior", "pan=0.3", "--prior", "scale=0.01"], "given twice"),
                        (["--calibrate", "scale"], "given twice")):
        try:  # a repeated flag is argparse's usage error: SystemExit(2)
            status = main(["solve", str(path), "--calibrate", "pan,scale", *extra])
        except SystemExit as exc:
            status = exc.code
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(err) == 1 and says in err[0], err  # not after the usage
    sigma = {"alpha_deg": 0.01, "d_total_rel": 0.002}
    for key, block in (("sigma.alpha_deg", {**sigma, "alpha_deg": 1e-320}),
                       ("sigma.d_total_rel", {**sigma, "d_total_rel": 1e-320}),
                       ("sigma.shared_alpha_deg", {"target": sigma, "beacons": sigma,
                                                   "shared_alpha_deg": 1e-320})):
        bad = tmp_path / "s.json"
        bad.write_text(json.dumps({**doc, "sigma": block}))
        assert main(["solve", str(bad)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and key in err[0] and str(bad) in err[0], err
    model = json.loads((Path(__file__).parents[1] / "mirrorsim" / "data"
                        / "error_model.json").read_text())
    tiny = tmp_path / "em.json"
    del model["sha256"]  # edited by hand, as a model is edited on purpose
    tiny.write_text(json.dumps({**model, "shared_alpha_deg": 1e-320}))
    assert main(["solve", str(path), "--error-model", str(tiny)]) == 2
    assert "shared_alpha_deg" in capsys.readouterr().err
    # the least σ's still solve (a nuisance or a beacon known to them is as good as known)
    assert main(["solve", str(path), "--calibrate", "pan,scale,power", "--prior",
                 "pan=1e-6,scale=1e-6,power=1e-6", "--beacon-sigma", "1e-4"]) == 0
    least = {"alpha_deg": 1e-6, "d_total_rel": 1e-6}
    path.write_text(json.dumps({**doc, "sigma": least}))
    assert main(["solve", str(path), "--calibrate", "pan,scale"]) == 0
    capsys.readouterr()
    # a library caller gets the solver's one-line refusal, not an overflow
    with pytest.raises(SolverError, match="each σ_α must be within"):
        solve_measurements(OBS, bs, ts, sigma=ObjectSigmas.same(Sigma(1e-320, 0.002)))


@pytest.mark.parametrize("calibration, shared", [
    (SelfCalibration(), 0.0),
    (SelfCalibration(), 0.3),
    (SelfCalibration(("pan", "scale")), 0.0),
    (SelfCalibration(("pan", "scale", "power"), priors={"pan": 0.5, "scale": 0.01,
                                                        "power": 8e-4}), 0.0),
    (SelfCalibration(("pan", "scale", "power"), 0.3, {"pan": 0.9, "scale": 0.017,
                                                      "power": 8e-4}), 0.0),
    (SelfCalibration(("scale",), 0.2, {"scale": 0.02}), 0.4),
])
def test_the_reports_bound_is_its_own_estimators_and_never_above_its_covariance(
        calibration, shared):
    """The bound a report prints is the information of the estimator that ran (its
    nuisances, priors, positions σ and the shared α offset), at the truth; its covariance
    is the same information at the estimate.  Over noisy draws of three beacons the
    bound's target RMS stays within the linearization's difference (5 %) of the
    covariance's, never far above it (a bound without the priors was once 4.7 cm
    beside a 1.2 cm covariance), and the estimates' RMS error is the bound's to 25 %."""
    rng = np.random.default_rng(11)
    sig = ObjectSigmas(SIG.target, SIG.beacons, shared)
    bound = crlb(OBS, BEACONS, 20.0, mirror_rho=RHO, target=TARGET, sigma=sig,
                 calibration=calibration)
    crlb_rms = np.sqrt(np.trace(bound[2:4, 2:4]))
    errors, ratio = [], []
    for _ in range(150):
        bs, ts = _measure(rng)
        sol = solve_measurements(OBS, bs, ts, sigma=sig, calibration=calibration)
        ratio.append(crlb_rms / np.sqrt(np.trace(sol.target_covariance)))
        errors.append(np.linalg.norm(sol.target - TARGET))
        assert sol.covariance.shape[0] == len(sol.params_order)
    assert max(ratio) < 1.05 and min(ratio) > 0.8
    noise_only = calibration.position_sigma == 0 and not shared
    if noise_only:  # the draws hold no bench error: the estimator is the bound's
        assert np.sqrt(np.mean(np.square(errors))) == pytest.approx(crlb_rms, rel=0.25)


def test_a_prior_lets_fewer_beacons_carry_a_nuisance():
    """A nuisance with a prior brings its own row: one beacon carries pan, scale and
    power held by their priors (the bench's tolerances), and the bound widens by them."""
    rng = np.random.default_rng(2)
    bs, ts = _measure(rng, beacons=BEACONS[:1])
    cal = SelfCalibration(("pan", "scale", "power"),
                          priors={"pan": 0.5, "scale": 0.01, "power": 8e-4})
    sol = solve_measurements(OBS, bs, ts, sigma=SIG, calibration=cal)
    plain = solve_measurements(OBS, bs, ts, sigma=SIG)
    assert np.trace(sol.target_covariance) > 10 * np.trace(plain.target_covariance)
    with pytest.raises(SolverError, match="at least 2 beacon observations"):
        solve_measurements(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(("pan", "scale")))


def test_a_nuisance_the_beacons_do_not_separate_is_held_and_said():
    """Two beacons 2 mm apart (nearly one view of the mirror) cannot tell a pan offset
    from the mirror's yaw: asked to calibrate the pan freely, the solve holds it at the
    bench's prior (or at 0 with none) and says so, whatever the beacon count; three
    well-spread beacons separate it and nothing is said; an estimate far beyond its
    prior is flagged."""
    from types import SimpleNamespace

    from mirrorsim.formats.error_model_scope import BenchTolerances
    from mirrorsim.pipelines.solving import SEPARATED_SD, solve_separated

    rng = np.random.default_rng(4)
    close = [BEACONS[0], BEACONS[0] + np.array([0.2, 0.0])]
    bs, ts = _measure(rng, beacons=close)
    bench = SimpleNamespace(tolerances=BenchTolerances(pan_deg=1.5))
    ideal = SimpleNamespace(tolerances=BenchTolerances())
    free = solve_measurements(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(("pan",)))
    assert free.nuisance_sd["pan_offset_deg"] > SEPARATED_SD["pan"]
    sol, cal, said = solve_separated(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(("pan",)),
                                     model=bench)
    assert cal.priors == {"pan": pytest.approx(1.5 / 3**0.5)}
    assert any("do not separate it" in s and "held at its prior" in s for s in said)
    sol, cal, said = solve_separated(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(("pan",)),
                                     model=ideal)
    assert cal.nuisances == () and any("held at its neutral value" in s for s in said)
    bs, ts = _measure(rng)  # three beacons spread along the mirror
    sol, cal, said = solve_separated(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(("pan",)),
                                     model=bench)
    assert cal.nuisances == ("pan",) and said == []
    bs, ts = _measure(rng, delta=0.5)
    _, _, said = solve_separated(OBS, bs, ts, sigma=SIG,
                                 calibration=SelfCalibration(("pan",), priors={
        "pan": 0.05}), model=bench)
    assert any(s.startswith("warning: pan came out") for s in said)


def test_a_self_calibrated_target_far_from_plain_least_squares_is_said():
    """Three beacons of a bench whose mount reads the pan 0.5° off: calibrating the pan
    moves the target over 0.1 cm from plain least squares' estimate, and the line says
    so with the Hausman test's verdict, that the beacons show the bench error (p < 0.05);
    a move within the variance the nuisances add reads as plain's being as likely, and
    one under 0.1 cm says nothing."""
    from dataclasses import replace
    from types import SimpleNamespace

    from mirrorsim.formats.error_model_scope import BenchTolerances
    from mirrorsim.pipelines.solving import MOVED_CM, moved_from_plain, solve_separated

    bench = SimpleNamespace(tolerances=BenchTolerances(pan_deg=1.5))
    rng = np.random.default_rng(11)
    bs, ts = _measure(rng, delta=0.5)
    sol, _, said = solve_separated(OBS, bs, ts, sigma=SIG, calibration=SelfCalibration(("pan",)),
                                   model=bench)
    plain = solve_measurements(OBS, bs, ts, sigma=SIG)
    assert np.linalg.norm(sol.target - plain.target) > MOVED_CM
    line = [s for s in said if s.startswith("self-calibration moved the target")]
    assert len(line) == 1 and "show bench errors that plain leaves in" in line[0]
    assert " on 1, " in line[0]  # one nuisance: the variance it adds has one direction
    assert f"({plain.target[0]:.2f}, {plain.target[1]:.2f})" in line[0]
    # a move the nuisances' added variance explains: no bench error shows
    wide = replace(sol, target=plain.target + np.array([0.3, 0.0]),
                   covariance=sol.covariance * 1e4)
    assert "plain's is as likely" in moved_from_plain(wide, plain)[0]
    near = replace(sol, target=plain.target + np.array([0.09, 0.0]))
    assert moved_from_plain(near, plain) == []
