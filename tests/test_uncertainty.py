"""Honest uncertainty: σ per observation, the Cramér–Rao bound, the error model's σ law,
its validation on held-out rows, and the commands that take --error-model."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from mirrorsim.cli.analysis_tables import error_model_summary
from mirrorsim.cli.main import main
from mirrorsim.formats.error_model import ImageFeatures, default_model_path, feature_vector
from mirrorsim.formats.error_model_file import default_error_model, model_from_dict
from mirrorsim.formats.measurements import measurements_from_dict
from mirrorsim.pipelines import errormodel, sigma_laws, uncertainty
from solver.lsq import crlb, solve_measurements
from solver.measurements import BeaconMeasurement, ObjectSigmas, Sigma, Tail
from solver.selfcal import SelfCalibration
from solver.sltr import observe

from .conftest import SCENES, synthetic_columns, with_frame_columns

OBS = np.array([0.0, 0.0])
MIRROR = (np.array([40.0, 40.0]), 20.0)  # a point on the line, its yaw
TARGET = np.array([52.0, 20.0])
BEACONS = [np.array([30.0, 25.0]), np.array([45.0, 28.0]), np.array([20.0, 30.0])]


def _single(x) -> dict:
    """The one-beacon solution's four measurements (beacon α, d; target α, d) by name."""
    return dict(zip(("beacon_alpha_deg", "beacon_d_total", "target_alpha_deg",
                     "target_d_total"), map(float, x), strict=True))


def _exact(points):
    return [observe(OBS, MIRROR[0], MIRROR[1], point=p) for p in points]


def _noisy(rng, sig: ObjectSigmas, beacons=BEACONS):
    ob = _exact(beacons)
    ot = _exact([TARGET])[0]
    # one offset on every α of the frame (a pan reading's error)
    delta = rng.normal(0, sig.shared_alpha_deg) if sig.shared_alpha_deg else 0.0
    bs = []
    for i, (p, o) in enumerate(zip(beacons, ob, strict=True)):
        s = sig.beacons[0] if len(sig.beacons) == 1 else sig.beacons[i]
        bs.append(BeaconMeasurement(tuple(p), float(o.alpha_deg) + delta
                                    + rng.normal(0, s.alpha_deg),
                                    float(o.d_total) * (1 + rng.normal(0, s.d_total_rel))))
    t = sig.target
    return bs, [(float(ot.alpha_deg) + delta + rng.normal(0, t.alpha_deg),
                 float(ot.d_total) * (1 + rng.normal(0, t.d_total_rel)))]


def _rho():
    n = np.array([-np.sin(np.radians(MIRROR[1])), np.cos(np.radians(MIRROR[1]))])
    return float(n @ MIRROR[0])


@pytest.mark.parametrize("beacons", [BEACONS[:1], BEACONS])
def test_per_object_sigmas_give_ellipses_that_hold_and_meet_the_cramer_rao_bound(beacons):
    """Gaussian noise of known σ's, the target's 4× finer in d_total than the pencil's (as
    on renders): the solver's 95 % ellipse holds the true target 95 % of the time
    (binomial 99.9 % band for 600 draws: 0.925–0.970), the median Mahalanobis distance is
    χ₂'s 1.18, and the Monte Carlo covariance of the estimates equals the CRLB computed at
    the truth (efficiency within 10 %)."""
    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
    rng = np.random.default_rng(7)
    est, dist = [], []
    for _ in range(600):
        bs, ts = _noisy(rng, sig, beacons)
        sol = solve_measurements(OBS, bs, ts, sigma=sig)
        est.append(sol.target)
        dist.append(sol.mahalanobis(TARGET))
    dist = np.array(dist)
    inside = np.mean(dist <= Tail().radius(0.95))
    assert 0.925 <= inside <= 0.970
    assert np.median(dist) == pytest.approx(uncertainty.CHI2_MEDIAN, rel=0.1)
    bound = crlb(OBS, np.array(beacons), MIRROR[1], mirror_rho=_rho(), target=TARGET,
                 sigma=sig)[2:, 2:]
    mse = np.cov(np.array(est).T, bias=True) + np.outer(np.mean(est, 0) - TARGET,
                                                         np.mean(est, 0) - TARGET)
    assert math.sqrt(np.trace(mse) / np.trace(bound)) == pytest.approx(1.0, abs=0.1)


