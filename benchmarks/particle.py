"""Particle filter convergence on a simulated moving-beacon run (EXP1's mirror).

    python benchmarks/particle.py [--seeds 20] [--particles 4000] [--sigma-trs 0.1]
                             [--sigma-alpha 0.05] [--sigma-d 0.5]

A pencil follows the rectangular path (paper eq 20) in front of the mirror; commands
are corrupted by σ_trs = 0.1 cm per step, observations by σ = (0.05°, 0.5 %).  The filter
starts from a uniform prior (yaw ± 15°, offset ± 8 cm).  Prints the median and 90th
percentile over seeds of the mirror's yaw and offset errors after each step, beside the
same for the batch least-squares smoother over all steps so far (every pose, the mirror
and the motion at once: the best any estimator can do with these data, a reference
for the filter).

With --nees: the filter's own uncertainty against its errors.  After each step, the
normalized estimation error squared of the mirror (yaw, offset) under the particles'
weighted covariance, NEES = eᵀ C⁻¹ e, averaged over the seeds (a consistent filter gives
2, the χ²₂ mean; the 95 % interval of a mean over N seeds is χ²₂N's quantiles / N), and
the fraction of seeds whose truth lies in the 95 % region (NEES ≤ 5.99).
"""

from __future__ import annotations

import argparse

import clone  # noqa: E402, F401  (the clone first on sys.path)
import numpy as np

from solver.beacon_kalman import PFParams
from solver.geometry import line_normal  # noqa: E402
from solver.measurements import Sigma  # noqa: E402
from solver.particle import MovingBeaconFilter
from solver.particle_runs import mirror_errors, simulate_run, track  # noqa: E402
from solver.placement import path_points  # noqa: E402
from solver.smoother import smooth_run  # noqa: E402

OBSERVER, MIRROR, YAW = np.zeros(2), np.array([27.5, 65.0]), 38.0


def batch_yaw_error(start, controls, obs, true, params: PFParams) -> float:
    """|yaw error| of the batch smoother over these steps (started at the truth: it finds
    the optimum nearest it)."""
    k = len(controls)
    run = smooth_run(OBSERVER, start, controls, observations=obs, params=params, yaw_deg=YAW,
                     rho=line_normal(YAW) @ MIRROR,
                     beacons=true[: k + 1])
    return abs(run.yaw_deg - YAW)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--particles", type=int, default=4000)
    ap.add_argument("--sigma-trs", type=float, default=0.1, help="odometry σ per move, cm")
    ap.add_argument("--sigma-alpha", type=float, default=0.05, help="σ of α, degrees")
    ap.add_argument("--sigma-d", type=float, default=0.5, help="σ of d_total, in %% of d_total")
    ap.add_argument("--nees", action="store_true",
                    help="the filter's consistency (NEES) instead of its convergence")
    args = ap.parse_args()
    params = PFParams(Sigma(args.sigma_alpha, args.sigma_d / 100), args.sigma_trs)
    path = path_points("rectangular", (30.0, 60.0), 66.7, a=4.0, b=1.0, n=12)
    rho = line_normal(YAW) @ MIRROR
    if args.nees:
        nees_table(args, params, path, rho)
        return
    yaw_errs, off_errs, batch = [], [], []
    for seed in range(args.seeds):
        controls, obs, true = simulate_run(OBSERVER, MIRROR, YAW, path=path, params=params,
                                           rng=seed)
        est = track(OBSERVER, path[0], controls, observations=obs, yaw_range=(YAW - 15, YAW + 15),
                    rho_range=(rho - 8, rho + 8), n=args.particles, params=params, rng=1000 + seed)
        y, o = mirror_errors(est, MIRROR, YAW)
        yaw_errs.append(np.abs(y))
        off_errs.append(o)
        batch.append([batch_yaw_error(path[0], controls[:k], obs[:k], true, params)
                      for k in range(1, len(controls) + 1)])
    y, o, b = np.array(yaw_errs), np.array(off_errs), np.array(batch)
    print(f"{args.seeds} runs, {args.particles} particles, {y.shape[1]} steps, σ_trs "
          f"{args.sigma_trs:g} cm, σ = ({args.sigma_alpha:g}°, {args.sigma_d:g} %)\n")
    print("| step | yaw error median (°) | p90 (°) | offset error median (cm) | p90 (cm) "
          "| batch smoother's yaw error median (°) | p90 (°) |")
    print("|---|---|---|---|---|---|---|")
    for k in range(y.shape[1]):
        print(f"| {k + 1} | {np.median(y[:, k]):.3f} | {np.percentile(y[:, k], 90):.3f} | "
              f"{np.median(o[:, k]):.3f} | {np.percentile(o[:, k], 90):.3f} | "
              f"{np.median(b[:, k]):.3f} | {np.percentile(b[:, k], 90):.3f} |")


def nees_table(args, params: PFParams, path: np.ndarray, rho: float) -> None:
    """Mean NEES and 95 % coverage per step over the seeds."""
    from scipy.stats import chi2

    rows = []
    for seed in range(args.seeds):
        controls, obs, _ = simulate_run(OBSERVER, MIRROR, YAW, path=path, params=params, rng=seed)
        f = MovingBeaconFilter(OBSERVER, path[0], (YAW - 15, YAW + 15), (rho - 8, rho + 8),
                               args.particles, params, 1000 + seed)
        per = []
        for c, z in zip(controls, obs, strict=True):
            f.step(c, z)
            per.append(f.nees(MIRROR, YAW))
        rows.append(per)
    v = np.array(rows)
    n = v.shape[0]
    lo, hi = chi2.ppf(0.025, 2 * n) / n, chi2.ppf(0.975, 2 * n) / n
    print(f"filter consistency: {n} seeds, {args.particles} particles, σ_trs "
          f"{args.sigma_trs:g} cm, σ = ({args.sigma_alpha:g}°, {args.sigma_d:g} %); "
          f"a consistent filter's mean NEES lies in {lo:.2f}–{hi:.2f} (95 %)\n")
    print("| step | mean NEES (2 if consistent) | median | truth in the 95 % region |")
    print("|---|---|---|---|")
    for k in range(v.shape[1]):
        print(f"| {k + 1} | {v[:, k].mean():.2f} | {np.median(v[:, k]):.2f} | "
              f"{np.mean(v[:, k] <= chi2.ppf(0.95, 2)):.2f} |")


if __name__ == "__main__":
    main()
