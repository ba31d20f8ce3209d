"""The moving beacon against fixed beacons, on rendered frames (issue 14's comparisons).

    python benchmarks/track.py [--scenes default exp1 exp2 exp3] [--steps 20] [--spp N]
                          [--odometry-sigma CM] [--out renders/bench_track]
                          [--plot docs/track_paths.png] [--coverage SEEDS] [--beside]

For each scene, `mirrorsim track` is run (full size, seed 0, default odometry noise)
with the beacon on each of the paper's three paths (eqs 19–21), then standing still at
its start (one fixed beacon, seen in as many frames), then standing still where `plan`
puts the best fixed beacon.  Every run has the same number of frames and the same
filter, so the only difference is where the beacon stands.  Prints, per scene and run:
the poses seen, and after 5, 10 and the last step the commanded path length, the mirror
yaw error and the target error; the wall time of each run; and plots the target error
against the step (one panel per scene).  Frames are kept in --out, so a second call
only re-detects.

With --coverage N: instead, the rectangular path on each scene with N fresh seeds (each
its own renders and odometry), and per step the filter's honesty on rendered frames:
the share of runs whose true mirror lies inside the filter's 95 % region (NEES ≤ 5.99,
with a Clopper–Pearson interval) and the mean NEES (2 for an honest filter).

With --beside: instead, the rectangular path on each scene twice, from the same seed
(fresh unless --seed): the moving beacon alone, and with a second beacon standing still
where `plan` puts the best fixed beacon (placed from the scene's mirror, its position
known exactly) (`track` weighs it into the filter from the start); per run
the mirror's yaw error, the filter's yaw spread and the true mirror's NEES at the first
pose and the last, and the final target error.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import clone  # noqa: E402, F401  (the clone first on sys.path)
import numpy as np
from stamp import stamp  # noqa: E402

from mirrorsim.errors import BadParameter  # noqa: E402
from mirrorsim.pipelines.planning import plan_scene  # noqa: E402
from mirrorsim.pipelines.scenes import load_scene  # noqa: E402
from mirrorsim.pipelines.track import run_track
from mirrorsim.pipelines.track_report import TrackReport
from mirrorsim.scene.model import Beacon  # noqa: E402

CHI2_2_95 = 5.991  # χ²₂'s 95 % point
RUNS = ("rectangular", "linear", "sawtooth", "fixed", "plan's best")


def one_run(name: str, run: str, steps: int, spp: int | None, sigma: float, out: Path,
            seed: int = 0) -> tuple[TrackReport, float]:
    """One track of ``scene`` with the beacon on ``run``; its report and wall time."""
    scene = load_scene(Path("scenes") / f"{name}.yaml")
    kind = run
    if run == "plan's best":
        best = plan_scene(scene).best.position
        scene = replace(scene, beacons=(Beacon((float(best[0]), float(best[1])),
                                               scene.beacons[0].height),))
        kind = "fixed"
    t0 = time.perf_counter()
    if spp is not None:
        scene = scene.with_render(spp=spp)
    rep = run_track(scene, out / name / run.replace("'", "").replace(" ", "_"), kind=kind,
                    steps=steps, odometry_sigma=sigma, seed=seed)
    return rep, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["default", "exp1", "exp2", "exp3"])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--spp", type=int)
    ap.add_argument("--odometry-sigma", type=float, default=0.1)
    ap.add_argument("--out", type=Path, default=Path("renders/bench_track"))
    ap.add_argument("--plot", type=Path, default=Path("docs/track_paths.png"))
    ap.add_argument("--coverage", type=int, default=0, metavar="SEEDS")
    ap.add_argument("--beside", action="store_true",
                    help="the moving beacon alone and beside a fixed beacon at plan's best")
    ap.add_argument("--seed", type=int,
                    help="--beside's seed (default: a fresh one, printed)")
    args = ap.parse_args()
    if args.coverage:
        coverage(args)
        return
    if args.beside:
        beside(args)
        return
    marks = sorted({min(5, args.steps), min(10, args.steps), args.steps})
    print(f"machine: {platform.machine()}, {platform.system()}; {args.steps} moves, "
          f"seed 0, odometry σ {args.odometry_sigma:g} cm\n")
    head = " | ".join(f"after {m}: length cm / yaw ° / target cm" for m in marks)
    print(f"| scene | beacon | poses seen | {head} | wall s |")
    print("|---|---|---|" + "---|" * len(marks) + "---|")
    reports: dict[str, dict[str, TrackReport]] = {}
    for name in args.scenes:
        for run in RUNS:
            try:
                rep, wall = one_run(name, run, args.steps, args.spp, args.odometry_sigma,
                                    args.out)
            except BadParameter as exc:  # no way to walk it clear of the board's objects
                print(f"| {name} | {run} | refused: {exc} |" + " |" * len(marks) + " |",
                      flush=True)
                continue
            reports.setdefault(name, {})[run] = rep
            seen = sum(s.seen for s in rep.steps)
            cells = " | ".join(f"{rep.steps[m].path_length_cm:.0f} / "
                               f"{rep.steps[m].mirror_yaw_error_deg:.3f} / "
                               f"{rep.steps[m].target_error_cm:.2f}" for m in marks)
            print(f"| {name} | {run} | {seen}/{len(rep.steps)} | {cells} | {wall:.0f} |",
                  flush=True)
    plot(reports, args.plot)
    print(f"\nplot: {args.plot}")


def coverage(args: argparse.Namespace) -> None:
    """The filter's 95 % region against the true mirror on rendered frames, per step."""
    from mirrorsim.pipelines.uncertainty import binomial_interval

    first = int.from_bytes(os.urandom(3), "big")  # fresh: no test's seed
    nees: list[list[float]] = []
    refused: list[str] = []
    for name in args.scenes:
        for k in range(args.coverage):
            try:
                rep, wall = one_run(name, "rectangular", args.steps, args.spp,
                                    args.odometry_sigma, args.out / "coverage", first + k)
            except BadParameter as exc:  # the path cannot be walked there: no run
                print(f"{name}: not run: {exc}", file=sys.stderr, flush=True)
                refused.append(name)
                break
            nees.append([s.mirror_nees for s in rep.steps])
            print(f"{name} seed {first + k}: final NEES {nees[-1][-1]:.2f}, {wall:.0f} s",
                  file=sys.stderr, flush=True)
    v = np.array(nees)
    ran = [n for n in args.scenes if n not in refused]
    print(f"{stamp()}; seeds {first}–{first + args.coverage - 1} on each of "
          f"{', '.join(ran)}; rectangular path, {args.steps} moves, odometry σ "
          f"{args.odometry_sigma:g} cm"
          + (f"; not run on {', '.join(refused)} (no way to walk the path clear of the "
             "board's objects)" if refused else "") + "\n")
    print("| step | runs | true mirror inside the 95 % region (interval) | mean NEES (honest: 2) |")
    print("|---|---|---|---|")
    for k in range(v.shape[1]):
        col = v[:, k][np.isfinite(v[:, k])]
        inside = int(np.sum(col <= CHI2_2_95))
        lo, hi = binomial_interval(inside, len(col))
        print(f"| {k} | {len(col)} | {inside}/{len(col)} = {inside / len(col):.2f} "
              f"({lo:.2f}–{hi:.2f}) | {np.mean(col):.2f} |")