@pytest.mark.parametrize("beacons", [BEACONS[:1], BEACONS])
def test_a_shared_alpha_offset_gives_ellipses_that_hold(beacons):
    """Every α of a frame shifted by one draw of σ 0.05° (a pan reading), each image's
    own α error 0.002°: with the shared part declared, the 95 % ellipse holds the truth
    within its binomial band (600 draws) and the median Mahalanobis is χ₂'s; the Monte
    Carlo spread equals the CRLB (whose Σ holds the shared part).  Counted as
    independent errors of the same total size, the ellipse is misplaced: its median
    Mahalanobis is off by more than 20 %."""
    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),), shared_alpha_deg=0.05)
    total = ObjectSigmas(Sigma(math.hypot(0.002, 0.05), 0.0005),
                         (Sigma(math.hypot(0.003, 0.05), 0.002),))
    rng = np.random.default_rng(17)
    est, dist, naive = [], [], []
    for _ in range(600):
        bs, ts = _noisy(rng, sig, beacons)
        sol = solve_measurements(OBS, bs, ts, sigma=sig)
        est.append(sol.target)
        dist.append(sol.mahalanobis(TARGET))
        naive.append(solve_measurements(OBS, bs, ts, sigma=total).mahalanobis(TARGET))
    dist = np.array(dist)
    assert 0.925 <= np.mean(dist <= Tail().radius(0.95)) <= 0.970
    assert np.median(dist) == pytest.approx(uncertainty.CHI2_MEDIAN, rel=0.1)
    assert abs(np.median(naive) / uncertainty.CHI2_MEDIAN - 1) > 0.2
    bound = crlb(OBS, np.array(beacons), MIRROR[1], mirror_rho=_rho(), target=TARGET,
                 sigma=sig)[2:, 2:]
    mse = np.cov(np.array(est).T, bias=True) + np.outer(np.mean(est, 0) - TARGET,
                                                         np.mean(est, 0) - TARGET)
    assert math.sqrt(np.trace(mse) / np.trace(bound)) == pytest.approx(1.0, abs=0.1)


def test_the_fit_finds_a_shared_alpha_offset_and_only_where_there_is_one():
    """Rows whose α's share one offset of σ 0.02° per frame (own σ's 0.002 / 0.003°):
    the fit finds σ_shared within 15 % and own α laws well below it, and the held-out
    95 % ellipse covers within its binomial band; rows without one give 0."""
    train, test = _simulated_rows(400, 3, shared=0.02), _simulated_rows(400, 4, shared=0.02)
    model = errormodel.fit(train)
    assert model.shared_alpha_deg == pytest.approx(0.02, rel=0.15)
    # the own parts: their sum is what the pair's difference measures (the split
    # between the two kinds is weakly determined under a shared part 7× larger)
    own2 = sum(model.fits[k]["alpha"].typical_sigma ** 2 for k in ("target", "beacon"))
    assert own2 == pytest.approx(0.002**2 + 0.003**2, rel=0.3)
    v = uncertainty.validate(model, test)
    c95 = next(c for c in v.coverage if c.level == 0.95)
    lo, hi = uncertainty.binomial_interval(c95.inside, c95.n)
    assert lo <= 0.95 <= hi
    assert v.median_mahalanobis == pytest.approx(1.18, rel=0.12)
    assert errormodel.fit(_simulated_rows(400, 5)).shared_alpha_deg == 0.0
    back = model_from_dict(json.loads(json.dumps(model.to_json())), "m.json")
    assert back.shared_alpha_deg == model.shared_alpha_deg
    assert back.sigmas(_image(60.0, 80.0, 200.0), [_image(65.0, 70.0, 60.0)],
                       62.0).shared_alpha_deg == model.shared_alpha_deg


def test_one_pair_for_both_objects_gives_a_wrong_ellipse():
    """The same draws solved with one σ pair (the pencil's for both) give ellipses far
    too wide for the target's finer d_total: the per-object σ's are what makes them
    honest (median Mahalanobis well below 1.18)."""
    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.004),))
    one = ObjectSigmas.same(Sigma(0.003, 0.004))
    rng = np.random.default_rng(8)
    per, same = [], []
    for _ in range(300):
        bs, ts = _noisy(rng, sig)
        per.append(solve_measurements(OBS, bs, ts, sigma=sig).mahalanobis(TARGET))
        same.append(solve_measurements(OBS, bs, ts, sigma=one).mahalanobis(TARGET))
    assert np.median(per) == pytest.approx(1.18, rel=0.15)
    assert np.median(same) < 0.8 * np.median(per)


