"""The SLTR solver: forward model, exact single-beacon solution, least squares."""

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from solver.geometry import line_normal, signed_distance, unit
from solver.lsq import solve_lsq
from solver.measurements import BeaconMeasurement, Sigma
from solver.sltr import SolverError, locate, observe, solve_single

c = st.floats(-100, 100, allow_nan=False)


@settings(max_examples=300)
@given(c, c, st.floats(0, 180), c, c, c, c)
def test_observe_then_solve_recovers_mirror_and_target(mx, my, yaw, bx, by, tx, ty):
    o = np.zeros(2)
    m = np.array([mx, my])
    so = signed_distance(o, m, yaw)
    sb, st_ = signed_distance((bx, by), m, yaw), signed_distance((tx, ty), m, yaw)
    # valid geometry: both in front of the mirror, not on it, not too grazing a ray
    assume(abs(so) > 1 and abs(sb) > 1 and abs(st_) > 1 and so * sb > 0 and so * st_ > 0)
    ob = observe(o, m, yaw, point=(bx, by))
    ot = observe(o, m, yaw, point=(tx, ty))
    assume(abs(np.dot(unit(ot.alpha_deg), line_normal(yaw))) > 0.05)
    sol = solve_single(o, (bx, by), ob.alpha_deg, beacon_d_total=ob.d_total,
                       target_alpha_deg=ot.alpha_deg, target_d_total=ot.d_total)
    assert np.allclose(sol.target, (tx, ty), atol=1e-9 * max(1, np.hypot(tx, ty)) * 10)
    dyaw = (sol.mirror.yaw_deg - yaw + 90) % 180 - 90
    assert abs(dyaw) < 1e-9
    assert abs(signed_distance(sol.mirror.point, m, yaw)) < 1e-8
    assert np.allclose(sol.target_reflection_point, ot.reflection_point, atol=1e-8)


def test_closed_form_solves_eqs_6a_6c():
    """With the beacon's measurements, (d1, d2, θ) satisfy eqs 6a–6c exactly, the second
    leg at bearing 2θ − α (the physical form of the paper's α − 2θ)."""
    o, b = np.zeros(2), np.array([32.0, 62.5])
    ob = observe(o, (27.5, 65), 38.0, point=b)
    ot = observe(o, (27.5, 65), 38.0, point=(55, 70))
    sol = solve_single(o, b, ob.alpha_deg, beacon_d_total=ob.d_total,
                       target_alpha_deg=ot.alpha_deg, target_d_total=ot.d_total)
    th = sol.mirror.yaw_deg
    r = sol.beacon_reflection_points[0]
    d1 = float(np.linalg.norm(r - o))
    d2 = float(np.linalg.norm(b - r))
    a = ob.alpha_deg
    x = o[0] + d1 * math.cos(math.radians(a)) + d2 * math.cos(math.radians(2 * th - a))
    y = o[1] + d1 * math.sin(math.radians(a)) + d2 * math.sin(math.radians(2 * th - a))
    assert (x, y) == pytest.approx(tuple(b), abs=1e-10)  # eqs 6a, 6b
    assert d1 + d2 == pytest.approx(ob.d_total, abs=1e-10)  # eq 6c
    # the paper's literal α − 2θ does not land on the beacon here
    y_paper = o[1] + d1 * math.sin(math.radians(a)) + d2 * math.sin(math.radians(a - 2 * th))
    assert abs(y_paper - b[1]) > 1.0


def test_interface_example_solution():
    """The documented solution example for exp1: mirror point (29.08, 66.24)."""
    o = np.zeros(2)
    ob = observe(o, (27.5, 65), 38.0, point=(32, 62.5))
    ot = observe(o, (27.5, 65), 38.0, point=(55, 70))
    sol = solve_single(o, (32, 62.5), ob.alpha_deg, beacon_d_total=ob.d_total,
                       target_alpha_deg=ot.alpha_deg, target_d_total=ot.d_total)
    assert sol.mirror.point == pytest.approx([29.08, 66.24], abs=0.01)
    assert sol.target_reflection_point == pytest.approx([28.29, 65.62], abs=0.01)


