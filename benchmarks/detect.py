"""Benchmark: the detector's accuracy on rendered full-size frames, by sampler and spp.

    python benchmarks/detect.py [--frames 20] [--spec SPEC]
                                [--render independent:16 multijitter:4 …] [--seed 0] [--out FILE]
    python benchmarks/detect.py --offaxis [-25 -20 … 25] [--render multijitter:4]
                           [--plot docs/detect_offaxis.png]

``--render``: the render settings compared, each SAMPLER:SPP (uniform) or
SAMPLER:SPP:BACKGROUND_SPP (fewer samples outside the mirror's image), every one over
all the frames (default: the scenes' own settings: the spec's, or mirrorsim's).

``--offaxis``: the default scene with the camera panned so that the target's image lies
each given angle off the optical axis; the signed errors of α and d_total (target and
beacon) against that angle, as a table and a plot.

Frames: the bundled scenes (default, exp1–3) and random valid variations of the default
scene (mirror pose, target and beacon positions; kept only if the scene validates and
both images are whole in the mirror).  Errors are against each render's exact ground
truth.  Prints Markdown tables: median and 95th percentile of |Δα| and |Δd|/d for target
and beacon, end-to-end target error, gross errors and false clips, detection time per
frame, for each render setting.
"""

from __future__ import annotations

import argparse
import copy
import json
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml
from clone import ROOT  # noqa: E402  (the clone first on sys.path)

from mirrorsim.detection.detector import detect_frame
from mirrorsim.detection.frame_files import read_stored_frame
from mirrorsim.errors import DetectionError, SceneError  # noqa: E402
from mirrorsim.formats.error_model_file import default_error_model
from mirrorsim.pipelines.calibrate import calibrate  # noqa: E402
from mirrorsim.pipelines.frame import (
    render_and_measure,  # noqa: E402
    render_to_files,  # noqa: E402
)
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene  # noqa: E402
from mirrorsim.pipelines.scenes import load_scene, scene_from_dict  # noqa: E402
from mirrorsim.truth import optics, visibility  # noqa: E402
from solver.lsq import solve_measurements  # noqa: E402

BUNDLED = ("default", "exp1", "exp2", "exp3")


def random_scenes(n: int, rng: np.random.Generator) -> list:
    """Valid variations of the default scene with both images whole in the mirror."""
    base = yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text())
    out, tries = [], 0
    while len(out) < n and tries < 5000:
        tries += 1
        d = copy.deepcopy(base)
        d["name"] = f"random{len(out):03d}"
        d["mirror"]["center"] = [float(rng.uniform(20, 45)), float(rng.uniform(45, 70))]
        d["mirror"]["yaw"] = float(rng.uniform(0, 45))
        d["target"]["position"] = [float(rng.uniform(35, 78)), float(rng.uniform(25, 78))]
        yaw = np.radians(d["mirror"]["yaw"])
        n_hat = np.array([np.sin(yaw), -np.cos(yaw)])  # towards the camera's side
        along = np.array([np.cos(yaw), np.sin(yaw)])
        b = (np.array(d["mirror"]["center"]) + rng.uniform(4, 14) * n_hat
             + rng.uniform(-5, 5) * along)
        d["beacon"]["position"] = [float(b[0]), float(b[1])]
        d["camera"]["pan"] = "mirror"
        try:
            s = scene_from_dict(d, default_name=d["name"])
        except SceneError:
            continue
        if s.warnings or any(visibility.visibility(s, o).fraction < 1 for o in (s.target,
                                                                            *s.beacons)):
            continue
        out.append(s)
    return out


def with_render(scene, config: str | None):
    """The scene with the render setting SAMPLER:SPP (uniform) or
    SAMPLER:SPP:BACKGROUND_SPP (None: as it is)."""
    if config is None:
        return scene
    sampler, spp, *bg = config.split(":")
    return replace(scene, render=replace(scene.render, sampler=sampler, spp=int(spp),
                                         background_spp=int(bg[0]) if bg else int(spp)))


def label(scene) -> str:
    r = scene.render
    return f"{r.sampler}:{r.spp}" + (f":{r.background_spp}" if r.background_spp < r.spp
                                      else "")


