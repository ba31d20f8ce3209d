"""SLTR in three dimensions (solver/sltr3d.py): the forward model against a hand-worked
reflection and pyroomacoustics' image sources; the closed form recovering leaning
mirrors and raised targets; the planar solver as its special case."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solver.errors import SolverError
from solver.sltr import solve_single
from solver.sltr3d import MirrorPlane, locate3, observe3, solve_single3

CAMERA = np.array([0.0, 0.0, 12.0])  # the board's corner, the lens 12 cm up


def _scene(rng: np.random.Generator, lean_range: float = 4.0, z_range: float = 15.0):
    """A leaning mirror in front of the camera, and a beacon and a target before its
    face, raised 0..z_range cm (drawn at random)."""
    centre = np.array([rng.uniform(25, 60), rng.uniform(45, 75), 0.0])
    yaw, lean = rng.uniform(-50, 50), rng.uniform(-lean_range, lean_range)
    plane = MirrorPlane.from_pose(centre, yaw, lean, toward=CAMERA)
    u = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw)), 0.0])
    face = np.array([plane.normal[0], plane.normal[1], 0.0])
    face /= np.linalg.norm(face)
    points = [centre + rng.uniform(-12, 12) * u + rng.uniform(6, 30) * face
              + np.array([0.0, 0.0, rng.uniform(0, z_range)]) for _ in range(2)]
    return plane, yaw, lean, points


def _seen(o: np.ndarray, plane: MirrorPlane, p: np.ndarray) -> tuple[float, float, float]:
    ob = observe3(o, plane, p)
    return ob.alpha_deg, ob.elevation_deg, ob.d_total


def test_a_hand_worked_leaning_reflection():
    """The plane z = y (a mirror along x leaning 45°, facing −y and up) swaps a point's
    y and z: (0, −10, 0) has its image at (0, 0, −10); seen from (0, −30, 0) that is
    √(30² + 10²) away at 18.43° below the horizontal."""
    plane = MirrorPlane.from_pose((0.0, 0.0, 0.0), 0.0, 45.0, toward=(0.0, -30.0, 0.0))
    assert plane.normal == pytest.approx([0.0, -math.sqrt(0.5), math.sqrt(0.5)], abs=1e-15)
    assert (plane.lean_deg, plane.yaw_deg) == pytest.approx((45.0, 0.0), abs=1e-12)
    ob = observe3((0.0, -30.0, 0.0), plane, (0.0, -10.0, 0.0))
    assert ob.virtual == pytest.approx([0.0, 0.0, -10.0], abs=1e-12)
    assert ob.d_total == pytest.approx(math.hypot(30.0, 10.0), abs=1e-12)
    assert ob.elevation_deg == pytest.approx(-math.degrees(math.atan(10 / 30)), abs=1e-12)
    assert ob.alpha_deg == pytest.approx(90.0, abs=1e-12)
    assert ob.d1 + ob.d2 == pytest.approx(ob.d_total, abs=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_the_closed_form_recovers_a_leaning_mirror_and_a_raised_target(seed):
    rng = np.random.default_rng(20261206 + seed)
    plane, yaw, lean, (beacon, target) = _scene(rng)
    sol = solve_single3(CAMERA, beacon, _seen(CAMERA, plane, beacon),
                        target_seen=_seen(CAMERA, plane, target))
    assert sol.target == pytest.approx(target, abs=1e-9)
    assert sol.plane.normal == pytest.approx(plane.normal, abs=1e-12)
    assert sol.plane.rho == pytest.approx(plane.rho, abs=1e-9)
    assert (sol.plane.lean_deg, sol.plane.yaw_deg) == pytest.approx((lean, yaw % 180),
                                                                    abs=1e-9)
    # the reflection point lies on the plane and on the camera's ray to the image
    r = sol.target_reflection_point
    assert r @ plane.normal == pytest.approx(plane.rho, abs=1e-9)
    assert locate3(CAMERA, plane, _seen(CAMERA, plane, target)) == pytest.approx(target,
                                                                                abs=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_the_planar_solver_is_its_upright_special_case(seed):
    """An upright mirror (lean 0): the 3-D solve's target and yaw are the planar
    solver's on the horizontal projections (α, d_total·cos ε), to 1e-9 cm; and on the
    camera's own plane (ε = 0) the two are the same numbers."""
    rng = np.random.default_rng(7000 + seed)
    plane, _, _, (beacon, target) = _scene(rng, lean_range=0.0)
    bs, ts = _seen(CAMERA, plane, beacon), _seen(CAMERA, plane, target)
    sol3 = solve_single3(CAMERA, beacon, bs, target_seen=ts)

    def flat(seen):
        return seen[0], seen[2] * math.cos(math.radians(seen[1]))

    sol2 = solve_single(CAMERA[:2], beacon[:2], flat(bs)[0], beacon_d_total=flat(bs)[1],
                        target_alpha_deg=flat(ts)[0], target_d_total=flat(ts)[1])
    assert sol3.target[:2] == pytest.approx(sol2.target, abs=1e-9)
    assert sol3.target[2] == pytest.approx(target[2], abs=1e-9)
    assert sol3.plane.yaw_deg == pytest.approx(sol2.mirror.yaw_deg % 180, abs=1e-9)
    level = [np.array([*p[:2], CAMERA[2]]) for p in (beacon, target)]
    bl, tl = _seen(CAMERA, plane, level[0]), _seen(CAMERA, plane, level[1])
    assert (bl[1], tl[1]) == pytest.approx((0.0, 0.0), abs=1e-12)
    sol2 = solve_single(CAMERA[:2], beacon[:2], bl[0], beacon_d_total=bl[2],
                        target_alpha_deg=tl[0], target_d_total=tl[2])
    assert solve_single3(CAMERA, level[0], bl, target_seen=tl).target[:2] == pytest.approx(
        sol2.target, abs=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_images_are_pyroomacoustics_image_sources_in_3d(seed):
    """An upright mirror as one wall of a 3-D room (pyroomacoustics: a polygon extruded):
    each raised point's image from observe3 is the library's image source across that
    wall (within its float32: 1 µm)."""
    pra = pytest.importorskip("pyroomacoustics")
    rng = np.random.default_rng(500 + seed)
    plane, yaw, _, points = _scene(rng, lean_range=0.0)
    u = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw))])
    face = plane.normal[:2] / np.linalg.norm(plane.normal[:2])
    c = plane.rho * plane.normal[:2]  # a point of the wall's line
    span = 300.0
    corners = np.array([c - span * u, c + span * u, c + span * u + span * face,
                        c - span * u + span * face])
    area = sum(a[0] * b[1] - b[0] * a[1]
               for a, b in zip(corners, np.roll(corners, -1, 0), strict=True))
    corners = corners if area > 0 else corners[::-1]  # anticlockwise
    m = 0.01  # the library works in metres (its walls' planarity to 10 µm, in float32)
    for p in points:
        room = pra.Room.from_corners(corners.T * m, fs=8000, max_order=1)
        room.extrude(2.0)
        room.add_source(p * m)
        room.add_microphone(CAMERA * m)
        room.image_source_model()
        images = room.sources[0].images.T / m
        v = observe3(CAMERA, plane, p).virtual
        assert np.min(np.linalg.norm(images - v, axis=1)) < 1e-4


