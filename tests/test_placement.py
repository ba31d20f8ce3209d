"""The paper's placement geometry, paths, Algorithm 1, ref. [26] and the best beacon."""

import math

import numpy as np
import pytest

from solver.errors import SolverError
from solver.lsq import solve_lsq, solve_measurements
from solver.measurements import BeaconMeasurement, Sigma
from solver.placement import (
    MirrorPrior,
    algorithm1,
    best_beacon,
    expected_target_error,
    orientation_from_beacons,
    paper_placement,
    path_lengths,
    path_points,
    polyline_length,
    region_area,
)
from solver.sltr import observe


def test_paper_step_and_width_by_slopes():
    """Eqs 9–18 evaluated literally with tan() slopes, as the paper writes them."""
    alpha, d, s, eps = 66.0, 90.0, 18.2, 5.0
    g = paper_placement(alpha, d, s, eps_deg=eps)
    ta, tb = math.tan(math.radians(alpha)), math.tan(math.radians(alpha - 2 * eps))
    xr, yr = d * math.cos(math.radians(alpha)), d * math.sin(math.radians(alpha))
    th = math.radians(alpha - eps)
    xc, yc = xr - s / 2 * math.cos(th), yr - s / 2 * math.sin(th)  # eq 9
    x1 = (xc * tb - xr * ta + yr - yc) / (tb - ta)  # eq 13a
    y1 = ta * x1 + yr - xr * ta  # eq 13b
    assert g.b == pytest.approx(math.hypot(x1 - xr, y1 - yr), rel=1e-9)  # eq 14
    t90 = math.tan(math.radians(90 - alpha))
    x2 = (xc * tb - xr * t90 + yr - yc) / (tb - t90)  # eq 17a
    y2 = t90 * x2 + yr - xr * t90  # eq 17b
    assert g.half_a == pytest.approx(math.hypot(x2 - xr, y2 - yr), rel=1e-9)  # eq 18
    assert g.n_beacons == pytest.approx(2 * d / g.b)  # eq 8


def test_section7_claim_holds_for_the_formulas_not_for_exact_visibility():
    o = np.zeros(2)
    ds = (50.0, 100.0, 400.0)
    lit = [paper_placement(66.0, d, 18.2, eps_deg=5.0).area for d in ds]
    assert max(lit) - min(lit) < 1e-9  # the paper's triangle: independent of d_total
    exact = [region_area(o, 66.0, d, s=18.2, eps_deg=5.0) for d in ds]
    # the exact region shrinks with distance (the mirror subtends a smaller angle)
    assert exact[0] > exact[1] > exact[2] and exact[0] > 1.5 * exact[2]


def test_path_lengths_match_the_polylines():
    for a, b, n in [(2.9, 4.6, 20), (5.0, 1.0, 7), (1.0, 1.0, 1)]:
        eq = path_lengths(a, b, n)
        for kind in ("linear", "rectangular", "sawtooth"):
            pts = path_points(kind, (0, 0), 66.0, a=a, b=b, n=n)
            # the linear path of eq 19 walks n−1 steps down one side and back the other
            assert polyline_length(pts) == pytest.approx(eq[kind], rel=1e-12), kind


def test_path_lengths_known_answers():
    """Eqs 19–21 by hand for a = 3, b = 4, n = 3: linear a + 2(n−1)b = 3 + 16; rectangular
    a + (n−1)(a + b) = 3 + 14; sawtooth a + (n−1)(a + √(a² + b²)) = 3 + 2·8."""
    assert path_lengths(3.0, 4.0, 3) == pytest.approx(
        {"linear": 19.0, "rectangular": 17.0, "sawtooth": 19.0}, rel=1e-12)


def test_rectangular_shortest_claim_holds_for_b_greater_than_a_only():
    # values worked by hand: a = 1, b = 2, n = 10: linear 1 + 18·2 = 37,
    # rectangular 1 + 9·3 = 28, saw-tooth 1 + 9·(1 + √5) = 30.125
    L = path_lengths(1.0, 2.0, 10)
    assert L["linear"] == pytest.approx(37.0)
    assert L["rectangular"] == pytest.approx(28.0)
    assert L["sawtooth"] == pytest.approx(1 + 9 * (1 + math.sqrt(5)))
    # b < a: the linear path is shorter (a = 3, b = 1, n = 10: 21 vs 39)
    L = path_lengths(3.0, 1.0, 10)
    assert (L["linear"], L["rectangular"]) == pytest.approx((21.0, 39.0))
    # saw-tooth < linear fails for b only slightly above a (a = 1, b = 1.1, n = 10:
    # 1 + 9·(1 + 1.487) = 23.38 > 1 + 18·1.1 = 20.8)
    L = path_lengths(1.0, 1.1, 10)
    assert L["sawtooth"] == pytest.approx(1 + 9 * (1 + math.hypot(1, 1.1)))
    assert L["sawtooth"] > L["linear"] == pytest.approx(20.8)


def test_algorithm1_beacon_count_and_sides():
    steps = algorithm1((0, 0), 66.0, 90.0, s=18.2, eps_deg=5.0)
    g = paper_placement(66.0, 90.0, 18.2, eps_deg=5.0)
    assert len(steps) == math.floor(90.0 / g.b)
    assert 2 * len(steps) == pytest.approx(g.n_beacons, abs=2)  # eq 8, up to rounding
    u = np.array([math.cos(math.radians(66)), math.sin(math.radians(66))])
    for st in steps:
        side = [u[0] * b[1] - u[1] * b[0] for b in st["beacons"]]
        assert side[0] * side[1] < 0  # one beacon on each side of the observation line


