"""Benchmark: self-calibrating SLTR on rendered frames of a real bench's imperfections.

    python benchmarks/selfcal.py [--scenes 40] [--seed S] [--spec scenes/dataset_spec_bench.yaml]
                                 [--beacons 3] [--calibrate pan,scale,power] [--out DIR]
                                 [--lossless] [--error-model FILE] [--priors]

For each random scene of the spec (its bench imperfections drawn as the spec draws
them: pan error, calibration error, curvature, JPEG…), `plan --beacons N --calibrate
NUISANCES` places N beacons; each beacon's believed position is off by the spec's
`beacon.known_position_offset` range (drawn per beacon and axis); the scene is rendered
(one frame per beacon), detected, and solved four ways from the same measurements:
plain least squares and self-calibrated (``--calibrate``'s nuisances, by default the
pan, the scale and the mirror's power; the beacons known to the offsets' σ,
(hi − lo)/√12, as the experimenter would say), with the believed beacon
positions and with the exact ones (then known exactly).  The plan is made with the same
σ.  Beside them: the believed positions self-calibrated for pan and scale only (what
the other nuisances add), and a reference: plain least squares with the exact
positions on the measurements with the frame's shared errors taken out by the truth
(the mean of its images' α errors, and of their relative d_total errors), which leaves
each image's own error.  Prints each scene's target errors, the medians, and the
images' own α errors beside the mirror's power's first-order move.  ``--lossless``: the same scenes
(the same draws) with each frame stored as PNG instead of the JPEG the spec draws, to
tell JPEG's part from the rest.  ``--priors``: two more columns, self-calibrated with
the spec's ranges as what the bench knows of each nuisance (``SelfCalibration.priors``: a
uniform draw's σ, (hi − lo)/√12; the calibration's distance error over D_REF as the
scale's), with the believed and with the exact positions.  Every run ends with two
more columns: the same frames measured with the camera's pose from the pegboard's holes
(``evaluate --board-pose``: every α turned by the board's pan, every d_total corrected
for its pitch, the pan then known to the board's precision), self-calibrated for the
rest, with the believed and with the exact positions.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
from clone import ROOT  # noqa: E402  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

from mirrorsim.errors import DetectionError, SceneError  # noqa: E402
from mirrorsim.formats.error_model_file import default_error_model, load_error_model
from mirrorsim.pipelines.calibrate import D_REF  # noqa: E402
from mirrorsim.pipelines.evaluate import evaluate_scene  # noqa: E402
from mirrorsim.pipelines.planning import plan_scene  # noqa: E402
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene  # noqa: E402
from mirrorsim.scene.model import Beacon  # noqa: E402
from solver.errors import SolverError  # noqa: E402
from solver.fit_model import power_terms
from solver.geometry import line_normal  # noqa: E402
from solver.lsq import solve_measurements
from solver.measurements import BeaconMeasurement  # noqa: E402
from solver.selfcal import (  # noqa: E402
    PLAIN,
    SelfCalibration,
    check_nuisances,
    describe_priors,
)


def _at_exact_positions(m, scene) -> list[BeaconMeasurement]:
    """The measured beacons with their exact positions in place of the believed ones."""
    return [BeaconMeasurement(tuple(b.position), mb.alpha_deg, mb.d_total)
            for b, mb in zip(scene.beacons, m.beacons, strict=True)]


def _board_errors(rep, scene, position_sigma: float, nuisances: tuple[str, ...]
                  ) -> tuple[float, float]:
    """Target error self-calibrated on the measurements corrected by the board's camera
    pose (``rep``: evaluated with ``board_pose``), with believed and with exact positions."""
    m, truth = rep.measurements, np.asarray(rep.truth.target.position, float)
    exact = _at_exact_positions(m, scene)
    return tuple(float(np.linalg.norm(solve_measurements(
        m.observer, beacons, m.targets, sigma=m.sigma,
        calibration=SelfCalibration(nuisances, ps)).target - truth))
        for beacons, ps in ((m.beacons, position_sigma), (exact, 0.0)))


def _errors(rep, scene, position_sigma: float, nuisances: tuple[str, ...],
            priors: dict[str, float]) -> tuple[float, ...]:
    """Target error: plain and self-calibrated, with believed and with exact positions;
    the reference (plain, exact positions, the frame's shared errors taken out) and its
    two parts; self-calibrated for pan and scale only (believed positions); with
    ``priors``, self-calibrated with them (believed, then exact positions)."""
    m, truth = rep.measurements, np.asarray(rep.truth.target.position, float)
    exact = _at_exact_positions(m, scene)
    out = []
    for beacons, ps in ((m.beacons, position_sigma), (exact, 0.0)):
        for nu in ((), nuisances):
            sol = solve_measurements(m.observer, beacons, m.targets, sigma=m.sigma,
                                     calibration=SelfCalibration(nu, ps) if nu else PLAIN)
            out.append(float(np.linalg.norm(sol.target - truth)))
    # the shared errors as the truth has them: every image's α error and relative
    # d_total error, averaged (the target's image counts once, as the beacons' do)
    measured = [(b.alpha_deg, b.d_total) for b in m.beacons] + [m.targets[0]]
    true = [(t.alpha_deg, t.d_total) for t in (*rep.truth.beacons, rep.truth.target)]
    delta = float(np.mean([a - ta for (a, _), (ta, _) in zip(measured, true, strict=True)]))
    scale = float(np.mean([d / td for (_, d), (_, td) in zip(measured, true, strict=True)]))
    # the reference, then its two parts: each image's own α error alone (every d_total
    # true) and its own d_total error alone (every α true)
    for keep_a, keep_d in ((True, True), (True, False), (False, True)):
        def pick(a, d, ta, td, keep_a=keep_a, keep_d=keep_d):
            return a - delta if keep_a else ta, d / scale if keep_d else td

        known = [BeaconMeasurement(b.position, *pick(b.alpha_deg, b.d_total, *t))
                 for b, t in zip(exact, true[:-1], strict=True)]
        targets = [pick(a, d, *true[-1]) for a, d in m.targets]
        sol = solve_measurements(m.observer, known, targets, sigma=m.sigma)
        out.append(float(np.linalg.norm(sol.target - truth)))
    if {"pan", "scale"} < set(nuisances):  # what the nuisances beyond them add
        sol = solve_measurements(m.observer, m.beacons, m.targets, sigma=m.sigma,
                                 calibration=SelfCalibration(("pan", "scale"), position_sigma))
        out.append(float(np.linalg.norm(sol.target - truth)))
    else:
        out.append(float("nan"))
    for beacons, ps in ((m.beacons, position_sigma), (exact, 0.0)) if priors else ():
        sol = solve_measurements(m.observer, beacons, m.targets, sigma=m.sigma,
                                 calibration=SelfCalibration(nuisances, ps, priors))
        out.append(float(np.linalg.norm(sol.target - truth)))
    return tuple(out)


def _priors(spec, nuisances: tuple[str, ...]) -> dict[str, float]:
    """σ of each estimated nuisance from the spec's range for it (a uniform draw's):
    what a bench built to those tolerances knows before its frames."""
    bench = spec.data.get("bench", {})
    ranges = {"pan": ((bench.get("camera") or {}).get("pan_error"), 1.0),
              "scale": (spec.calibration_error, 1 / D_REF),
              "power": ((bench.get("mirror") or {}).get("curvature"), 1.0)}
    out = {}
    for n in nuisances:
        r, per = ranges[n]
        if isinstance(r, list) and r[1] > r[0]:
            out[n] = _uniform_sd(*r) * per
    return out


def _uniform_sd(lo: float, hi: float) -> float:
    """The σ of a uniform draw in [lo, hi], as a spec's ranges draw."""
    return (hi - lo) / np.sqrt(12)