def test_a_point_behind_the_mirror_and_a_beacon_on_its_image_are_refused():
    plane = MirrorPlane.from_pose((40.0, 60.0, 0.0), 10.0, 2.0, toward=CAMERA)
    with pytest.raises(SolverError, match="in front of the mirror"):
        observe3(CAMERA, plane, plane.reflect(np.array([40.0, 50.0, 5.0])))
    b = np.array([40.0, 50.0, 5.0])
    seen = (math.degrees(math.atan2(b[1], b[0])), math.degrees(math.atan2(
        b[2] - CAMERA[2], math.hypot(b[0], b[1]))), float(np.linalg.norm(b - CAMERA)))
    with pytest.raises(SolverError, match="coincides"):
        solve_single3(CAMERA, b, seen, target_seen=seen)


def _more_beacons(rng: np.random.Generator, plane: MirrorPlane, yaw: float, k: int):
    """``k`` more beacons before the face of ``plane``, raised 0–15 cm."""
    u = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw)), 0.0])
    face = np.array([plane.normal[0], plane.normal[1], 0.0])
    face /= np.linalg.norm(face)
    foot = plane.rho * plane.normal - (plane.rho * plane.normal)[2] * np.array([0, 0, 1.0])
    return [foot + rng.uniform(-15, 15) * u + rng.uniform(8, 30) * face
            + np.array([0.0, 0.0, rng.uniform(0, 15)]) for _ in range(k)]