def test_crlb_of_one_beacon_is_the_closed_forms_first_order_spread():
    """For one beacon and one target the bound is the closed form's covariance,
    ∂(target)/∂(measurements) Σ ∂(target)/∂(measurements)ᵀ, here by central differences
    of solve_single (not the analytic Jacobian the bound is built from)."""
    from solver.sltr import solve_single

    sig = ObjectSigmas(Sigma(0.004, 0.001), (Sigma(0.002, 0.003),))
    ob, ot = _exact([BEACONS[0], TARGET])
    x0 = np.array([float(ob.alpha_deg), float(ob.d_total), float(ot.alpha_deg),
                   float(ot.d_total)])
    cols = []
    for k, h in enumerate((1e-5, 1e-5, 1e-5, 1e-5)):
        e = np.zeros(4)
        e[k] = h
        cols.append((solve_single(OBS, BEACONS[0], **_single(x0 + e)).target
                     - solve_single(OBS, BEACONS[0], **_single(x0 - e)).target) / (2 * h))
    J = np.column_stack(cols)
    sd = np.array([0.002, 0.003 * x0[1], 0.004, 0.001 * x0[3]])
    bound = crlb(OBS, BEACONS[:1], MIRROR[1], mirror_rho=_rho(), target=TARGET, sigma=sig)
    np.testing.assert_allclose(bound[2:4, 2:4], J @ np.diag(sd**2) @ J.T, rtol=1e-5)


def test_sigma_blocks_in_measurement_files():
    base = {"observer": [0, 0], "target": {"alpha_deg": 30, "d_total": 60},
            "beacons": [{"position": [30, 25], "alpha_deg": 35, "d_total": 50}] * 2}
    one = measurements_from_dict({**base, "sigma": {"alpha_deg": 0.01, "d_total_rel": 0.002}})
    assert one.sigma == ObjectSigmas.same(Sigma(0.01, 0.002))
    per = measurements_from_dict({**base, "sigma": {
        "target": {"alpha_deg": 0.001, "d_total_rel": 0.0005},
        "beacons": [{"alpha_deg": 0.002, "d_total_rel": 0.002},
                    {"alpha_deg": 0.003, "d_total_rel": 0.001}]}})
    assert per.sigma.beacons[1] == Sigma(0.003, 0.001)
    assert measurements_from_dict(per.to_json()) == per  # written as read
    with pytest.raises(ValueError, match="sigma.beacons"):
        measurements_from_dict({**base, "sigma": {"target": {"alpha_deg": 1, "d_total_rel": .1},
                                                  "beacons": [{"alpha_deg": 1,
                                                               "d_total_rel": .1}] * 3}})


def _image(alpha: float, d: float, height_px: float) -> ImageFeatures:
    """An image of a lossless frame, its contrast and noise those of the rows above."""
    return ImageFeatures(alpha, d, height_px, 0.5, 0.01)


def test_the_sigma_law_recovers_a_known_one_and_stays_positive():
    """Errors with σ_α = 0.001°·(h/100 px)^−1 (h the image's height in pixels) and σ_d =
    0.002 flat, plus 2 % gross errors of ±0.5°: the fit finds the power (a log σ slope
    of −1 per unit log h), counts the gross errors apart, sets a tail factor ≥ 1 and
    gives a σ > 0 everywhere, even far outside the rows."""
    n = 3000
    cols = synthetic_columns(n, 3)
    rng = np.random.default_rng(4)
    for kind in ("target", "beacon"):
        h = np.asarray(cols[f"{kind}_height_px_meas"])
        err = rng.normal(0, 0.001 * (h / 100) ** -1.0)
        gross = rng.random(n) < 0.02
        err[gross] += rng.choice([-0.5, 0.5], gross.sum())
        cols[f"{kind}_alpha_err"] = err
    model = errormodel.fit(cols)
    a = model.fits["target"]["alpha"]
    x = feature_vector(np.array([100.0, 200.0]), 0.0, 0.55, noise=0.0125, jpeg_quality=0)
    s100, s200 = a.log_sigma(x)
    assert s100 == pytest.approx(0.001, rel=0.1)
    assert s100 / s200 == pytest.approx(2.0, rel=0.1)
    assert a.gross_errors == pytest.approx(0.02 * n, rel=0.3)
    assert a.tail >= 1.0
    assert model.fits["beacon"]["d_rel"].typical_sigma == pytest.approx(0.005, rel=0.15)
    far = feature_vector(np.array([1e-1, 1e5]), np.array([89.0, -89.0]), 1e-6, noise=1.0,
                         jpeg_quality=10)
    for kind in ("target", "beacon"):
        for q in ("alpha", "d_rel"):
            assert np.all(model.fits[kind][q].log_sigma(far) > 0)