def _power_check(rep, scene) -> tuple[np.ndarray, np.ndarray]:
    """Each image's own α error (after the frame's mean) beside what the mirror's power
    moves it by to first order (power_terms with the true 1/R, the vertex at the
    mirror's centre, the frame's mean taken out too)."""
    m, t = rep.measurements, rep.truth
    objs = [*t.beacons, t.target]
    err = np.array([b.alpha_deg for b in m.beacons] + [m.targets[0][0]]) - np.array(
        [o.alpha_deg for o in objs])
    R = scene.bench.curvature_radius
    yaw, centre = scene.mirror.yaw, np.asarray(scene.mirror.center, float)
    pts = np.array([o.position for o in objs], float)
    A, _ = power_terms((yaw, float(line_normal(yaw) @ centre)),
                       np.asarray(m.observer, float), pts, vertex=centre)
    pred = A / R if R else np.zeros(len(objs))
    return err - err.mean(), pred - pred.mean()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=40)
    ap.add_argument("--seed", type=int, help="default: a fresh one, printed")
    ap.add_argument("--spec", type=Path, default=ROOT / "scenes" / "dataset_spec_bench.yaml")
    ap.add_argument("--beacons", type=int, default=3)
    ap.add_argument("--step", type=float, default=2.0, help="the plan's grid step (cm)")
    ap.add_argument("--calibrate", default="pan,scale,power",
                    help="the nuisances the plan and the self-calibrated fits estimate")
    ap.add_argument("--out", type=Path, help="keep the frames here (default: a temp folder)")
    ap.add_argument("--lossless", action="store_true",
                    help="store every frame as PNG (the same scenes otherwise)")
    ap.add_argument("--error-model", type=Path,
                    help="the σ's that weight every fit, and its typical σ's the plan "
                         "(default: the ideal bench's model for the fits, the plan's "
                         "own default σ's)")
    ap.add_argument("--priors", action="store_true",
                    help="also self-calibrate with the spec's ranges as each nuisance's prior")
    a = ap.parse_args()
    nuisances = tuple(n.strip() for n in a.calibrate.split(",") if n.strip())
    check_nuisances(nuisances, a.beacons, 1)
    # the ideal bench's σ's unless given (not the bench model evaluate would take for
    # these scenes, whose priors would self-calibrate every fit, plain ones too)
    model = load_error_model(a.error_model) if a.error_model else default_error_model()
    seed = a.seed if a.seed is not None else int.from_bytes(os.urandom(3), "big")
    spec = load_spec(a.spec)
    lo, hi = spec.data.get("bench", {}).get("beacon", {}).get("known_position_offset", [0, 0])
    position_sigma = _uniform_sd(lo, hi)
    priors = _priors(spec, nuisances) if a.priors else {}
    if a.priors and not priors:
        sys.exit(f"--priors: {a.spec} draws none of {', '.join(nuisances)} from a range")
    print(f"self-calibration on rendered frames: {a.scenes} scenes of {a.spec.name}, seed "
          f"{seed}, {a.beacons} beacons planned and self-calibrated for "
          f"{', '.join(nuisances)}, believed positions off by U({lo}, {hi}) cm "
          f"per axis{'; frames stored as PNG, not JPEG' if a.lossless else ''}; σ's of "
          f"{a.error_model.name if a.error_model else 'the ideal bench’s error model'}; "
          f"{stamp()}\n")
    if a.priors:
        print(f"priors (the spec's ranges): "
              f"{describe_priors(priors)}\n")
    extra = (" self-calibrated with priors | … exact positions |" if a.priors else "") + (
        " board's pose, self-calibrated | board's pose, exact positions |")
    print("| scene | plain (cm) | self-calibrated | pan and scale only | plain, exact "
          "positions | self-calibrated, exact positions | reference: pan and scale known | "
          f"pan error ° | calibration error cm |{extra}\n|---|---|---|---|---|---|---|---|---|"
          + "---|---|" * a.priors + "---|---|")
    rows, skipped, own, moved, pose_err = [], [], [], [], []
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or Path(tmp)
        for i in range(a.scenes):
            scene = sample_scene(spec, np.random.default_rng(np.random.SeedSequence(
                seed, spawn_key=(i,))), f"sc{i:03d}")
            if a.lossless:  # after the draw: the same scenes, their frames stored as PNG
                scene = replace(scene, bench=replace(scene.bench, jpeg_quality=None))
            try:
                plan = plan_scene(scene, model.typical if a.error_model else None,
                                  n_beacons=a.beacons, step=a.step,
                                  calibration=SelfCalibration(nuisances, position_sigma))
            except (SolverError, ValueError) as exc:
                skipped.append(f"{scene.name}: plan: {exc}")
                continue
            h = scene.beacons[0].height
            beacons = tuple(Beacon((float(p[0]), float(p[1])), h,
                                   (float(p[0] + rng.uniform(lo, hi)),
                                    float(p[1] + rng.uniform(lo, hi))))
                            for p in plan.beacon_set.positions)
            scene = replace(scene, beacons=beacons)
            try:
                rep = evaluate_scene(scene, out / scene.name, progress=False, keep=(),
                                     error_model=model)
                # the same frames (reused), measured with the board's camera pose
                posed = evaluate_scene(scene, out / scene.name, progress=False, keep=(),
                                       error_model=model, board_pose=True)
                e = (_errors(rep, scene, position_sigma, nuisances, priors)
                     + _board_errors(posed, scene, position_sigma, nuisances))
                cp, bench = posed.camera_pose, scene.bench
                # the mount reads pan + pan_error: the board's offset should be its negative
                pose_err.append((cp.pan_offset_deg + bench.pan_error, cp.pitch_deg - bench.pitch,
                                 cp.roll_deg - bench.roll))
            except (DetectionError, SolverError, SceneError) as exc:
                # (SceneError: planned positions the scene file's checks refuse, which
                # evaluate runs on a scene it is given)
                # the frame's name without the (temporary) folder it was written to
                skipped.append(f"{scene.name}: {str(exc).replace(str(out) + os.sep, '')}")
                continue
            rows.append(e)
            o, p = _power_check(rep, scene)
            own.append(o)
            moved.append(p)
            print(f"| {scene.name} | {e[0]:.3f} | {e[1]:.3f} | {e[7]:.3f} | {e[2]:.3f} | "
                  f"{e[3]:.3f} | {e[4]:.3f} | "
                  f"{scene.bench.pan_error:+.2f} | {scene.bench.calibration_distance_error:+.2f} |"
                  + "".join(f" {x:.3f} |" for x in e[8:]),
                  flush=True)
    if not rows:
        sys.exit("no scene was measured: " + "; ".join(skipped[:3]))
    v = np.array(rows)
    med = [statistics.median(v[:, k]) for k in range(v.shape[1])]
    print(f"| **median** ({len(rows)} scenes) | **{med[0]:.3f}** | **{med[1]:.3f}** | "
          f"**{med[7]:.3f}** | **{med[2]:.3f}** | **{med[3]:.3f}** | **{med[4]:.3f}** | | |"
          + "".join(f" **{x:.3f}** |" for x in med[8:]))
    print(f"\nself-calibrated / plain, medians: {med[1] / med[0]:.2f} (believed positions), "
          f"{med[3] / med[2]:.2f} (exact positions); pan and scale only: "
          f"{med[7] / med[0]:.2f} (believed); the reference / plain: {med[4] / med[2]:.2f} "
          f"(exact)" + (f"; with priors: {med[8] / med[0]:.2f} (believed), "
                        f"{med[9] / med[2]:.2f} (exact)" if a.priors else "")
          + f"; with the board's camera pose: {med[-2] / med[0]:.2f} (believed), "
          f"{med[-1] / med[2]:.2f} (exact)")
    pe = np.abs(np.array(pose_err))
    print(f"\nthe board's camera pose against the bench's, {len(pe)} scenes (mean of each "
          f"scene's frames): pan RMS {np.sqrt(np.mean(pe[:, 0]**2)):.4f}° (at most "
          f"{pe[:, 0].max():.4f}°), pitch RMS {np.sqrt(np.mean(pe[:, 1]**2)):.4f}° (at most "
          f"{pe[:, 1].max():.4f}°), roll RMS {np.sqrt(np.mean(pe[:, 2]**2)):.4f}°")
    print(f"\nthe reference's parts, medians: each image's own α error alone (every d_total "
          f"true) {med[5]:.3f} cm, its own d_total error alone (every α true) {med[6]:.3f} cm")
    own, moved = np.concatenate(own), np.concatenate(moved)
    if moved.any():  # a spec with a curved mirror
        slope = float(moved @ own / (moved @ moved))
        print(f"\nthe images' own α errors (each frame's mean taken out), {len(own)} images, "
              f"against the mirror's power to first order (solver.lsq.power_terms, the "
              f"true 1/R, the vertex at the mirror's centre): slope {slope:.2f}, correlation "
              f"{np.corrcoef(moved, own)[0, 1]:.2f}; RMS {np.sqrt(np.mean(own**2)):.3f}°, "
              f"{np.sqrt(np.mean((own - moved)**2)):.3f}° with it taken out")
    for s in skipped:
        print(f"skipped {s}")


if __name__ == "__main__":
    main()