@pytest.mark.parametrize("seed", range(4))
def test_least_squares_recovers_the_plane_from_several_beacons(seed):
    from solver.lsq3 import solve_lsq3

    rng = np.random.default_rng(900 + seed)
    plane, yaw, lean, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 2)]
    fit = solve_lsq3(CAMERA, [(b, _seen(CAMERA, plane, b)) for b in beacons],
                     [_seen(CAMERA, plane, target)] * 2)
    assert fit.target == pytest.approx(target, abs=1e-8)
    assert fit.plane.normal == pytest.approx(plane.normal, abs=1e-10)
    assert (fit.plane.lean_deg, fit.plane.yaw_deg) == pytest.approx((lean, yaw % 180),
                                                                    abs=1e-8)
    assert fit.covariance is None


def test_least_squares_covariance_holds_its_errors():
    """With measurement noise of the σ's given, the target's squared Mahalanobis
    distance in the fit's 3×3 covariance averages 3 (χ²₃) over 300 draws (its mean's
    own spread there: ±0.15), and 95 % of the errors lie inside the 95 % ellipsoid."""
    from scipy.stats import chi2

    from solver.lsq3 import solve_lsq3

    rng = np.random.default_rng(42)
    plane, yaw, _, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 3)]
    sigma = (0.01, 0.01, 0.002)
    m2 = []
    for _ in range(300):
        def noisy(p):
            a, e, d = _seen(CAMERA, plane, p)
            return (a + rng.normal(0, sigma[0]), e + rng.normal(0, sigma[1]),
                    d * (1 + rng.normal(0, sigma[2])))
        fit = solve_lsq3(CAMERA, [(b, noisy(b)) for b in beacons], [noisy(target)],
                         sigma=sigma)
        err = fit.target - target
        m2.append(float(err @ np.linalg.solve(fit.target_covariance, err)))
    m2 = np.array(m2)
    assert 2.6 < m2.mean() < 3.4
    assert 0.92 < np.mean(m2 <= chi2.ppf(0.95, 3)) < 0.98


def _with_nuisances(seen, pan=0.0, pitch=0.0, scale=1.0):
    a, e, d = seen
    return a + pan, e + pitch, d * scale


def test_least_squares_self_calibrates_pan_pitch_and_scale():
    """Every image seen with the mount's pan off by 0.3°, its pitch by 0.2° and the range
    scaled by 1.004: estimated alongside, they come back to 1e-7, and the target with
    them (four beacons, the target seen twice)."""
    from solver.lsq3 import solve_lsq3

    rng = np.random.default_rng(77)
    plane, yaw, _, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 3)]
    bench = {"pan": 0.3, "pitch": 0.2, "scale": 1.004}
    fit = solve_lsq3(CAMERA, [(b, _with_nuisances(_seen(CAMERA, plane, b), **bench))
                              for b in beacons],
                     [_with_nuisances(_seen(CAMERA, plane, target), **bench)] * 2,
                     nuisances=("pan", "pitch", "scale"))
    assert fit.nuisances == pytest.approx(bench, abs=1e-7)
    assert fit.target == pytest.approx(target, abs=1e-6)
    plain = solve_lsq3(CAMERA, [(b, _with_nuisances(_seen(CAMERA, plane, b), **bench))
                                for b in beacons],
                       [_with_nuisances(_seen(CAMERA, plane, target), **bench)] * 2)
    assert np.linalg.norm(plain.target - target) > 0.05  # what the nuisances cost


