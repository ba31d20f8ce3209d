"""Whether the printed error bars hold on scenes a user writes: scenes drawn by a
generator of this script's own (not the dataset specs' sampler, whose ranges the shipped
models were fitted on), across the domain docs/scenes.md's *Where the error bars are
checked* states, each accepted by `check` (no warning, every image whole in the
mirror), then evaluated as `mirrorsim evaluate SCENE` would (the model the scene's bench
calls for, its default render settings, a fresh seed).

    python benchmarks/acceptance.py --scenes 100 --seed S [--bench] [--workers 2]
    python benchmarks/acceptance.py --report renders/acceptance-S-ideal renders/acceptance-S-bench

The geometry is drawn from the camera outwards: a mirror at a bearing and distance from
the camera, turned to an incidence from square-on to grazing; the target placed along a
ray the camera's line of sight reflects into; beacons in front of the glass, up to its
ends; a wall across the camera's line to the target.  Every third scene has two or
three beacons (held through its draws), each pencil of its own height.  ``--bench``
draws every imperfection of a hand-built bench from the population the shipped bench
model declares (its tolerances: docs/reliability.md).  Each scene's record is a line of
``OUT/records.jsonl``; a run interrupted resumes where it stopped.

Prints (Markdown): the truth inside the 95 % ellipse (drawn where the error model's
tail puts its edge, with a Clopper–Pearson 95 % interval), the median Mahalanobis
distance, scenes that failed to evaluate, gross errors on ideal benches (an image's α
off by more than 0.05° or its d_total by more than 1 %; and, in brackets, how many have
an image off by more than 6 of its own σ's: the laws' Student-t tails put 3.5 % of the
target's α errors there, at the shipped ideal model's ν of 1.8), and the same by feature.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from acceptance_report import report  # noqa: E402  (the Markdown summary)
from clone import ROOT  # noqa: E402  (the clone first on sys.path)

GROSS_ALPHA_DEG, GROSS_D_PCT = 0.05, 1.0
RESOLUTIONS = ((960, 544), (1280, 720), (1600, 896), (1920, 1088))


def _unit(deg: float) -> np.ndarray:
    return np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])


def draw_scene(rng: np.random.Generator, name: str, bench: bool, beacons: int = 0) -> dict:
    """One candidate scene document (not yet checked); ``beacons``: that many (0: one,
    or two or three: see :func:`scene_for`)."""
    u = rng.uniform
    side = float(rng.choice([80.0, 90.0, 100.0]))
    cam = np.array([u(0, 20), u(0, 20)])
    width, height = RESOLUTIONS[int(rng.integers(len(RESOLUTIONS)))]
    # the mirror at a bearing and distance from the camera, turned to an incidence
    to_mirror = u(15, 75)
    centre = cam + u(25, 95) * _unit(to_mirror)
    incidence = u(-84, 84)  # its normal against the line back to the camera
    normal = _unit(to_mirror + 180.0 + incidence)
    yaw = math.degrees(math.atan2(normal[1], normal[0])) + 90.0
    mw, mh = u(10, 32), u(8, 25)
    along = _unit(yaw)
    # the target along the ray a line of sight to the glass reflects into
    p = centre + u(-0.45, 0.45) * mw * along
    ray = (p - cam) / np.linalg.norm(p - cam)
    out = ray - 2.0 * (ray @ normal) * normal
    target = p + u(8, 55) * out
    tw, th = u(6, 16), u(6, 18)
    count = beacons or (1 if rng.random() < 2 / 3 else int(rng.integers(2, 4)))
    beacons = []
    for _ in range(count):
        b = centre + u(2.5, 30) * normal + u(-0.5, 0.5) * mw * along
        beacons.append({"position": b.round(3).tolist(), "height": round(u(2, 8), 3)})
    at = u(0.25, 0.8)
    mid = cam + at * (target - cam)
    t = (target - cam) / max(np.linalg.norm(target - cam), 1e-9)
    half = u(6, 22) / 2 * np.array([-t[1], t[0]])
    hfov = u(35, 90)
    pick = rng.random()
    # the pan as a scene file gives it: at the mirror, the target, the beacon, or a
    # bearing near the mirror, as an experimenter points by hand
    pan = ("mirror" if pick < 0.5 else "target" if pick < 0.7 else "beacon" if pick < 0.8
           else round(to_mirror + u(-0.25, 0.25) * hfov, 3))
    doc = {"name": name, "board": {"size": [side, side], "hole_pitch": 2.5},
           "camera": {"position": cam.round(3).tolist(), "height": round(u(3, 15), 3),
                      "resolution": [width, height], "hfov": round(hfov, 3), "pan": pan},
           "mirror": {"center": centre.round(3).tolist(), "yaw": round(yaw % 360.0, 3),
                      "size": [round(mw, 3), round(mh, 3)]},
           "target": {"position": target.round(3).tolist(),
                      "size": [round(tw, 3), round(th, 3)]},
           "beacons": beacons,
           "occluders": [{"start": (mid - half).round(3).tolist(),
                          "end": (mid + half).round(3).tolist(),
                          "height": round(u(12, 30), 3)}],
           "render": {"seed": int(rng.integers(1, 2**31))}}
    if bench:
        _bench(rng, doc)
    return doc


def _bench(rng: np.random.Generator, doc: dict) -> None:
    """Every imperfection drawn from the shipped bench model's declared population."""
    from mirrorsim.formats.error_model_file import default_error_model

    u = rng.uniform
    model = default_error_model("bench")
    ranges = model.domain.bench
    t = model.tolerances
    get = lambda key: u(*ranges[key])  # noqa: E731
    cam = doc["camera"]
    cam["pan_error"] = round(u(-t.pan_deg, t.pan_deg), 4)
    cam["pitch"], cam["roll"] = round(get("camera.pitch"), 4), round(get("camera.roll"), 4)
    cam["distortion"] = [round(get("camera.distortion[0]"), 5), 0.0]
    cam["distortion_known"] = bool(rng.integers(2))
    cam["noise"] = {"full_well": round(get("camera.noise.full_well"), 1),
                    "read_noise": round(get("camera.noise.read_noise"), 3)}
    lo, hi = ranges["camera.jpeg_quality"]
    cam["jpeg_quality"] = int(rng.integers(int(lo), int(hi) + 1))
    c = u(-t.curvature_per_cm, t.curvature_per_cm)
    if abs(c) > 1e-6:
        doc["mirror"]["curvature_radius"] = round(1.0 / c, 2)
    doc["mirror"]["tilt"] = round(get("mirror.tilt"), 4)
    doc["calibration"] = {"distance_error": round(u(-t.calibration_cm, t.calibration_cm), 4)}
    for b in doc["beacons"]:
        b["known_position"] = [round(p + u(-t.beacon_position_cm, t.beacon_position_cm), 4)
                               for p in b["position"]]