def test_the_sigma_law_of_student_t_errors_is_their_scale_and_their_dof():
    """Errors σ·t₃ with σ = 0.002·(h/100 px)^−1: the law is their scale, not their RMS
    (√3 times it), within 10 %, with ν within 2–4.5; the model says how far 95 % of them
    reach (t₃'s 95 % point, 3.18, over 1.96: a tail of 1.6) and does not apply it.  Errors
    from a Gaussian give a ν over 100 (a t's that near a Gaussian's cannot be told from
    it on 3000 rows)."""
    rng = np.random.default_rng(11)
    h = rng.uniform(20.0, 400.0, 3000)
    X = np.log(h)[:, None]
    law, nu, gross = sigma_laws.gross_free_fit(X, 0.002 * (h / 100) ** -1.0
                                               * rng.standard_t(3, h.size))
    assert law(np.log([[100.0]]))[0] == pytest.approx(0.002, rel=0.1)
    assert 2.0 <= nu <= 4.5 and gross.sum() <= 6
    cols = synthetic_columns(3000, 3)
    for kind in ("target", "beacon"):
        hk = np.asarray(cols[f"{kind}_height_px_meas"])
        cols[f"{kind}_alpha_err"] = 0.002 * (hk / 100) ** -1.0 * rng.standard_t(3, hk.size)
    a = errormodel.fit(cols).fits["target"]["alpha"]
    assert a.tail == pytest.approx(3.182 / 1.96, rel=0.1) and 2.0 <= a.dof <= 4.5
    x = feature_vector(np.array([100.0]), 0.0, 0.55, noise=0.0125, jpeg_quality=0)
    assert a.sigma(x)[0] == pytest.approx(a.log_sigma(x)[0])
    _, nu_gauss, _ = sigma_laws.gross_free_fit(X, rng.normal(0.0, 0.002, h.size))
    assert nu_gauss > 100


def test_a_fit_on_too_few_rows_says_how_many_it_needs():
    with pytest.raises(ValueError, match=r"too few usable rows \(6\).*30 needed"):
        errormodel.fit(synthetic_columns(6, 0))


def test_validation_of_an_honest_model_on_held_out_rows():
    """Rows simulated from the geometry with the model's own σ's: on held-out rows the
    95 % ellipse covers within its binomial band, the median Mahalanobis is ≈ 1.18 and
    about 68 % / 95 % of each measurement's errors lie within 1σ / 2σ."""
    train, test = _simulated_rows(400, 1), _simulated_rows(400, 2)
    model = errormodel.fit(train)
    v = uncertainty.validate(model, test)
    c95 = next(c for c in v.coverage if c.level == 0.95)
    lo, hi = uncertainty.binomial_interval(c95.inside, c95.n)
    assert lo <= 0.95 <= hi
    assert v.median_mahalanobis == pytest.approx(1.18, rel=0.12)
    for kind in ("target", "beacon"):
        for q in ("alpha", "d_rel"):
            one, two = v.within[kind][q]
            assert one == pytest.approx(0.683, abs=0.06) and two == pytest.approx(0.954, abs=0.03)
            # what the law's t_ν puts there: a Gaussian's, for rows drawn Gaussian
            e1, e2 = v.expected[kind][q]
            assert e1 == pytest.approx(0.683, abs=0.03) and e2 == pytest.approx(0.954, abs=0.02)
    assert model.tail.dof > 20 and model.tail.scale == pytest.approx(1.0, abs=0.1)
    # a model whose σ's are 3× too small (its tail the honest one's) fails visibly
    small = replace(model, fits={
        k: {q: replace(f, log_sigma=replace(f.log_sigma,
                                            intercept=f.log_sigma.intercept - math.log(3)))
            for q, f in qs.items()} for k, qs in model.fits.items()})
    assert uncertainty.validate(small, test).coverage[2].fraction < 0.5
    # fitted on rows whose σ's were 3× too small, the tail says so: it widens the ellipse
    train_small = {**train, **{f"{k}_{q}": np.asarray(train[f"{k}_{q}"]) / 3
                               for k in ("target", "beacon") for q in ("alpha_err", "d_rel_err")}}
    widened = errormodel.fit(train_small)
    assert widened.tail.scale == pytest.approx(3.0, rel=0.15)
    c95 = uncertainty.validate(widened, test).coverage[2]
    assert 0.90 <= c95.fraction <= 0.99