def test_the_3d_power_terms_are_the_planar_ones_on_an_upright_glass_at_lens_height():
    """An upright mirror, every point and the vertex at the lens's height: power_terms3's α and
    d_total changes are :func:`solver.fit_model.power_terms`' (a separate, planar
    derivation), its elevation's change 0."""
    from solver.fit_model import power_terms
    from solver.geometry import line_normal
    from solver.sltr3d import power_terms3

    plane = MirrorPlane.from_pose([40.0, 60.0, 0.0], 25.0, 0.0, toward=CAMERA)
    pts = np.array([[30.0, 45.0, CAMERA[2]], [45.0, 50.0, CAMERA[2]], [48.0, 40.0, CAMERA[2]]])
    assert (pts @ plane.normal - plane.rho).min() > 5  # before the glass
    # the vertex at the lens's height too: the planar terms curve the glass in plan
    vertex = np.array([38.0, 59.0, CAMERA[2]])
    vertex -= (vertex @ plane.normal - plane.rho) * plane.normal  # onto the glass
    got = power_terms3(CAMERA, plane, pts, vertex=vertex)
    line = (25.0, float(line_normal(25.0) @ np.array([40.0, 60.0])))  # (θ, ρ)
    da, dd = power_terms(line, CAMERA[:2], pts[:, :2], vertex=vertex[:2])
    assert got[:, 0] == pytest.approx(da, rel=1e-9, abs=1e-12)
    assert got[:, 2] == pytest.approx(dd, rel=1e-9, abs=1e-9)
    assert np.abs(got[:, 1]).max() < 1e-9


def _on_sphere(o, q, plane, vertex, radius):
    """Where the ray from ``o`` to ``q`` meets a glass of radius ``radius`` (> 0 concave)
    touching ``plane`` at ``vertex``: the point of stationary path length (Fermat),
    found by minimizing it over the sphere near the flat glass's reflection point."""
    from scipy.optimize import minimize

    n = plane.normal
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    centre = vertex + radius * n

    def surface(st):
        v = vertex + st[0] * e1 + st[1] * e2
        return centre + radius * (v - centre) / np.linalg.norm(v - centre)

    flat = plane.hit(o, plane.reflect(q) - o) - vertex
    best = minimize(lambda st: np.linalg.norm(surface(st) - o) + np.linalg.norm(q - surface(st)),
                    [flat @ e1, flat @ e2], method="Nelder-Mead",
                    options={"xatol": 1e-12, "fatol": 1e-15, "maxiter": 20000})
    return surface(best.x)


@pytest.mark.parametrize("radius,within", [(20000.0, 0.01), (2000.0, 0.025)])
def test_the_3d_power_terms_turn_each_ray_as_a_curved_glass_does(radius, within):
    """Each image's α and ε on a leaning glass curved to R = 200 m about a vertex (the
    reflection point found on the sphere by Fermat's principle, here) against the first
    order: within 1 % of the larger of the two changes; at R = 20 m within 2.5 % (2.2 %
    measured: the second order)."""
    from solver.sltr3d import power_terms3

    rng = np.random.default_rng(11)
    plane, _, _, pts = _scene(rng)
    vertex = plane.hit(CAMERA, plane.reflect(pts[0]) - CAMERA) + np.array([3.0, -2.0, 4.0])
    vertex -= (vertex @ plane.normal - plane.rho) * plane.normal
    c = 1.0 / radius
    terms = power_terms3(CAMERA, plane, pts, vertex=vertex)
    for p, (da, de, _) in zip(pts, terms, strict=True):
        x = _on_sphere(CAMERA, p, plane, vertex, 1.0 / c)
        ray = x - CAMERA
        flat = plane.reflect(p) - CAMERA
        alpha = math.degrees(math.atan2(ray[1], ray[0]) - math.atan2(flat[1], flat[0]))
        elev = math.degrees(math.asin(ray[2] / np.linalg.norm(ray))
                            - math.asin(flat[2] / np.linalg.norm(flat)))
        scale = max(abs(da), abs(de)) * c
        assert alpha == pytest.approx(c * da, abs=within * scale)
        assert elev == pytest.approx(c * de, abs=within * scale)