def test_locate_inverts_observe():
    o = np.array([1.0, 2.0])
    p = np.array([40.0, 30.0])
    ob = observe(o, (20, 50), 10.0, point=p)
    assert np.allclose(locate(o, (20, 50), 10.0, alpha_deg=ob.alpha_deg, d_total=ob.d_total), p)


@pytest.mark.parametrize("case, args, match", [
    ("beacon on the mirror line", dict(b=(27.5, 65.0)), "mirror line|coincides"),
    ("negative beacon distance", dict(db=-5.0), "positive"),
    ("zero target distance", dict(dt=0.0), "positive"),
    ("image nearer than the beacon", dict(db=10.0), "shorter"),
    ("target ray parallel to the mirror", dict(at=38.0), "parallel"),
    ("target short of the mirror", dict(dt=20.0), "reach past"),
])
def test_degenerate_input_raises_our_error(case, args, match):
    o = np.zeros(2)
    b = np.array(args.get("b", (32.0, 62.5)))
    ob = observe(o, (27.5, 65), 38.0, point=(32, 62.5))
    ot = observe(o, (27.5, 65), 38.0, point=(55, 70))
    ab = args.get("ab", ob.alpha_deg)
    db = args.get("db", ob.d_total)
    if case == "beacon on the mirror line":
        ab, db = math.degrees(math.atan2(b[1], b[0])), float(np.hypot(*b))
    with pytest.raises(SolverError, match=match):
        solve_single(o, b, ab, beacon_d_total=db, target_alpha_deg=args.get("at", ot.alpha_deg),
                     target_d_total=args.get("dt", ot.d_total))


def test_observe_refuses_point_behind_mirror():
    with pytest.raises(SolverError, match="behind"):
        observe((0, 0), (10, 10), 0.0, point=(5, 20))


def _measure(o, m, yaw, beacons, target, sigma=None, rng=None):
    out = []
    for b in beacons:
        ob = observe(o, m, yaw, point=b)
        a, d = float(ob.alpha_deg), float(ob.d_total)
        if rng is not None:
            a += rng.normal(0, sigma.alpha_deg)
            d *= 1 + rng.normal(0, sigma.d_total_rel)
        out.append(BeaconMeasurement(tuple(b), a, d))
    ot = observe(o, m, yaw, point=target)
    a, d = float(ot.alpha_deg), float(ot.d_total)
    if rng is not None:
        a += rng.normal(0, sigma.alpha_deg)
        d *= 1 + rng.normal(0, sigma.d_total_rel)
    return out, [(a, d)]


def test_least_squares_agrees_with_closed_form_on_one_beacon():
    o, m, yaw = np.zeros(2), (16.0, 34.5), 38.3
    rng = np.random.default_rng(3)
    sig = Sigma(0.05, 0.005)
    for _ in range(5):
        bs, ts = _measure(o, m, yaw, [(17, 33.5)], (65.5, 42.7), sig, rng)
        cf = solve_single(o, bs[0].position, bs[0].alpha_deg, beacon_d_total=bs[0].d_total,
                          target_alpha_deg=ts[0][0], target_d_total=ts[0][1])
        ls = solve_lsq(o, bs, ts, sigma=sig)
        assert np.allclose(ls.target, cf.target, atol=1e-8)
        assert abs((ls.mirror.yaw_deg - cf.mirror.yaw_deg + 90) % 180 - 90) < 1e-8