def _simulated_rows(n: int, seed: int, shared: float = 0.0) -> dict:
    """Dataset columns of n one-beacon scenes with exact forward-model measurements plus
    Gaussian errors: target σ (0.002°, 0.05 %), beacon σ (0.003°, 0.2 %), and
    (``shared``) one offset of that σ on both α's of a scene."""
    rng = np.random.default_rng(seed)
    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
    cols: dict = {k: [] for k in ("index", "error", "observer_pan_deg", "observer_x",
                                  "observer_y", "beacon_known_x", "beacon_known_y",
                                  "target_x", "target_y")}
    for i in range(n):
        b = BEACONS[0] + rng.uniform(-5, 5, 2)
        t = TARGET + rng.uniform(-5, 5, 2)
        ob, ot = _exact([b, t])
        delta = rng.normal(0, shared) if shared else 0.0
        for kind, o, s in (("target", ot, sig.target), ("beacon", ob, sig.beacons[0])):
            ea, ed = rng.normal(0, s.alpha_deg) + delta, rng.normal(0, s.d_total_rel)
            for name, v in ((f"{kind}_alpha_meas", float(o.alpha_deg) + ea),
                            (f"{kind}_d_meas", float(o.d_total) * (1 + ed)),
                            (f"{kind}_alpha_err", ea), (f"{kind}_d_rel_err", ed),
                            (f"{kind}_d_true", float(o.d_total)),
                            (f"{kind}_off_axis_deg", float(o.alpha_deg) - 30.0),
                            (f"{kind}_incidence_deg", 30.0),
                            (f"{kind}_height_px_true", 15000 / float(o.d_total))):
                cols.setdefault(name, []).append(v)
        for name, v in (("index", i), ("error", ""), ("observer_pan_deg", 30.0),
                        ("observer_x", 0.0), ("observer_y", 0.0), ("beacon_known_x", b[0]),
                        ("beacon_known_y", b[1]), ("target_x", t[0]), ("target_y", t[1])):
            cols[name].append(v)
    return with_frame_columns(cols, rng)


def test_the_shipped_model_says_where_it_comes_from_and_what_the_renders_show():
    """The shipped model records its dataset (seed, ≥ 40 scenes) and holds what every
    accuracy benchmark of the detector says: the panel's d_total is measured finer than
    the pencil's (230 px against 45-95 px of height)."""
    model = default_error_model()
    assert default_model_path().name == "error_model.json"
    prov = model.provenance or {}
    assert prov.get("dataset_seed") is not None and prov.get("dataset_n", 0) >= 40
    s = model.sigmas(_image(60.0, 80.0, 230.0), [_image(65.0, 70.0, 70.0)], 62.0)
    assert s.target.d_total_rel < s.beacons[0].d_total_rel
    assert s.target.alpha_deg < 0.01 and s.beacons[0].alpha_deg < 0.01  # ~0.25 px or less


def test_solve_says_which_sigmas_win(tmp_path, capsys):
    meas = tmp_path / "m.json"
    assert main(["check", str(SCENES / "exp1.yaml"), "--measurements", str(meas)]) == 0
    d = json.loads(meas.read_text())
    d["sigma"] = {"alpha_deg": 0.5, "d_total_rel": 0.05}  # huge: a wide ellipse
    meas.write_text(json.dumps(d))
    capsys.readouterr()
    out = tmp_path / "s.json"
    assert main(["solve", str(meas), "--json", str(out)]) == 0
    wide = json.loads(out.read_text())["covariance"]["target_ellipse95"]["major"]
    assert "`sigma` of" in capsys.readouterr().err
    out.unlink()
    model = tmp_path / "model.json"
    model.write_text(default_model_path().read_text())
    assert main(["solve", str(meas), "--error-model", str(model), "--json", str(out)]) == 0
    err = capsys.readouterr().err
    assert "--error-model" in err and "not used" in err
    narrow = json.loads(out.read_text())["covariance"]["target_ellipse95"]["major"]
    assert narrow < wide / 2


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ideal", "bench"])
def test_the_shipped_models_rows_are_what_make_error_model_renders(kind, tmp_path,
                                                                   monkeypatch):
    """Each shipped model comes from `make error-model`: the rows its provenance records
    (scenes of its dataset's seed and spec), made again here, measure the same errors
    and features (to 1e-6, and 1e-8 near 0: the render is bit for bit the same with
    the same seed, the calibration is made afresh; the measurement's float arithmetic
    is not, across numpy and OpenCV releases: installed afresh on 2026-12-08 (numpy
    2.4.6, OpenCV 5.1.0.95) a pencil's height moved by 1e-7 px and a d_total error of
    8e-5 by 1.3e-9)."""
    from pathlib import Path

    from mirrorsim.pipelines.dataset import process_one
    from mirrorsim.pipelines.random_scenes import load_spec

    prov = default_error_model(kind).provenance
    assert prov["dataset_n"] >= 300 and len(prov["check_rows"]) == errormodel.CHECK_ROWS
    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path / "cache"))
    spec = load_spec(Path(__file__).parents[1] / prov["spec_file"])
    model = default_error_model(kind)
    for folder in ("rows", "scenes", "frames"):
        (tmp_path / folder).mkdir()
    for row in prov["check_rows"]:
        done = process_one(row["index"], prov["dataset_seed"], spec, out=str(tmp_path), spp=None,
                           variant="auto", error_model=model)
        assert done.row is not None and not done.row.error
        for c in errormodel.CHECK_COLUMNS:
            assert done.row[c] == pytest.approx(row[c], rel=1e-6, abs=1e-8), c