@pytest.mark.parametrize("scale", [1.0, 1.006])
def test_least_squares_self_calibrates_a_curved_glass(scale):
    """Readings of a glass curved to R = 20 m about its centre (the first-order terms at
    that vertex), with (1.006) and without a range scale on them, s·(d + c·D): estimated
    with the power and the scale (the fit curving about its images' middle, a vertex
    elsewhere being a turn and a shift of the plane to first order), the target comes
    back within 0.02 cm, the power within 1 % and the scale within 3e-4 (the second
    order: 1.0e-4 measured); plain, it is off by ten times that."""
    from solver.lsq3 import solve_lsq3
    from solver.sltr3d import power_terms3

    rng = np.random.default_rng(78)
    plane, yaw, _, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 3)]
    centre = plane.hit(CAMERA, plane.reflect(b0) - CAMERA)
    c = 1.0 / 2000.0
    objects = [*beacons, target]
    terms = power_terms3(CAMERA, plane, objects, vertex=centre)
    seen = [_with_nuisances(np.add(_seen(CAMERA, plane, p), c * t), scale=scale)
            for p, t in zip(objects, terms, strict=True)]
    fit = solve_lsq3(CAMERA, list(zip(beacons, seen[:-1], strict=True)), [seen[-1]],
                     nuisances=("scale", "power"))
    assert fit.nuisances["power"] == pytest.approx(c, rel=0.01)
    assert fit.nuisances["scale"] == pytest.approx(scale, abs=3e-4)
    assert np.linalg.norm(fit.target - target) < 0.02
    plain = solve_lsq3(CAMERA, list(zip(beacons, seen[:-1], strict=True)), [seen[-1]])
    assert np.linalg.norm(plain.target - target) > 0.2


def test_the_fit_s_covariance_at_exact_data_is_the_bound_at_the_truth():
    """On exact measurements the fit sits at the truth, where its covariance is the
    inverse of the Fisher information the bound takes: the two agree (priors included)."""
    from solver.lsq3 import crlb3, solve_lsq3

    rng = np.random.default_rng(5)
    plane, yaw, _, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 2)]
    sigma = (0.01, 0.012, 0.002)
    kw = {"nuisances": ("pan", "scale"), "priors": {"pan": 0.5}}
    fit = solve_lsq3(CAMERA, [(b, _seen(CAMERA, plane, b)) for b in beacons],
                     [_seen(CAMERA, plane, target)], sigma=sigma, **kw)
    bound = crlb3(CAMERA, beacons, plane, target=target, sigma=sigma, **kw)
    assert fit.covariance == pytest.approx(bound, rel=1e-4, abs=1e-12)
    assert np.sqrt(np.trace(bound[3:6, 3:6])) < 1.0  # cm: a determined geometry


def test_one_bad_image_is_trusted_less_and_named(monkeypatch):
    """A beacon's azimuth off by 1° (a detector fault): the Huber loss keeps the target
    within 0.1 cm and a tenth of the error a plain fit makes, and the solution names
    the image it trusted less."""
    from solver import lsq3
    from solver.lsq3 import solve_lsq3

    rng = np.random.default_rng(11)
    plane, yaw, _, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 4)]
    seen = [_seen(CAMERA, plane, b) for b in beacons]
    seen[2] = (seen[2][0] + 1.0, *seen[2][1:])
    def error() -> tuple[float, tuple[str, ...]]:
        fit = solve_lsq3(CAMERA, list(zip(beacons, seen, strict=True)),
                         [_seen(CAMERA, plane, target)], sigma=(0.01, 0.01, 0.002))
        return float(np.linalg.norm(fit.target - target)), fit.downweighted

    robust, down = error()
    monkeypatch.setattr(lsq3, "HUBER_K", 1e9)  # a plain (Gaussian) fit
    plain, _ = error()
    assert robust < 0.1 and robust < plain / 10
    assert any(d.startswith("beacon 2 α") for d in down)