def accepted(doc: dict):
    """The scene if `check` accepts it without a warning and shows every image whole,
    else None."""
    from mirrorsim.errors import SceneError
    from mirrorsim.pipelines.scenes import scene_from_dict
    from mirrorsim.truth import visibility

    try:
        scene = scene_from_dict(doc, source=doc["name"], default_name=doc["name"])
    except SceneError:
        return None
    if scene.warnings:
        return None
    if all(visibility.visibility(scene, o).fraction == 1.0
           for o in (scene.target, *scene.beacons)):
        return scene
    return None


def scene_for(seed: int, i: int, bench: bool, beacons: int = 0) -> tuple[dict, int]:
    """Scene i of a run: the first accepted draw of its own stream, and the draws taken."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(i, int(bench))))
    name = f"{'bench' if bench else 'ideal'}{i:04d}"
    # every third scene two or three beacons, kept through its draws: drawn per draw,
    # check refuses more of those, and a third became 10-24 % of the accepted scenes
    count = beacons or (1 if i % 3 != 2 else 2 + (i // 3) % 2)
    for tries in range(1, 20001):
        doc = draw_scene(rng, name, bench, count)
        if accepted(doc) is not None:
            return doc, tries
    raise RuntimeError(f"no accepted scene in 20000 draws for {name}")


def _features(scene, report) -> dict:
    """What the breakdown groups the scenes by (from the scene and its report: the
    images' measured heights in pixels, where the reflections fall on the glass)."""
    mirror = scene.mirror
    centre = np.asarray(mirror.center, float)
    axis = _unit(mirror.yaw)
    t = report.truth
    ends = [abs((np.asarray(o.reflection_point) - centre) @ axis) / (mirror.size[0] / 2)
            for o in (t.target, *t.beacons)]
    cam = np.asarray(scene.camera.position, float)
    to_glass = centre - cam
    cos_i = abs(to_glass @ mirror.normal_towards(cam)) / np.linalg.norm(to_glass)
    return {"camera_to_mirror_cm": float(np.linalg.norm(to_glass)),
            "camera_height": scene.camera.height, "hfov": scene.camera.hfov,
            "width_px": scene.camera.resolution[0],
            "pencil_min_cm": min(b.height for b in scene.beacons),
            "pencil_max_cm": max(b.height for b in scene.beacons),
            "beacon_px_min": min(f.height_px for f in report.image_features[1:]),
            "glass_end": max(ends),
            "grazing_deg": 90.0 - math.degrees(math.acos(min(cos_i, 1.0))),
            "beacons": len(scene.beacons),
            "beacon_depth_min_cm": min(
                abs((np.asarray(b.position) - centre) @ mirror.normal_towards(cam))
                for b in scene.beacons)}


def _worst_image(rep) -> float:
    """The largest error of any image's α or d_total over its own σ."""
    e, sig = rep.errors, rep.measurements.sigma
    beacons = sig.beacons * len(e.beacon_alpha_deg) if len(sig.beacons) == 1 else sig.beacons
    worst = 0.0
    images = zip((sig.target, *beacons), (e.target_alpha_deg, *e.beacon_alpha_deg),
                 (e.target_d_total_pct, *e.beacon_d_total_pct), strict=True)
    for s, da, dp in images:
        worst = max(worst, abs(da) / math.hypot(s.alpha_deg, sig.shared_alpha_deg),
                    abs(dp) / 100.0 / s.d_total_rel)
    return worst


def run_one(job: tuple) -> dict:
    """Evaluate one scene as `mirrorsim evaluate` does; its record."""
    import warnings

    from mirrorsim.pipelines.evaluate import evaluate_scene
    from mirrorsim.pipelines.scenes import scene_from_dict

    doc, tries, out, bench, threads = job
    from mirrorsim.rendering.backend import set_render_threads

    set_render_threads(threads)
    scene = scene_from_dict(doc, source=doc["name"], default_name=doc["name"])
    record = {"scene": doc["name"], "bench": bench, "tries": tries, "doc": doc}
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a JPEG frame says so; the record keeps all
            rep = evaluate_scene(scene, Path(out) / doc["name"], progress=False, keep=())
    except Exception as exc:  # a failure to evaluate is a result here
        record.update(failed=f"{type(exc).__name__}: {exc}")
        return record
    e = rep.errors
    alpha = [e.target_alpha_deg, *e.beacon_alpha_deg]
    dpct = [e.target_d_total_pct, *e.beacon_d_total_pct]
    major, minor, _ = rep.solution.ellipse95()
    worst_z = _worst_image(rep)
    # counted at sigma_laws.GROSS σ's, without the Student-t's 99.9 % reach `errormodel`
    # adds: at the shipped ideal model's target α ν of 1.8 that reach is 45 σ, and next
    # to no error would count
    from mirrorsim.pipelines.sigma_laws import GROSS
    plain_cm = math.nan
    if len(scene.beacons) > 1:  # plain least squares on the same measurements and σ's
        from solver.lsq import solve_measurements

        m = rep.measurements
        try:
            plain = solve_measurements(m.observer, m.beacons, m.targets, sigma=m.sigma)
            plain_cm = float(np.linalg.norm(plain.target - np.asarray(rep.truth.target.position)))
        except Exception:  # noqa: BLE001 - a plain solve that fails is a result here
            pass
    record.update(
        plain_cm=plain_cm, notes=list(rep.calibration_notes),
        failed="", seconds=time.perf_counter() - t0, mahalanobis=e.target_mahalanobis,
        inside95=bool(e.target_inside95), radius95=rep.solution.tail.radius(0.95),
        radius50=rep.solution.tail.radius(0.5),
        target_cm=e.target_cm,
        crlb_cm=e.target_crlb_cm, major95=major, minor95=minor,
        gross=bool(max(alpha) > GROSS_ALPHA_DEG or max(dpct) > GROSS_D_PCT),
        gross_sigma=bool(worst_z > GROSS), worst_sigma=worst_z,
        worst_alpha_deg=max(alpha), worst_d_pct=max(dpct), model=rep.error_model,
        warnings=list(rep.model_warnings), features=_features(scene, rep),
        nuisances=dict(rep.solution.nuisances))
    return record


def run(n: int, seed: int, bench: bool, out: Path, workers: int, beacons: int = 0) -> Path:
    """Evaluate n scenes into ``out`` (resuming a run there); the records' file."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "records.jsonl"
    done = set()
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                done.add(json.loads(line)["scene"])
            except (ValueError, KeyError):
                continue  # a line cut by an interruption: its scene runs again
    jobs = []
    threads = max(1, (os.cpu_count() or 1) // workers)
    for i in range(n):
        name = f"{'bench' if bench else 'ideal'}{i:04d}"
        if name not in done:
            doc, tries = scene_for(seed, i, bench, beacons)
            jobs.append((doc, tries, str(out / "frames"), bench, threads))
    t0 = time.perf_counter()
    with ProcessPoolExecutor(workers) as pool, path.open("a") as f:
        futures = [pool.submit(run_one, j) for j in jobs]
        for k, fut in enumerate(as_completed(futures), 1):
            rec = fut.result()
            f.write(json.dumps(rec) + "\n")
            f.flush()
            rate = k / (time.perf_counter() - t0) * 60
            print(f"[{k}/{len(jobs)}] {rec['scene']}: "
                  + (f"failed: {rec['failed'][:80]}" if rec["failed"] else
                     f"{rec['mahalanobis']:.2f} σ, {rec['target_cm']:.3f} cm")
                  + f"  ({rate:.1f} scenes/min, ETA {(len(jobs) - k) / max(rate, 1e-9):.0f} min)",
                  file=sys.stderr, flush=True)
    return path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", type=int, default=100)
    p.add_argument("--seed", type=int, default=None, help="the run's seed (required to run)")
    p.add_argument("--bench", action="store_true", help="hand-built benches")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--beacons", type=int, default=0, choices=(0, 1, 2, 3),
                   help="every scene with this many beacons (default 0: one, or two or "
                   "three every third scene); with several, the report compares the "
                   "self-calibrated error with plain least squares'")
    p.add_argument("--out", type=Path, default=None,
                   help="records folder (default renders/acceptance-SEED-KIND)")
    p.add_argument("--report", type=Path, nargs="+", help="only summarize these runs' folders")
    a = p.parse_args()
    if a.report:
        folders = a.report
    else:
        if a.seed is None:
            p.error("--seed is required to run scenes")
        out = a.out or ROOT / "renders" / f"acceptance-{a.seed}-{'bench' if a.bench else 'ideal'}"
        run(a.scenes, a.seed, a.bench, out, a.workers, a.beacons)
        folders = [out]
    print(report(folders))


if __name__ == "__main__":
    main()