def measure(scene, tmp: Path) -> dict:
    # render, calibrate and detect written out (not pipelines.frame): the detector alone
    # is timed
    spp = label(scene)
    res = render_to_files(scene, tmp / scene.name, progress=False)
    stored = read_stored_frame(res.image)  # its pixels and its kind, from one read
    img, lossy = stored.pixels, stored.subsampled
    cal = calibrate(scene.camera, scene.target.size, scene.beacons[0].height,
                    subsampled=lossy)
    t0 = time.perf_counter()
    try:
        out = detect_frame(img, res.capture, cal, subsampled=lossy)
    except DetectionError as exc:
        return {"scene": scene.name, "spp": spp, "error": str(exc)}
    dt = time.perf_counter() - t0
    t, b = res.truth.target, res.truth.beacons[0]
    mt, mb = out.target, out.beacons[0][1]
    target_cm = None
    if mt.d_total is not None:  # end to end: the solver on these measurements
        meas = out.measurements()
        sigma = default_error_model().sigmas(out.features(out.target),
                                             [out.features(m) for _, m in out.beacons],
                                             meas.observer_pan_deg, fx_px=scene.camera.fx)
        sol = solve_measurements(meas.observer, meas.beacons, meas.targets, sigma=sigma)
        target_cm = float(np.linalg.norm(sol.target - np.asarray(t.position)))
    return {
        "scene": scene.name, "spp": spp, "seconds": dt, "target_cm": target_cm,
        "target_clipped": mt.clipped, "truth_clipped": t.clipped,
        "off_axis_deg": t.alpha_deg - scene.camera.pan_deg,
        "target_dalpha": abs(mt.alpha_deg - t.alpha_deg),
        "target_drel": None if mt.d_total is None else abs(mt.d_total - t.d_total) / t.d_total,
        "beacon_dalpha": abs(mb.alpha_deg - b.alpha_deg),
        "beacon_drel": abs(mb.d_total - b.d_total) / b.d_total,
        "target_d": t.d_total, "beacon_d": b.d_total,
        "beacon_drel_signed": (mb.d_total - b.d_total) / b.d_total,
    }


def summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if "error" not in r]

    def stat(key, scale=1.0):
        v = np.array([r[key] for r in ok if r[key] is not None]) * scale
        return (float(np.median(v)), float(np.percentile(v, 95))) if len(v) else (np.nan,) * 2

    gross = [r for r in ok if max(r["target_dalpha"], r["beacon_dalpha"]) > 0.1
             or max(r["target_drel"] or 0, r["beacon_drel"]) > 0.03]
    false_clip = [r for r in ok if r.get("target_clipped") and not r.get("truth_clipped")]
    return {"frames": len(rows), "failed": len(rows) - len(ok),
            "target_alpha": stat("target_dalpha"), "target_d_pct": stat("target_drel", 100),
            "beacon_alpha": stat("beacon_dalpha"), "beacon_d_pct": stat("beacon_drel", 100),
            "target_cm": stat("target_cm"), "gross": [r["scene"] for r in gross],
            "false_clipped": [r["scene"] for r in false_clip], "seconds": stat("seconds")}


def table(title: str, summaries: dict) -> str:
    lines = [f"\n{title}\n",
             "| sampler:spp | frames (failed) | target \\|Δα\\| ° median / p95 | "
             "target \\|Δd\\|/d % median / p95 | beacon \\|Δα\\| ° median / p95 | "
             "beacon \\|Δd\\|/d % median / p95 |"
             " end-to-end target cm median / p95 | gross errors | false clips |"
             " detect s median |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for spp, s in summaries.items():
        f = lambda p, nd: f"{p[0]:.{nd}f} / {p[1]:.{nd}f}"  # noqa: E731
        lines.append(f"| {spp} | {s['frames']} ({s['failed']}) | {f(s['target_alpha'], 4)} | "
                     f"{f(s['target_d_pct'], 3)} | {f(s['beacon_alpha'], 4)} | "
                     f"{f(s['beacon_d_pct'], 3)} | {f(s['target_cm'], 3)} | "
                     f"{len(s['gross'])} | {len(s['false_clipped'])} | {s['seconds'][0]:.2f} |")
    return "\n".join(lines)


def offaxis_scenes(angles: list[float]) -> list:
    """The default scene panned to put the target's image ``angle`` off the axis."""
    base = yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text())
    ref = scene_from_dict(base)
    alpha = optics.mirror_image(ref.camera.position, ref.mirror, ref.target.position).alpha_deg
    out = []
    for a in angles:
        d = copy.deepcopy(base)
        d["name"] = f"offaxis{a:.1f}".replace("-", "m")
        d["camera"]["pan"] = float(alpha - a)  # +a: α − pan = a, the image left of the axis
        out.append(scene_from_dict(d, default_name=d["name"]))
    return out


def measure_signed(scene, tmp: Path) -> dict:
    """Signed errors of one frame (target and beacon), with the target's off-axis angle."""
    spp = label(scene)
    m = render_and_measure(scene, tmp / scene.name, progress=False)
    res, det = m.files, m.detection
    t, b = res.truth.target, res.truth.beacons[0]
    mt, mb = det.target, det.beacons[0][1]
    return {"scene": scene.name, "spp": spp,
            "off_axis_deg": t.alpha_deg - scene.camera.pan_deg,  # as the dataset's column
            "target_dalpha": mt.alpha_deg - t.alpha_deg,
            "target_drel": None if mt.d_total is None else (mt.d_total - t.d_total) / t.d_total,
            "target_clipped": mt.clipped,
            "beacon_dalpha": mb.alpha_deg - b.alpha_deg,
            "beacon_drel": (mb.d_total - b.d_total) / b.d_total}