def test_closed_form_covariance_equals_least_squares():
    from solver.lsq import solve_measurements

    o = np.zeros(2)
    bs, ts = _measure(o, (16.0, 34.5), 38.3, [(17, 33.5)], (65.5, 42.7))
    sig = Sigma(0.01, 0.002)
    cf = solve_measurements(o, bs, ts, sigma=sig)
    ls = solve_lsq(o, bs, ts, sigma=sig)
    assert cf.method.startswith("closed form")
    assert np.allclose(cf.covariance, ls.covariance, rtol=1e-6, atol=1e-12)
    assert np.allclose(cf.target, ls.target, atol=1e-9)


def test_covariance_matches_monte_carlo_spread():
    o, m, yaw = np.zeros(2), (27.5, 65.0), 38.0
    beacons, target = [(32, 62.5), (22, 55)], (55, 70)
    sig = Sigma(0.05, 0.005)
    rng = np.random.default_rng(11)
    bs0, ts0 = _measure(o, m, yaw, beacons, target)
    predicted = solve_lsq(o, bs0, ts0, sigma=sig).target_covariance
    est = []
    for _ in range(1000):
        bs, ts = _measure(o, m, yaw, beacons, target, sig, rng)
        est.append(solve_lsq(o, bs, ts, sigma=sig).target)
    emp = np.cov(np.array(est).T)
    # compare the spreads (trace) and the orientation-free size (det) within 10 %
    assert np.trace(emp) == pytest.approx(np.trace(predicted), rel=0.10)
    assert np.sqrt(np.linalg.det(emp)) == pytest.approx(np.sqrt(np.linalg.det(predicted)),
                                                        rel=0.10)


def test_more_beacons_reduce_error_as_theory_says():
    """Independent, identically placed beacon observations: variance falls as 1/N for
    the mirror part; with the target's own noise fixed, the total error falls towards
    the target-only floor.  Checked on the covariance and on a Monte Carlo."""
    o, m, yaw = np.zeros(2), (27.5, 65.0), 38.0
    target = (55, 70)
    sig = Sigma(0.05, 0.005)
    rng = np.random.default_rng(5)
    err = {}
    for n in (1, 4, 16):
        beacons = [(32, 62.5)] * n  # n observations of one beacon
        bs, ts = _measure(o, m, yaw, beacons, target)
        cov = solve_lsq(o, bs, ts, sigma=sig).covariance
        err[n] = cov
        mc = []
        for _ in range(300):
            bs, ts = _measure(o, m, yaw, beacons, target, sig, rng)
            mc.append(solve_lsq(o, bs, ts, sigma=sig).target)
        rms = np.sqrt(np.mean(np.sum((np.array(mc) - target) ** 2, axis=1)))
        assert rms == pytest.approx(np.sqrt(np.trace(cov[2:, 2:])), rel=0.15)
    # the mirror's yaw and offset variances scale as 1/N exactly
    for n in (4, 16):
        assert err[n][0, 0] == pytest.approx(err[1][0, 0] / n, rel=1e-6)
        assert err[n][1, 1] == pytest.approx(err[1][1, 1] / n, rel=1e-6)
    assert np.trace(err[16][2:, 2:]) < np.trace(err[4][2:, 2:]) < np.trace(err[1][2:, 2:])


def test_solution_json_and_ellipse():
    o = np.zeros(2)
    bs, ts = _measure(o, (27.5, 65.0), 38.0, [(32, 62.5)], (55, 70))
    sol = solve_lsq(o, bs, ts, sigma=Sigma(0.01, 0.002))
    j = json.loads(json.dumps(sol.to_json()))
    major, minor, _ = sol.ellipse95()
    assert major >= minor > 0
    # the 95 % ellipse's area is π·5.991·sqrt(det Σ)
    area = math.pi * major * minor
    assert area == pytest.approx(math.pi * 5.991465 * math.sqrt(np.linalg.det(
        sol.target_covariance)), rel=1e-5)
    assert np.allclose(j["covariance"]["target"], sol.target_covariance)
    assert j["mirror"]["yaw_deg"] == pytest.approx(38.0, abs=1e-9)
