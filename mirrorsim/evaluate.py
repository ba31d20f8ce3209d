"""End to end: render → detect → solve → score against the exact ground truth.

One frame per beacon (a scene with ``beacons:`` renders each beacon alone, as a moving
beacon would be photographed at each pose); the target is measured in every frame.
The solver sees only the measurements; the score compares its estimate with the
ground truth.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from mirrorsim import optics
from mirrorsim.calibrate import calibrate
from mirrorsim.detect import DetectorView, annotate, detect_frame, read_frame, write_png
from mirrorsim.render import render_scene
from mirrorsim.scene import Scene
from solver.geometry import line_normal
from solver.sltr import BeaconMeasurement, Sigma, solve_measurements

# Measurement σ's the solver weights with: the detector's accuracy on full-size frames
# at 16 spp (bench/detect.py; README): α to ~0.005° (p95), the target's d_total to ~0.1 %,
# the pencil's to ~0.6 % (median).  One σ_d serves both: the larger.
DETECTOR_SIGMA = Sigma(alpha_deg=0.005, d_total_rel=0.006)


def scene_fingerprint(scene: Scene, spp: int, seed: int) -> str:
    """What a render depends on: the scene's content (not its file name), spp, seed."""
    d = asdict(replace(scene, source="", warnings=()))
    text = json.dumps(d, sort_keys=True, default=str) + f"|{spp}|{seed}"
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _frame(scene: Scene, out: Path, spp: int, seed: int, variant: str, progress: bool):
    """Render, or reuse a render of exactly this scene, spp and seed."""
    fp = scene_fingerprint(scene, spp, seed)
    png, js = out / f"{scene.name}.png", out / f"{scene.name}.json"
    if png.exists() and js.exists():
        try:
            truth = json.loads(js.read_text())
            if truth.get("render", {}).get("fingerprint") == fp:
                return png, truth, True
        except (OSError, ValueError):
            pass
    res = render_scene(scene, out, spp=spp, seed=seed, variant=variant, progress=progress,
                       fingerprint=fp)
    return res.png, res.truth, False


def evaluate_scene(scene: Scene, out_dir: str | Path | None = None, *, spp: int | None = None,
                   seed: int | None = None, variant: str = "auto", progress: bool = True,
                   sigma: Sigma = DETECTOR_SIGMA) -> dict:
    """Render (or reuse), detect, solve and score ``scene``; return the report."""
    spp = scene.render.spp if spp is None else spp
    seed = scene.render.seed if seed is None else seed
    out = Path(out_dir) if out_dir is not None else Path("renders") / scene.name
    cam = scene.camera
    cal = calibrate(cam, scene.target.size, scene.beacons[0].height, variant=variant)

    frames = []
    per_beacon = [scene] if len(scene.beacons) == 1 else [
        replace(scene, name=f"{scene.name}_b{i}", beacons=(b,))
        for i, b in enumerate(scene.beacons)]
    for sub in per_beacon:
        png, truth, reused = _frame(sub, out, spp, seed, variant, progress)
        image = read_frame(png)
        meas = detect_frame(image, DetectorView.from_scene(sub), cal)
        annotated = out / f"{sub.name}.annotated.png"
        write_png(annotated, annotate(image, meas))
        frames.append({"png": str(png), "annotated": str(annotated), "reused": reused,
                       "truth": truth, "measurements": meas})

    truth = optics.ground_truth(scene)
    beacons = [BeaconMeasurement(tuple(b.position), f["measurements"]["beacons"][0]["alpha_deg"],
                                 f["measurements"]["beacons"][0]["d_total"])
               for b, f in zip(scene.beacons, frames, strict=True)]
    targets = [(f["measurements"]["target"]["alpha_deg"], f["measurements"]["target"]["d_total"])
               for f in frames if f["measurements"]["target"]["d_total"] is not None]
    if not targets:
        raise RuntimeError("the target's d_total could not be measured in any frame "
                           "(its image is clipped at the top)")
    measurements = {
        "observer": list(cam.position),
        "target": {"alpha_deg": float(np.mean([t[0] for t in targets])),
                   "d_total": float(np.mean([t[1] for t in targets]))},
        "beacons": [{"position": list(b.position), "alpha_deg": b.alpha_deg,
                     "d_total": b.d_total} for b in beacons],
        "sigma": {"alpha_deg": sigma.alpha_deg, "d_total_rel": sigma.d_total_rel},
    }
    sol = solve_measurements(cam.position, beacons, targets, sigma)
    errors = score(truth, measurements, sol)
    report = {
        "scene": scene.name,
        "truth": truth,
        "measurements": measurements,
        "solution": sol.to_json(),
        "errors": errors,
        "frames": [{k: f[k] for k in ("png", "annotated", "reused")} for f in frames],
        "render": {"spp": spp, "seed": seed, "variant": frames[0]["truth"]["render"]["variant"]},
        "calibration": {"target_k": cal.target_k, "pencil_k": cal.pencil_k},
    }
    if len(beacons) > 1:
        report["error_vs_beacons"] = [
            {"beacons": k, **score(truth, measurements,
                                   solve_measurements(cam.position, beacons[:k], targets, sigma))}
            for k in range(1, len(beacons) + 1)]
    return report