def test_one_bad_image_does_not_drag_the_estimate_and_is_named():
    """Three beacons, one of whose d_total is off by 5 % (a gross detector error, 25 of
    its σ's): the robust fit keeps the target within 3 σ of the truth and names the
    measurement it trusted less; clean measurements name none."""
    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
    bs, ts = _noisy(np.random.default_rng(5), sig)
    bad = [bs[0], BeaconMeasurement(bs[1].position, bs[1].alpha_deg, bs[1].d_total * 1.05),
           bs[2]]
    sol = solve_measurements(OBS, bad, ts, sigma=sig)
    assert any(name.startswith("beacon 1 d_total") for name in sol.downweighted)
    assert sol.mahalanobis(TARGET) < 3.0
    clean = solve_measurements(OBS, bs, ts, sigma=sig)
    assert clean.downweighted == ()


@pytest.mark.parametrize("bad", [0, 3])
def test_with_a_shared_offset_one_bad_alpha_is_still_the_one_named(bad):
    """Every α shifted by one shared offset (σ 0.05°, each image's own 0.003°) and one
    beacon's α off by a further 0.2° (67 of its own σ's): the fit names that beacon's α
    as the farthest off and keeps the target within 5 σ of the truth (Huber's loss
    still lets a gross error pull a little).  (With these four beacons a bad beacon 2
    is taken for a bad beacon 0, with or without the shared offset: the robust fit is
    not convex.)"""
    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),), shared_alpha_deg=0.05)
    beacons = [*BEACONS, np.array([38.0, 22.0])]
    bs, ts = _noisy(np.random.default_rng(11), sig, beacons)
    bs[bad] = BeaconMeasurement(bs[bad].position, bs[bad].alpha_deg + 0.2, bs[bad].d_total)
    sol = solve_measurements(OBS, bs, ts, sigma=sig)
    off = {n.split(" (")[0]: float(n.split("(")[1].split(" σ")[0]) for n in sol.downweighted}
    assert max(off, key=off.get) == f"beacon {bad} α" and off[f"beacon {bad} α"] > 30
    assert sol.mahalanobis(TARGET) < 5.0


def test_validation_scales_the_alpha_sigmas_by_each_rows_focal_length():
    """Rows of a camera with half the training's fx have twice the pixel-limited α
    errors: with their fx recorded, the model's σ_α's double and 95 % of the errors stay
    within 2σ (a d_total's σ follows the image's height in pixels, not fx)."""
    train, test = _simulated_rows(300, 3), _simulated_rows(300, 4)
    model = errormodel.fit(train)
    assert model.fx_px == 1500.0
    for k in ("target", "beacon"):
        test[f"{k}_alpha_err"] = np.asarray(test[f"{k}_alpha_err"]) * 2
    test["fx_px"] = [750.0] * 300
    v = uncertainty.validate(model, test)
    one, two = v.within["beacon"]["alpha"]
    assert two == pytest.approx(0.954, abs=0.04)


def test_one_beacon_sigma_for_several_beacons_round_trips():
    base = {"observer": [0, 0], "target": {"alpha_deg": 30, "d_total": 60},
            "beacons": [{"position": [30, 25], "alpha_deg": 35, "d_total": 50}] * 2}
    m = measurements_from_dict({**base, "sigma": {
        "target": {"alpha_deg": 0.001, "d_total_rel": 0.0005},
        "beacons": {"alpha_deg": 0.002, "d_total_rel": 0.002}}})
    assert measurements_from_dict(m.to_json()) == m


def test_beacon_position_sigma_widens_the_ellipse_and_names_the_offsets():
    """Beacons known to 0.2 cm: the target's ellipse grows (the positions' uncertainty is
    in it), the covariance names each beacon's offset, and solve prints the
    self-calibration with it (the nuisances' σ's come from their own rows)."""
    from mirrorsim.cli.tables import solution_summary

    sig = ObjectSigmas(Sigma(0.002, 0.0005), (Sigma(0.003, 0.002),))
    bs, ts = _noisy(np.random.default_rng(2), sig)
    exact = solve_measurements(OBS, bs, ts, sigma=sig,
                               calibration=SelfCalibration(("pan", "scale")))
    loose = solve_measurements(OBS, bs, ts, sigma=sig,
                               calibration=SelfCalibration(("pan", "scale"), 0.2))
    assert np.trace(loose.target_covariance) > np.trace(exact.target_covariance)
    assert loose.params_order[-1] == "beacon2_offset_y" and len(loose.params_order) == 12
    assert "pan offset" in solution_summary("m.json", loose)