def test_a_leaning_mirror_leans_the_image_twice_and_shortens_it():
    """An object straight ahead, seen in a mirror facing the camera square-on and leaning
    by λ, the camera level with the image's foot: the image leans by 2λ, so its top stands
    H·cos 2λ up and H·sin 2λ farther (a top leaning away), and it looks
    cos 2λ / (1 + (H/Z)·sin 2λ) as tall as an upright one at its foot, Z the
    foot's depth (worked by hand); 1 in an upright mirror."""
    from solver.sltr3d import apparent_height_ratio

    base, h = np.array([0.0, 40.0, 5.0]), 10.0
    for lean in (0.0, 2.0, 4.0):
        plane = MirrorPlane.from_pose((0.0, 60.0, 0.0), 0.0, lean, toward=(0.0, 0.0, 5.0))
        o = np.array([0.0, 0.0, plane.reflect(base)[2]])  # level with the image's foot
        image_axis = plane.reflect(base + [0, 0, h]) - plane.reflect(base)
        assert math.degrees(math.acos(image_axis[2] / h)) == pytest.approx(2 * lean, abs=1e-9)
        z = plane.reflect(base)[1] - o[1]
        two = math.radians(2 * lean)
        assert apparent_height_ratio(o, plane, base, height=h) == pytest.approx(
            math.cos(two) / (1 + h / z * math.sin(two)), abs=1e-12)


def test_what_a_detector_reads_is_the_exact_image_in_an_upright_mirror():
    from solver.sltr3d import measured3, seen3

    plane = MirrorPlane.from_pose([40.0, 60.0, 0.0], 15.0, 0.0, toward=CAMERA)
    for base in ([35.0, 50.0, 0.0], [50.0, 48.0, 7.5]):
        for front in (0.0, 0.338):  # the near face's foot, taken at its own distance
            for pan in (None, 40.0, 75.0):  # the image on the axis, or 20-30° off it
                np.testing.assert_allclose(
                    measured3(CAMERA, plane, base, height=6.0, front=front, pan_deg=pan),
                    seen3(CAMERA, plane, base), rtol=0, atol=1e-9)


@pytest.mark.parametrize("pan_off", [0.0, 18.0, -25.0])
def test_what_a_detector_reads_in_a_leaning_mirror_is_the_pinhole_projection(pan_off):
    """The readings of :func:`measured3` against a pinhole camera written out here, in
    pixels, read as the detector reads them (image_geometry's formulas): the reflected
    foot, top and near face's foot projected; α at the foot and top's middle column;
    d_total = f·H / s / cos φ with s the image's length; the foot row's elevation."""
    from solver.sltr3d import measured3

    plane = MirrorPlane.from_pose([40.0, 60.0, 0.0], 15.0, 4.0, toward=CAMERA)
    base, h, front = np.array([35.0, 50.0, 3.0]), 6.0, 0.338
    foot, top = (plane.reflect(p) for p in (base, base + [0, 0, h]))
    axis = (top - foot) / h
    toward = (CAMERA - foot) - ((CAMERA - foot) @ axis) * axis
    near = foot + front * toward / np.linalg.norm(toward)
    mid = (foot + top) / 2 - CAMERA
    pan = math.degrees(math.atan2(mid[1], mid[0])) + pan_off
    f, cx, cy = 1500.0, 959.5, 543.5
    fwd = np.array([math.cos(math.radians(pan)), math.sin(math.radians(pan)), 0.0])
    right = np.array([math.sin(math.radians(pan)), -math.cos(math.radians(pan)), 0.0])

    def pixel(p):
        q = p - CAMERA
        return np.array([cx + f * (q @ right) / (q @ fwd), cy - f * q[2] / (q @ fwd)])

    pf, pt, pn = pixel(foot), pixel(top), pixel(near)
    phi = math.atan(((pf[0] + pt[0]) / 2 - cx) / f)
    d = f * h / float(np.linalg.norm(pf - pt)) / math.cos(phi)
    rise = (cy - pn[1]) * math.cos(phi) / f * (d - front)
    alpha, elev, dist = measured3(CAMERA, plane, base, height=h, front=front, pan_deg=pan)
    assert alpha == pytest.approx(pan - math.degrees(phi), abs=1e-9)
    assert dist == pytest.approx(math.hypot(d, rise), rel=1e-12)
    assert elev == pytest.approx(math.degrees(math.atan2(rise, d)), abs=1e-9)
    # and the lean biases them: the base's exact image is elsewhere (its bearing, the
    # mid-height's, by a tenth of a degree and more)
    exact = observe3(CAMERA, plane, base)
    assert abs(alpha - exact.alpha_deg) > 0.05


