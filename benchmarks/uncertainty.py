"""Benchmark: how close the solver's estimates come to the Cramér–Rao bound.

    python benchmarks/uncertainty.py [--scenes 40] [--draws 2000] [--seed S] [--beacons 1 2 3]
    python benchmarks/uncertainty.py --renders 20 [--scene scenes/default.yaml] [--seed S]

For random scenes of the default spec (geometry only: nothing is rendered), the exact
measurements of the target and of 1, 2 or 3 beacons (the spec's beacon and beacons drawn
on the board where the mirror shows them), each measurement's σ's from the shipped error
model, and DRAWS Gaussian draws of those σ's: the estimator's RMS target error, mirror
yaw error and mirror offset error against the CRLB's (√trace of the target block, √ of
the yaw and offset variances) at the truth.  Efficiency = RMSE / √CRLB (1: efficient).

With --renders N: the scene rendered with N fresh render seeds and evaluated with the
shipped error model (`evaluate`'s default); each run's target error against its own
95 % ellipse: how often the truth lies inside, and the Mahalanobis distances.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from clone import ROOT  # noqa: E402  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

from mirrorsim.formats.error_model_file import default_error_model
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene  # noqa: E402
from solver.errors import SolverError  # noqa: E402
from solver.geometry import line_normal, yaw_difference  # noqa: E402
from solver.lsq import crlb, solve_measurements  # noqa: E402
from solver.measurements import BeaconMeasurement  # noqa: E402
from solver.sltr import observe  # noqa: E402


def _extra_beacons(scene, rng, k: int) -> list[np.ndarray]:
    """k more beacon positions in front of the mirror, seen in it: near the spec's beacon."""
    m, cam = scene.mirror, scene.camera
    out, tries = [], 0
    b0 = np.asarray(scene.beacons[0].position, float)
    while len(out) < k and tries < 2000:
        tries += 1
        p = b0 + rng.uniform(-8, 8, 2)
        try:
            o = observe(cam.position, m.center, m.yaw, point=p)
        except SolverError:
            continue
        along = (np.asarray(o.reflection_point) - np.asarray(m.center)) @ np.array(
            [np.cos(np.radians(m.yaw)), np.sin(np.radians(m.yaw))])
        if abs(along) < 0.4 * m.size[0]:
            out.append(p)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=40)
    ap.add_argument("--draws", type=int, default=2000)
    ap.add_argument("--seed", type=int, help="default: a fresh one, printed")
    ap.add_argument("--beacons", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--renders", type=int, default=0)
    ap.add_argument("--scene", type=Path, default=ROOT / "scenes" / "default.yaml")
    a = ap.parse_args()
    seed = a.seed if a.seed is not None else int.from_bytes(os.urandom(3), "big")
    if a.renders:
        renders(a.scene, a.renders, seed)
        return
    model = default_error_model()
    spec = load_spec(None)
    print(f"estimator efficiency against the CRLB: {a.scenes} scenes of the default spec, "
          f"seed {seed}, {a.draws} draws each, the shipped error model's typical σ's; {stamp()}\n")
    print("| beacons | estimator | target RMSE / √CRLB median (p5–p95) | yaw | offset | "
          "target √CRLB cm median |\n|---|---|---|---|---|---|")
    rng = np.random.default_rng(seed)
    for nb in a.beacons:
        eff = {"target": [], "yaw": [], "offset": []}
        bound_cm = []
        for i in range(a.scenes):
            scene = sample_scene(spec, np.random.default_rng(np.random.SeedSequence(
                seed, spawn_key=(nb, i))), f"s{i}")
            cam, m = scene.camera, scene.mirror
            beacons = [np.asarray(scene.beacons[0].position, float)]
            beacons += _extra_beacons(scene, rng, nb - 1)
            if len(beacons) < nb:
                continue
            t = np.asarray(scene.target.position, float)
            ob = [observe(cam.position, m.center, m.yaw, point=b) for b in beacons]
            ot = observe(cam.position, m.center, m.yaw, point=t)
            # the model's typical σ's at this camera (exact measurements hold no pixels)
            typical = model.typical_at(cam.fx)
            sig = replace(typical, beacons=typical.beacons * len(ob))
            n = line_normal(m.yaw % 180)
            rho = float(n @ np.asarray(m.center, float))
            bound = crlb(cam.position, np.array(beacons), m.yaw % 180, mirror_rho=rho, target=t,
                         sigma=sig)
            errs = {"target": [], "yaw": [], "offset": []}
            for _ in range(a.draws):
                bs = [BeaconMeasurement(tuple(b), float(o.alpha_deg) + rng.normal(0, s.alpha_deg),
                                        float(o.d_total) * (1 + rng.normal(0, s.d_total_rel)))
                      for b, o, s in zip(beacons, ob, sig.beacons, strict=True)]
                ts = [(float(ot.alpha_deg) + rng.normal(0, sig.target.alpha_deg),
                       float(ot.d_total) * (1 + rng.normal(0, sig.target.d_total_rel)))]
                try:
                    sol = solve_measurements(cam.position, bs, ts, sigma=sig)
                except SolverError:
                    continue
                errs["target"].append(np.sum((sol.target - t) ** 2))
                errs["yaw"].append(yaw_difference(sol.mirror.yaw_deg, m.yaw % 180) ** 2)
                errs["offset"].append((sol.mirror.rho - rho) ** 2)
            eff["target"].append(np.sqrt(np.mean(errs["target"]) / np.trace(bound[2:, 2:])))
            eff["yaw"].append(np.sqrt(np.mean(errs["yaw"]) / bound[0, 0]))
            eff["offset"].append(np.sqrt(np.mean(errs["offset"]) / bound[1, 1]))
            bound_cm.append(np.sqrt(np.trace(bound[2:, 2:])))
        name = "closed form" if nb == 1 else "least squares"
        cells = [f"{statistics.median(v):.3f} ({np.percentile(v, 5):.3f}–"
                 f"{np.percentile(v, 95):.3f})" for v in eff.values()]
        print(f"| {nb} | {name} | {' | '.join(cells)} | {statistics.median(bound_cm):.3f} |",
              flush=True)


def renders(path: Path, n: int, seed: int) -> None:
    """Evaluate ``path`` with n render seeds; coverage of its 95 % ellipse."""
    import tempfile

    from mirrorsim.pipelines.evaluate import evaluate_scene
    from mirrorsim.pipelines.scenes import load_scene
    from mirrorsim.pipelines.uncertainty import binomial_interval

    scene = load_scene(path)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(n):
            s = scene.with_render(seed=seed + k)
            rep = evaluate_scene(s, Path(tmp) / str(k), progress=False, keep=())
            e = rep.errors
            rows.append((e.target_cm, e.target_ellipse95_major_cm, e.target_mahalanobis,
                         e.target_crlb_cm, e.target_inside95))
    v = np.array(rows, float)
    inside = int(np.sum(v[:, 4]))
    lo, hi = binomial_interval(inside, n)
    print(f"{path.name}, {n} renders (seeds {seed}..{seed + n - 1}), the shipped error model; "
          f"{time.strftime('%Y-%m-%d')}, {platform.machine()}\n")
    print(f"| target error cm median (max) | 95 % semi-major cm median | √CRLB cm | inside "
          f"the 95 % ellipse | median Mahalanobis (honest 1.18) |\n|---|---|---|---|---|\n"
          f"| {np.median(v[:, 0]):.3f} ({v[:, 0].max():.3f}) | {np.median(v[:, 1]):.3f} | "
          f"{np.median(v[:, 3]):.3f} | {inside}/{n} (95 % interval {lo:.2f}–{hi:.2f}) | "
          f"{np.median(v[:, 2]):.2f} |")


if __name__ == "__main__":
    main()