def offaxis_main(args) -> None:
    scenes = [with_render(s, args.render[0]) for s in offaxis_scenes(args.offaxis)]
    setting = label(scenes[0])
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for s in scenes:
            rows.append(measure_signed(s, Path(tmp)))
            print(f"{s.name}: {rows[-1]}", file=sys.stderr)
    print(f"Off-axis sweep, default scene, 1920×1088, {setting}; {platform.machine()}")
    print("\n| target off axis α − pan (°) | target Δα (°) | target Δd/d (%) | beacon Δα (°) | "
          "beacon Δd/d (%) | clipped |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        dd = "—" if r["target_drel"] is None else f"{100 * r['target_drel']:+.3f}"
        print(f"| {r['off_axis_deg']:+.1f} | {r['target_dalpha']:+.4f} | {dd} | "
              f"{r['beacon_dalpha']:+.4f} | {100 * r['beacon_drel']:+.3f} | "
              f"{r['target_clipped'] or 'no'} |")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        x = [r["off_axis_deg"] for r in rows]
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
        a1.plot(x, [r["target_dalpha"] for r in rows], "o-", label="target")
        a1.plot(x, [r["beacon_dalpha"] for r in rows], "s-", label="beacon")
        a1.set_xlabel("target's image off the optical axis, α − pan (°)")
        a1.set_ylabel("α error (°)")
        a2.plot(x, [100 * (r["target_drel"] or np.nan) for r in rows], "o-", label="target")
        a2.plot(x, [100 * r["beacon_drel"] for r in rows], "s-", label="beacon")
        a2.set_xlabel("target's image off the optical axis, α − pan (°)")
        a2.set_ylabel("d_total error (%)")
        for a in (a1, a2):
            a.axhline(0, color="k", lw=0.5)
            a.grid(alpha=0.3)
            a.legend()
        fig.suptitle(f"detector errors against off-axis angle (default scene, {setting})")
        fig.tight_layout()
        fig.savefig(args.plot, dpi=110)
        print(f"\nplot: {args.plot}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--offaxis", type=float, nargs="*",
                    help="off-axis angles of the target's image (default −25…25 in 5° steps)")
    ap.add_argument("--plot", type=Path, help="with --offaxis: the plot to write")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--render", nargs="*", default=[None], metavar="SAMPLER:SPP",
                    help="render settings to compare (default: the scenes' own)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spec", type=Path, help="draw the frames from a dataset spec (e.g. "
                    "scenes/dataset_spec.yaml) instead of the bundled scenes and variations")
    ap.add_argument("--out", type=Path, help="write all rows as JSON here")
    args = ap.parse_args()
    if args.offaxis is not None:
        args.offaxis = args.offaxis or [float(a) for a in range(-25, 26, 5)]
        offaxis_main(args)
        return

    rng = np.random.default_rng(args.seed)
    if args.spec:
        spec = load_spec(args.spec)
        scenes = [sample_scene(spec, np.random.SeedSequence(args.seed, spawn_key=(i,)),
                               f"spec{i:03d}") for i in range(args.frames)]
    else:
        bundled = [load_scene(ROOT / "scenes" / f"{n}.yaml") for n in BUNDLED]
        scenes = bundled + random_scenes(max(0, args.frames - len(bundled)), rng)
    by_config: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for config in args.render:
            for k, s in enumerate(scenes):
                s = with_render(s, config)
                row = measure(s, Path(tmp))
                by_config.setdefault(label(s), []).append(row)
                print(f"[{label(s)} {k + 1}/{len(scenes)}] {s.name}: {row}", file=sys.stderr)
    print(f"Detector accuracy, 1920×1088 frames; {platform.machine()}, Python "
          f"{platform.python_version()}, seed {args.seed}")
    print(table(f"{len(scenes)} frames{' of ' + str(args.spec) if args.spec else ''}:",
                {c: summary(rows) for c, rows in by_config.items()}))
    for c, rows in by_config.items():
        s = summary(rows)
        for r in rows:
            if "error" in r:
                print(f"\n{c} failed: {r['scene']}: {r['error']}")
            elif r["scene"] in s["gross"] or r["scene"] in s["false_clipped"]:
                print(f"\n{c} gross error or false clip: {r}")
    if args.out:
        args.out.write_text(json.dumps(by_config, indent=1))


if __name__ == "__main__":
    main()