def test_a_fit_that_models_the_readings_removes_a_leaning_mirrors_bias():
    from solver.lsq3 import solve_lsq3
    from solver.sltr3d import measured3

    plane = MirrorPlane.from_pose([40.0, 60.0, 0.0], 15.0, -4.0, toward=CAMERA)
    beacons = [np.array([32.0, 50.0, 0.0]), np.array([46.0, 52.0, 5.0])]
    target, heights = np.array([55.0, 45.0, 2.0]), (6.0, 6.0, 10.0)
    read = [measured3(CAMERA, plane, p, height=h)
            for p, h in zip([*beacons, target], heights, strict=True)]
    fit = solve_lsq3(CAMERA, list(zip(beacons, read[:2], strict=True)), [read[2]],
                     heights=heights)
    np.testing.assert_allclose(fit.target, target, atol=1e-6)
    assert fit.plane.lean_deg == pytest.approx(-4.0, abs=1e-7)
    naive = solve_lsq3(CAMERA, list(zip(beacons, read[:2], strict=True)), [read[2]])
    assert np.linalg.norm(naive.target - target) > 0.1


def test_the_3d_monte_carlo_solves_each_draw_as_the_closed_form_does():
    """The batch closed form gives solve_single3's plane and target on every draw, and on
    a flat set-up with no elevation noise it is the planar closed form, draw for draw."""
    from solver.montecarlo import Table1Geometry
    from solver.montecarlo3 import Rise, closed_form3_unchecked, layout3, run_row3

    lay = layout3(Table1Geometry(), Rise(lean_deg=3.0, target_z=0.5, beacon_z=0.2,
                                         camera_z=0.3))
    rng = np.random.default_rng(5)
    bs = np.asarray(lay.beacon_seen) + rng.normal(0, [1.0, 1.0, 0.05], (20, 3))
    ts = np.asarray(lay.target_seen) + rng.normal(0, [1.0, 1.0, 0.05], (20, 3))
    est = closed_form3_unchecked(lay.observer, lay.beacon, tuple(bs.T), target_seen=tuple(ts.T))
    for i in range(20):
        try:
            one = solve_single3(lay.observer, lay.beacon, tuple(bs[i]), target_seen=tuple(ts[i]))
        except SolverError:
            assert np.isnan(est.target[i]).all()
            continue
        assert np.allclose(one.target, est.target[i], atol=1e-12)
        assert np.allclose(one.target_reflection_point, est.target_reflection_point[i],
                           atol=1e-12)
        assert one.plane.lean_deg == pytest.approx(est.lean_deg[i], abs=1e-9)
        assert one.plane.yaw_deg == pytest.approx(est.yaw_deg[i], abs=1e-9)
    flat = layout3(Table1Geometry(), Rise())
    row = run_row3(1.73, 0.16, 500, layout=flat, rng=3, sigma_elevation_deg=0.0)
    assert row.rmse_tar == pytest.approx(row.rmse_tar_planar, rel=1e-9)
    assert row.rmse_lean_deg == 0.0