def score(truth: dict, measurements: dict, sol) -> dict:
    """Errors of measurements and estimate against the ground truth (INTERFACE.md)."""
    t_true = np.asarray(truth["target"]["position"], float)
    rp_true = np.asarray(truth["target"]["reflection_point"], float)
    yaw_true = truth["mirror"]["yaw_deg"]
    yaw_est = sol.mirror.yaw_deg
    n = line_normal(yaw_est)
    t_meas = measurements["target"]
    return {
        "target_cm": float(np.linalg.norm(sol.target - t_true)),
        "mirror_yaw_deg": float(abs((yaw_est - yaw_true + 90.0) % 180.0 - 90.0)),
        # how far the estimated line passes from the true reflection point
        "mirror_offset_cm": float(abs(n @ (rp_true - sol.mirror.point))),
        "reflection_point_cm": float(np.linalg.norm(sol.target_reflection_point - rp_true)),
        "target_alpha_deg": float(abs(t_meas["alpha_deg"] - truth["target"]["alpha_deg"])),
        "target_d_total_pct": float(100 * abs(t_meas["d_total"] - truth["target"]["d_total"])
                                    / truth["target"]["d_total"]),
        "beacon_alpha_deg": [float(abs(m["alpha_deg"] - t["alpha_deg"]))
                             for m, t in zip(measurements["beacons"], truth["beacons"],
                                             strict=True)],
        "beacon_d_total_pct": [float(100 * abs(m["d_total"] - t["d_total"]) / t["d_total"])
                               for m, t in zip(measurements["beacons"], truth["beacons"],
                                               strict=True)],
        "target_rmse95_cm": _ellipse_bound(sol),
    }


def _ellipse_bound(sol) -> float | None:
    """The solver's own 95 % bound on the target error: the ellipse's major semi-axis."""
    e = sol.ellipse95()
    return None if e is None else float(e[0])


def report_table(report: dict) -> str:
    """The compact table `mirrorsim evaluate` prints."""
    t, m, s, e = report["truth"], report["measurements"], report["solution"], report["errors"]
    rows = [("", "truth", "measured", "estimate", "error")]
    rows.append(("target α (°)", f"{t['target']['alpha_deg']:.4f}",
                 f"{m['target']['alpha_deg']:.4f}", "", f"{e['target_alpha_deg']:.4f}"))
    rows.append(("target d_total (cm)", f"{t['target']['d_total']:.3f}",
                 f"{m['target']['d_total']:.3f}", "", f"{e['target_d_total_pct']:.3f} %"))
    for i, (tb, mb) in enumerate(zip(t["beacons"], m["beacons"], strict=True)):
        rows.append((f"beacon {i} α (°)", f"{tb['alpha_deg']:.4f}", f"{mb['alpha_deg']:.4f}", "",
                     f"{e['beacon_alpha_deg'][i]:.4f}"))
        rows.append((f"beacon {i} d_total (cm)", f"{tb['d_total']:.3f}", f"{mb['d_total']:.3f}",
                     "", f"{e['beacon_d_total_pct'][i]:.3f} %"))
    rows.append(("mirror yaw (°)", f"{t['mirror']['yaw_deg']:.3f}", "",
                 f"{s['mirror']['yaw_deg']:.3f}", f"{e['mirror_yaw_deg']:.3f}"))
    rows.append(("mirror line offset (cm)", "0", "", "", f"{e['mirror_offset_cm']:.3f}"))
    rp_t, rp_e = t["target"]["reflection_point"], s["target"]["reflection_point"]
    rows.append(("reflection point (cm)", f"({rp_t[0]:.2f}, {rp_t[1]:.2f})", "",
                 f"({rp_e[0]:.2f}, {rp_e[1]:.2f})", f"{e['reflection_point_cm']:.3f}"))
    tp, te = t["target"]["position"], s["target"]["position"]
    bound = e.get("target_rmse95_cm")
    rows.append(("target (cm)", f"({tp[0]:.2f}, {tp[1]:.2f})", "",
                 f"({te[0]:.2f}, {te[1]:.2f})", f"{e['target_cm']:.3f}"
                 + ("" if bound is None else f"  (95 %: {bound:.3f})")))
    widths = [max(len(r[k]) for r in rows) for k in range(5)]
    lines = ["  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                       for k, (c, w) in enumerate(zip(r, widths, strict=True))) for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    if "error_vs_beacons" in report:
        lines.append("target error with the first k beacons: " + ", ".join(
            f"{r['beacons']}: {r['target_cm']:.3f} cm" for r in report["error_vs_beacons"]))
    return "\n".join(lines)