def test_errormodel_help_states_the_fits_minimum_and_its_stability_bounds(capsys):
    with pytest.raises(SystemExit):
        main(["errormodel", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"{errormodel.MIN_ROWS} usable rows of each kind" in text
    assert f"factor {errormodel.SPAN_REFUSE:.0f}" in text
    assert f"factor {errormodel.UNSTABLE_REFUSE:.0f}" in text
    assert f"beyond {errormodel.UNSTABLE_WARN:.0f}" in text
    assert f"{sigma_laws.STABILITY_DRAWS} resamples" in text


def test_an_unstable_law_is_refused_and_a_wide_one_warned():
    """A law whose σ's would span six orders of magnitude over its rows (errors from
    1e-7° to 0.1°, told apart by their contrast) is refused, naming it; a law its rows
    barely determine (40 rows for six coefficients, whose contrast is the same but for
    two, whose errors are 4× the others': resampled, the slope comes and goes with
    them) fits with a warning;
    400 rows of a law that truly varies 30-fold with the image's height fit without
    one."""
    rng = np.random.default_rng(8)
    cols = synthetic_columns(200, 8)
    c = rng.uniform(0.01, 0.9, 200)
    for kind in ("target", "beacon"):
        cols[f"{kind}_contrast"] = c
        cols[f"{kind}_alpha_err"] = rng.normal(0, 1e-7 * (0.9 / c) ** 3.5)
    with pytest.raises(ValueError, match=r"target alpha law is unstable: its σ's .* span"):
        errormodel.fit(cols)
    cols = synthetic_columns(40, 8)
    lone = np.zeros(40, bool)
    lone[:2] = True
    for kind in ("target", "beacon"):
        cols[f"{kind}_contrast"] = np.where(lone, 0.05, 0.5)
        cols[f"{kind}_alpha_err"] = 0.001 * np.where(lone, 4.0, rng.normal(0, 1.0, 40))
    model = errormodel.fit(cols)
    assert any("refitted on resamples" in w for w in model.provenance["warnings"])
    assert "warning: a loosely determined law" in error_model_summary(model)
    cols = synthetic_columns(400, 9)
    for kind in ("target", "beacon"):
        h = rng.uniform(20, 600, 400)
        cols[f"{kind}_height_px_meas"] = h
        cols[f"{kind}_d_rel_err"] = rng.normal(0, 0.3 / h)
    model = errormodel.fit(cols)
    # a table made by hand holds no geometry to solve its rows again: no tail, said so
    assert model.tail.gaussian and "observer_x" in model.provenance["tail_not_fitted"]
    assert "warnings" not in model.provenance
    assert "warning" not in error_model_summary(model)


def test_a_tail_draws_its_ellipses_at_a_student_t_s_radii():
    """The Tail's radius is the quantile of √(2F₂,ν)·scale, worked here by scipy (the
    code has its closed form), its level the inverse, and ν → ∞ gives χ₂'s."""
    from scipy.stats import f

    from solver.measurements import Tail

    for scale, dof in ((0.44, 1.28), (1.0, 3.0), (2.0, 40.0)):
        t = Tail(scale, dof)
        for p in (0.5, 0.9, 0.95):
            assert t.radius(p) == pytest.approx(scale * math.sqrt(2 * f.ppf(p, 2, dof)), rel=1e-9)
            # the radius's level by the F CDF's closed form, 1 − (1 + s²/ν)^(−ν/2)
            s2 = (t.radius(p) / scale) ** 2
            assert 1 - (1 + s2 / dof) ** (-dof / 2) == pytest.approx(p, abs=1e-12)
    # the density integrates to 1 and is a Gaussian's radius's as ν → ∞
    r = np.linspace(0, 2000, 2_000_001)
    assert np.trapezoid(Tail(0.5, 3.0).density(r), r) == pytest.approx(1.0, abs=1e-3)
    assert np.allclose(Tail().density(r[:5000]), r[:5000] * np.exp(-r[:5000] ** 2 / 2))
    assert Tail().radius(0.95) == pytest.approx(math.sqrt(-2 * math.log(0.05)), rel=1e-12)
    assert Tail(1.0, 1e8).radius(0.95) == pytest.approx(Tail().radius(0.95), rel=1e-6)
    assert Tail.from_json(Tail(0.5, 2.0).to_json()) == Tail(0.5, 2.0)
    assert Tail.from_json(Tail().to_json()) == Tail() and Tail.from_json(None).gaussian


def test_a_tail_is_fitted_back_from_distances_drawn_from_it():
    """Distances of truths drawn from a scaled 2-D Student-t (scale 2, ν 2) give that
    scale and ν back; Gaussian ones a scale near 1 and a large ν; and distances half
    what the σ's say leave the scale at 1: a tail never narrows an ellipse."""
    rng = np.random.default_rng(3)
    n = 4000
    x = rng.standard_normal((n, 2)) / np.sqrt(rng.chisquare(2.0, n) / 2.0)[:, None]
    t = sigma_laws.fit_tail(2.0 * np.linalg.norm(x, axis=1))
    assert t.scale == pytest.approx(2.0, rel=0.06) and t.dof == pytest.approx(2.0, rel=0.15)
    g = sigma_laws.fit_tail(np.linalg.norm(rng.standard_normal((n, 2)), axis=1))
    assert g.scale == pytest.approx(1.0, rel=0.05) and g.dof > 30
    half = sigma_laws.fit_tail(0.5 * np.linalg.norm(rng.standard_normal((n, 2)), axis=1))
    assert half.scale == 1.0 and half.radius(0.95) >= Tail().radius(0.95)
    assert sigma_laws.fit_tail(np.ones(10)).gaussian  # too few to fit: at their word


def test_the_solution_carries_its_sigmas_tail_to_its_ellipse_and_its_sentence():
    from mirrorsim.cli.tables import mahalanobis_sentence
    from solver.measurements import Tail
    from solver.sltr import Solution

    tail = Tail(0.44, 1.28)
    sig = ObjectSigmas(Sigma(0.01, 0.002), (Sigma(0.01, 0.002),), tail=tail)
    b = [BeaconMeasurement((60.0, 40.0), 40.0, 90.0)]
    sol = solve_measurements((0.0, 0.0), b, [(35.0, 110.0)], sigma=sig)
    plain = solve_measurements((0.0, 0.0), b, [(35.0, 110.0)], sigma=replace(sig, tail=Tail()))
    assert sol.tail == tail and plain.tail.gaussian
    ratio = tail.radius(0.95) / Tail().radius(0.95)
    assert sol.ellipse95()[0] == pytest.approx(ratio * plain.ellipse95()[0], rel=1e-12)
    back = Solution.from_json(json.loads(json.dumps(sol.to_json())))
    assert back.tail == tail and back.ellipse95()[0] == pytest.approx(sol.ellipse95()[0])
    # 4 σ: outside a Gaussian's 95 % ellipse, inside this tail's (its edge at 5.15 σ)
    said = mahalanobis_sentence(4.0, tail)
    assert "inside" in said and "5.15 σ" in said
    assert "outside" in mahalanobis_sentence(4.0) and "outside" in mahalanobis_sentence(5.2, tail)


def test_the_model_summary_says_what_its_tail_says_of_its_sigmas():
    from mirrorsim.cli.analysis_tables import tail_line
    from solver.measurements import Tail

    assert "heavier-tailed" in tail_line(Tail(0.44, 1.28)) and "5.15 σ" in tail_line(
        Tail(0.44, 1.28))
    assert "smaller than the σ's say" in tail_line(Tail(0.387, 1e4))
    assert "larger than the σ's say" in tail_line(Tail(2.0, 1e4))
    assert "taken as Gaussian" in tail_line(Tail())
    assert tail_line(Tail(1.0, 1e4)).endswith("at 2.45 σ, as a Gaussian's")


def test_the_within_sigma_reference_is_each_laws_own_student_t():
    """A law fitted with ν = 2 holds fewer of its errors within 1σ and 2σ of its scale
    than a Gaussian's σ: t₂'s 2F(1)−1 = 1/√3 and 2F(2)−1 = 2/√6 (closed forms of t₂)."""
    model = errormodel.fit(_simulated_rows(200, 5))
    heavy = replace(model, fits={k: {q: replace(f, dof=2.0) for q, f in qs.items()}
                                 for k, qs in model.fits.items()})
    v = uncertainty.validate(heavy, _simulated_rows(60, 6))
    e1, e2 = v.expected["target"]["d_rel"]
    assert e1 == pytest.approx(1 / math.sqrt(3), abs=1e-9)
    assert e2 == pytest.approx(2 / math.sqrt(6), abs=1e-9)
    assert "(0.577), within 2σ" in "\n".join(uncertainty.report_lines(v))