def test_the_3d_monte_carlo_sees_the_bias_a_planar_solve_makes_of_a_leaning_mirror():
    """Without noise the 3-D solve is exact, and the planar solve of the same readings
    misses the raised target by the error its flat geometry makes: its plan position from
    α and d_total as if they lay on the board, worked here by the planar closed form."""
    from solver.montecarlo import Table1Geometry
    from solver.montecarlo3 import Rise, layout3, run_row3

    lay = layout3(Table1Geometry(), Rise(lean_deg=2.0, target_z=3.0))
    row = run_row3(0.0, 0.0, 10, layout=lay, rng=0)
    assert row.rmse_tar < 1e-9 and row.rmse_ref < 1e-9 and row.failed == 0
    (ab, _, db), (at, _, dt) = lay.beacon_seen, lay.target_seen
    flat = solve_single(lay.observer[:2], lay.beacon[:2], ab, beacon_d_total=db,
                        target_alpha_deg=at, target_d_total=dt)
    assert row.rmse_tar_planar == pytest.approx(np.linalg.norm(flat.target - lay.target[:2]),
                                                rel=1e-9)
    assert row.rmse_tar_planar > 0.5


def test_beacons_known_to_a_position_sigma_are_estimated_as_the_planar_fit_does():
    """Beacons believed 0.3 cm (per axis) off where they stand: known exactly, the target
    is 0.49 cm off and 30 σ outside its ellipsoid; with their offsets estimated under a
    0.3 cm prior, it is inside it, and the bound widens.  On the lens's plane, by an
    upright glass, the 3-D fit is the planar one (a separate fit model: solver.fit_model)
    to 1e-6 cm, its covariance too."""
    from solver.lsq import solve_lsq
    from solver.lsq3 import crlb3, solve_lsq3
    from solver.measurements import BeaconMeasurement, Sigma
    from solver.selfcal import SelfCalibration

    def fits(plane, beacons, believed, target, **kw):
        return solve_lsq3(CAMERA, [(bb, _seen(CAMERA, plane, b))
                                   for bb, b in zip(believed, beacons, strict=True)],
                          [_seen(CAMERA, plane, target)], sigma=(0.003, 0.003, 0.001), **kw)

    rng = np.random.default_rng(5)
    plane, yaw, _, (b0, target) = _scene(rng)
    beacons = [b0, *_more_beacons(rng, plane, yaw, 3)]
    off = np.random.default_rng(9)
    believed = [b + np.r_[off.normal(0, 0.3, 2), 0.0] for b in beacons]

    def mahalanobis(fit):
        e = fit.target - target
        return float(np.sqrt(e @ np.linalg.solve(fit.target_covariance, e)))

    known, free = fits(plane, beacons, believed, target), fits(
        plane, beacons, believed, target, position_sigma=0.3)
    assert mahalanobis(known) > 10 and mahalanobis(free) < 2.8
    assert np.linalg.norm(free.target - target) < 0.5 * np.linalg.norm(known.target - target)
    assert free.covariance.shape == (14, 14) and known.covariance.shape == (6, 6)
    bounds = [crlb3(CAMERA, believed, plane, target=target, sigma=(0.003, 0.003, 0.001),
                    position_sigma=s)[3:6, 3:6].trace() for s in (0.0, 0.3)]
    assert bounds[1] > 2 * bounds[0]
    # the planar special case
    rng = np.random.default_rng(11)
    plane, yaw, _, (b0, target) = _scene(rng, lean_range=0.0)
    level = [np.r_[p[:2], CAMERA[2]] for p in (b0, *_more_beacons(rng, plane, yaw, 2), target)]
    beacons, target = level[:-1], level[-1]
    believed = [b + np.r_[off.normal(0, 0.3, 2), 0.0] for b in beacons]
    fit3 = fits(plane, beacons, believed, target, position_sigma=0.3)
    seen = [_seen(CAMERA, plane, b) for b in beacons]
    ts = _seen(CAMERA, plane, target)
    fit2 = solve_lsq(CAMERA[:2], [BeaconMeasurement(tuple(bb[:2]), a, d) for bb, (a, _, d)
                                  in zip(believed, seen, strict=True)], [(ts[0], ts[2])],
                     sigma=Sigma(0.003, 0.001), calibration=SelfCalibration((), 0.3))
    assert fit3.target[:2] == pytest.approx(fit2.target, abs=1e-6)
    assert fit3.target_covariance[:2, :2] == pytest.approx(fit2.target_covariance, rel=1e-5)
