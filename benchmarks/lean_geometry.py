"""How far a leaning mirror throws the planar solver, and the 3-D one on the same
measurements: the geometry alone (nothing rendered).

    python benchmarks/lean_geometry.py [--scenes 200] [--seed S]

Each scene is drawn at random (the glass taken as wide as it needs to be: every image
is seen):
- a mirror 25–60 cm out, at yaw −50..50°, leaning by the row's lean (its sign drawn),
  seen at least 10° from edge-on;
- a target and three beacons before its face, raised 0–15 cm;
- a camera at the board's corner, 12 cm up.

Every measurement is exact, plus Gaussian errors: 0.01° in azimuth and 0.2 % in
d_total (the detector's σ's), 0.01° in elevation (assumed; the rendered scenes'
elevation σ's are docs/method.md's, measured by benchmarks/evaluate3d.py).  They are
the σ's the 3-D solve is given, so its coverage checks consistency.

- The 3-D solver (:func:`solver.lsq3.solve_lsq3`) takes (α, ε, d_total).
- The planar solver (:func:`solver.lsq.solve_measurements`, the one mirrorsim runs
  today) takes α and the horizontal distance d_total·cos ε. That is the most a planar
  model can be given: it assumes every object on one plane and an upright mirror.

Printed: each solver's median and 95th-percentile target error in the board's plane,
the 3-D solver's height error, and how often its 95 % ellipsoid holds the truth.  Also
the median bias of d_total: size constancy applied to a 10 cm pencil's image in the
leaning glass, not told the lean (:func:`solver.sltr3d.apparent_height_ratio`).  The
measurements above are given without that bias: a detector in 3-D must correct it.
Markdown, stamped.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from clone import ROOT  # noqa: F401 (puts the repository on the path)
from stamp import stamp

from solver.errors import SolverError
from solver.lsq import solve_measurements
from solver.lsq3 import solve_lsq3
from solver.measurements import BeaconMeasurement, Sigma
from solver.sltr3d import MirrorPlane, apparent_height_ratio, observe3

CAMERA = np.array([0.0, 0.0, 12.0])
SIGMA = (0.01, 0.01, 0.002)  # σ_α (deg), σ_ε (deg), σ_d (fraction of d_total)
LEANS = (0.0, 1.0, 2.0, 3.0, 4.0)


def _scene(rng: np.random.Generator, lean: float):
    while True:  # a camera that sees the glass at 10° or more from edge-on, as `check` asks
        centre = np.array([rng.uniform(25, 60), rng.uniform(45, 75), 0.0])
        yaw = rng.uniform(-50, 50)
        plane = MirrorPlane.from_pose(centre, yaw, lean * rng.choice((-1.0, 1.0)),
                                      toward=CAMERA)
        ray = CAMERA - centre
        if plane.normal @ ray > math.sin(math.radians(10.0)) * np.linalg.norm(ray):
            break
    u = np.array([math.cos(math.radians(yaw)), math.sin(math.radians(yaw)), 0.0])
    face = np.array([plane.normal[0], plane.normal[1], 0.0]) / math.hypot(*plane.normal[:2])
    points = [centre + rng.uniform(-12, 12) * u + rng.uniform(6, 30) * face
              + np.array([0.0, 0.0, rng.uniform(0, 15)]) for _ in range(4)]
    return plane, points[0], points[1:]


def _noisy(rng: np.random.Generator, plane: MirrorPlane, p: np.ndarray):
    ob = observe3(CAMERA, plane, p)
    return (ob.alpha_deg + rng.normal(0, SIGMA[0]), ob.elevation_deg + rng.normal(0, SIGMA[1]),
            ob.d_total * (1 + rng.normal(0, SIGMA[2])))


def run(lean: float, scenes: int, rng: np.random.Generator) -> dict[str, float]:
    """The row of ``lean``: each solver's errors over ``scenes`` random scenes."""
    from scipy.stats import chi2

    planar, flat, height, inside, bias = [], [], [], [], []
    for _ in range(scenes):
        plane, target, beacons = _scene(rng, lean)
        # what size constancy would make of a 10 cm pencil's d_total, not told the lean
        bias += [1.0 / apparent_height_ratio(CAMERA, plane, b, height=10.0) - 1.0 for b in beacons]
        seen_b = [_noisy(rng, plane, b) for b in beacons]
        seen_t = _noisy(rng, plane, target)
        try:
            fit = solve_lsq3(CAMERA, list(zip(beacons, seen_b, strict=True)), [seen_t],
                             sigma=SIGMA)
        except SolverError:
            continue
        err = fit.target - target
        flat.append(float(np.hypot(*err[:2])))
        height.append(abs(float(err[2])))
        inside.append(float(err @ np.linalg.solve(fit.target_covariance, err))
                      <= chi2.ppf(0.95, 3))

        def horizontal(s):
            return s[0], s[2] * math.cos(math.radians(s[1]))

        sol = solve_measurements(CAMERA[:2], [BeaconMeasurement(tuple(b[:2]), *horizontal(s))
                                              for b, s in zip(beacons, seen_b, strict=True)],
                                 [horizontal(seen_t)], sigma=Sigma(SIGMA[0], SIGMA[2]))
        planar.append(float(np.hypot(*(np.asarray(sol.target) - target[:2]))))
    return {"n": len(flat), "planar_median": float(np.median(planar)),
            "planar_p95": float(np.percentile(planar, 95)),
            "median": float(np.median(flat)), "p95": float(np.percentile(flat, 95)),
            "height_median": float(np.median(height)), "inside": float(np.mean(inside)),
            "bias": float(np.median(np.abs(bias)))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=20261206)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"{args.scenes} random scenes a row (seed {args.seed}): a mirror leaning by the "
          "row's lean, the target and three beacons raised 0–15 cm, the camera 12 cm up; "
          "exact measurements with Gaussian errors of σ 0.01° in azimuth (the detector's), "
          "0.01° in elevation (assumed) and 0.2 % in d_total "
          "(the detector's), the σ's the 3-D solve is given. Target errors in the board's "
          "plane, cm.\n")
    print("| lean | planar solver: median | p95 | 3-D solver: median | p95 | "
          "height error median | 95 % ellipsoid holds | size-constancy d_total bias |")
    print("|---|---|---|---|---|---|---|---|")
    for lean in LEANS:
        r = run(lean, args.scenes, rng)
        print(f"| ±{lean:g}° | {r['planar_median']:.3f} | {r['planar_p95']:.3f} | "
              f"{r['median']:.3f} | {r['p95']:.3f} | {r['height_median']:.3f} | "
              f"{r['inside']:.2f} ({r['n']}) | {100 * r['bias']:.2f} % |")
    print(f"\n{stamp()}")


if __name__ == "__main__":
    main()
