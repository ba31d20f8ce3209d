"""The paper's open question: how the target's error grows as the reflector shrinks
against d_total, down to the s/d = 1/1000 of an RF reflector.

    python benchmarks/reflector_size.py [--d-total 100] [--sigma-alpha 0.01] [--sigma-d 0.2]

The geometry is exact and follows the paper's Table 1 set-up, scaled:
- the observer is at the origin;
- the target's ray leaves at 70° and meets the mirror at 0.6·d_total;
- the mirror is turned 30° from square-on;
- the target lies the rest of d_total beyond.

For each width s, a beacon is seen only where its image reaches the observer through
the glass. Every such position is tried: a reflection point u along the glass and a
distance t along the reflected ray.

Two solves are compared, each by the solver's Cramér–Rao bound at the truth
(:func:`solver.lsq.crlb`, σ_α and σ_d on every measurement):
- the least RMS target error of one beacon at its best place;
- the least RMS target error of two beacons, one at each end of the glass, at their
  best common distance.

Markdown on stdout, stamped.
"""

from __future__ import annotations

import argparse

import numpy as np
from clone import ROOT  # noqa: F401 (puts the repository on the path)
from stamp import stamp

from solver.errors import SolverError
from solver.geometry import line_normal, unit
from solver.lsq import crlb
from solver.measurements import Sigma
from solver.montecarlo import Table1Geometry

RATIOS = (1 / 2, 1 / 5, 1 / 10, 1 / 20, 1 / 50, 1 / 100, 1 / 200, 1 / 500, 1 / 1000)


def _beacon(o: np.ndarray, point: np.ndarray, yaw: float, u: float, t: float) -> np.ndarray:
    """The position whose image the observer sees through the glass at ``u`` along it
    from ``point``, ``t`` from the glass: on the ray reflected there."""
    r = point + u * unit(yaw)
    v = (r - o) / np.linalg.norm(r - o)
    n = line_normal(yaw)
    return r + t * (v - 2.0 * (v @ n) * n)


def _rms(o, beacons, lay, sigma) -> float:
    """√trace of the target's block of the CRLB, or inf where it is singular."""
    n = line_normal(lay.yaw_deg)
    try:
        cov = crlb(o, np.array(beacons), lay.yaw_deg, mirror_rho=float(n @ lay.mirror_point),
                   target=lay.target, sigma=sigma)
    except SolverError:
        return float("inf")
    return float(np.sqrt(np.trace(cov[2:4, 2:4])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--d-total", type=float, default=100.0, help="the target's d_total (cm)")
    ap.add_argument("--sigma-alpha", type=float, default=0.01, help="σ_α (deg)")
    ap.add_argument("--sigma-d", type=float, default=0.2, help="σ_d (%% of d_total)")
    args = ap.parse_args()
    d = args.d_total
    lay = Table1Geometry(d_total=d, d1=0.6 * d).layout()
    o = np.zeros(2)
    sigma = Sigma(args.sigma_alpha, args.sigma_d / 100)
    ts = np.geomspace(0.005 * d, 1.0 * d, 40)
    print(f"Target error against the reflector's width s (d_total {d:g} cm; Table 1's "
          f"layout scaled; σ_α {args.sigma_alpha:g}°, σ_d {args.sigma_d:g} % on every "
          "measurement; the Cramér–Rao bound of the target's RMS error at the truth)\n")
    print("| s / d_total | s (cm) | one beacon, best place: RMS (cm) | its u / s, t / d | "
          "two beacons at the ends: RMS (cm) | RMS / d_total |")
    print("|---|---|---|---|---|---|")
    for ratio in RATIOS:
        s = ratio * d
        best = (float("inf"), 0.0, 0.0)
        for u in np.linspace(-0.5 * s, 0.5 * s, 21):
            for t in ts:
                e = _rms(o, [_beacon(o, lay.mirror_point, lay.yaw_deg, u, t)], lay, sigma)
                best = min(best, (e, u / s, t / d))
        ends = min(_rms(o, [_beacon(o, lay.mirror_point, lay.yaw_deg, k * s / 2, t)
                            for k in (-1, 1)], lay, sigma) for t in ts)
        print(f"| 1/{round(1 / ratio)} | {s:.3g} | {best[0]:.3g} | {best[1]:+.2f}, "
              f"{best[2]:.3f} | {ends:.3g} | {min(best[0], ends) / d:.2e} |")
    print(f"\n{stamp()}")


if __name__ == "__main__":
    main()