def beside(args: argparse.Namespace) -> None:
    """The moving beacon alone against the same run beside a fixed beacon at plan's best."""
    seed = int.from_bytes(os.urandom(3), "big") if args.seed is None else args.seed
    print(f"{stamp()}; seed {seed}; rectangular path, {args.steps} moves, odometry σ "
          f"{args.odometry_sigma:g} cm; the fixed beacon where `plan` puts the best one\n")
    print("| scene | beacons | first pose: yaw error ° / spread ° / NEES | last pose: yaw "
          "error ° / spread ° / NEES | final target error cm | wall s |")
    print("|---|---|---|---|---|---|")
    for name in args.scenes:
        scene = load_scene(Path("scenes") / f"{name}.yaml")
        if args.spp is not None:
            scene = scene.with_render(spp=args.spp)
        best = plan_scene(scene).best.position
        still = Beacon((float(best[0]), float(best[1])), scene.beacons[0].height)
        for label, s in (("moving alone", scene),
                         ("moving + fixed at plan's best",
                          replace(scene, beacons=(scene.beacons[0], still)))):
            t0 = time.perf_counter()
            try:
                rep = run_track(s, args.out / "beside" / name / label.split()[-1],
                                kind="rectangular", steps=args.steps,
                                odometry_sigma=args.odometry_sigma, seed=seed)
            except (ValueError, RuntimeError) as exc:  # a path through the fixed beacon…
                print(f"| {name} | {label} | not run: {exc} | | | |", flush=True)
                continue
            a, z = rep.steps[0], rep.final
            print(f"| {name} | {label} | {a.mirror_yaw_error_deg:.3f} / "
                  f"{a.yaw_spread_deg:.3f} / {a.mirror_nees:.2f} | "
                  f"{z.mirror_yaw_error_deg:.3f} / {z.yaw_spread_deg:.3f} / "
                  f"{z.mirror_nees:.2f} | {z.target_error_cm:.2f} | "
                  f"{time.perf_counter() - t0:.0f} |", flush=True)


def plot(reports: dict[str, dict[str, TrackReport]], out: Path) -> None:
    """Target error against the step, one panel per scene, one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(reports), figsize=(4.2 * len(reports), 3.6),
                             squeeze=False, sharey=True)
    for ax, (name, runs) in zip(axes[0], reports.items(), strict=True):
        for run, rep in runs.items():
            ax.plot([s.step for s in rep.steps], [s.target_error_cm for s in rep.steps],
                    "-" if run in RUNS[:3] else "--", marker=".", label=run)
        ax.set_yscale("log")
        ax.set_title(name)
        ax.set_xlabel("step")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("target error (cm)")
    axes[0][-1].legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