def test_two_beacon_orientation_of_known_reflector():
    o, r, yaw = np.zeros(2), np.array([27.5, 65.0]), 38.0
    beacons = [(32, 62.5), (25, 60)]
    alphas = [observe(o, r, yaw, point=b).alpha_deg for b in beacons]
    assert orientation_from_beacons(o, r, beacons, alphas_deg=alphas,
                                    initial_yaw_deg=30.0) == pytest.approx(yaw, abs=1e-9)


def test_expected_error_matches_least_squares_and_best_is_much_better():
    """EXP3's own beacon ≈ 2.4 cm at σ = (0.01°, 0.2 %), good positions ≈ 0.2 (figures
    fixed before this code was written)."""
    o, m, yaw = np.zeros(2), np.array([16.0, 34.5]), 38.3
    ot = observe(o, m, yaw, point=(65.5, 42.7))
    sig = Sigma(0.01, 0.002)
    err, seen = expected_target_error(o, ot.alpha_deg, ot.d_total, beacons=np.array([[17.0, 33.5]]),
                                      poses=[(m, yaw)], sigma=sig, mirror_size=18.2, min_depth=0.0)
    assert seen[0] == 1.0 and err[0] == pytest.approx(2.4, abs=0.1)
    # the same figure from the solver's own covariance (least squares with σ's) on the
    # exact measurements of this pose: sqrt(trace) of the target block
    ob = observe(o, m, yaw, point=(17.0, 33.5))
    sol = solve_measurements(o, [BeaconMeasurement((17.0, 33.5), ob.alpha_deg, ob.d_total)],
                             [(ot.alpha_deg, ot.d_total)], sigma=sig)
    assert err[0] == pytest.approx(np.sqrt(np.trace(sol.target_covariance)), rel=1e-6)
    lsq = solve_lsq(o, [BeaconMeasurement((17.0, 33.5), ob.alpha_deg, ob.d_total)],
                    [(ot.alpha_deg, ot.d_total)], sigma=sig)
    assert err[0] == pytest.approx(np.sqrt(np.trace(lsq.target_covariance)), rel=1e-4)
    best = best_beacon(o, ot.alpha_deg, ot.d_total, poses=[(m, yaw)], sigma=sig, mirror_size=18.2,
                       board=(80, 80), step=1.0)
    assert best.rmse < 0.3
    # with a prior of mirror poses the best position is still an order of magnitude better
    prior = MirrorPrior(d1=float(ot.d1), yaw_deg=yaw, d1_spread=2, yaw_spread_deg=3)
    poses = prior.poses(o, ot.alpha_deg)
    best = best_beacon(o, ot.alpha_deg, ot.d_total, poses=poses, sigma=sig, mirror_size=18.2,
                       board=(80, 80), step=1.0)
    paper, _ = expected_target_error(o, ot.alpha_deg, ot.d_total, beacons=np.array([[17.0, 33.5]]),
                                     poses=poses, sigma=sig, mirror_size=18.2, min_depth=0.0)
    assert best.rmse < paper[0] / 10 and best.seen_fraction == 1.0


def test_best_beacon_falls_back_to_fewer_poses_where_the_test_refuses_every_fully_seen():
    """A wide prior leaves few positions seen under every pose; where ``accept`` refuses
    them all, the best position seen under fewer poses is chosen (it stopped with an
    error after 500 candidates), and where it refuses every position, one line says so."""
    o, m, yaw = np.zeros(2), np.array([16.0, 34.5]), 38.3
    ot = observe(o, m, yaw, point=(65.5, 42.7))
    sig = Sigma(0.01, 0.002)
    poses = MirrorPrior(d1=float(ot.d1), yaw_deg=yaw, d1_spread=2,
                        yaw_spread_deg=3).poses(o, ot.alpha_deg)
    free = best_beacon(o, ot.alpha_deg, ot.d_total, poses=poses, sigma=sig, mirror_size=18.2,
                       board=(80, 80), step=1.0)
    full = free.seen >= 1.0
    assert full.any() and (free.seen[(free.seen > 0) & ~full]).any()
    # refuse every position seen under all poses
    xs, ys = np.meshgrid(free.xs, free.ys)
    refused = {(float(x), float(y)) for x, y in zip(xs[full], ys[full], strict=True)}
    calls = []

    def accept(p):
        calls.append(tuple(p))
        return (float(p[0]), float(p[1])) not in refused

    got = best_beacon(o, ot.alpha_deg, ot.d_total, poses=poses, sigma=sig, mirror_size=18.2,
                      board=(80, 80), step=1.0,
                      accept=accept)
    assert got.seen_fraction < 1.0 and tuple(got.position) not in refused
    assert got.seen_fraction == free.seen[free.seen < 1.0].max()
    assert len(calls) == len(set(calls))  # no position tested twice
    with pytest.raises(SolverError, match="no beacon position on the board passes"):
        best_beacon(o, ot.alpha_deg, ot.d_total, poses=poses, sigma=sig, mirror_size=18.2,
                    board=(80, 80), step=1.0,
                    accept=lambda _p: False)
