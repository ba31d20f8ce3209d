"""The ``mirrorsim`` command: argument parsing and printing only."""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from pathlib import Path

from mirrorsim.scene import load_scene
from solver.measurements import InputError
from solver.sltr import SolverError  # light: scipy is imported only where it is used


class BadArgument(ValueError):
    """A command-line value out of range (exit 2)."""

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1
VARIANT_CHOICES = ["auto", "cuda", "llvm", "scalar"]


def _scene_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", type=Path, help="scene file (YAML, see INTERFACE.md)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mirrorsim",
        description="Physically rendered mirror space for NLOS localization (SLTR): "
                    "render scenes with exact ground truth, check and plot them.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("render", help="render the frame and write its ground truth",
                       description="Render SCENE with Mitsuba 3 and write DIR/<name>.png (sRGB, "
                       "8-bit), DIR/<name>.json (exact ground truth, with each object's "
                       "bbox_px and visible_px in the mirror from an object-id pass) and "
                       "DIR/<name>.ids.png (the id labels).")
    _scene_arg(p)
    p.add_argument("--out", type=Path, help="output folder (default renders/<name>/)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's, else 16)")
    p.add_argument("--seed", type=int, help="sampler seed (default: the scene's, else 0)")
    p.add_argument("--variant", default="auto",
                   choices=VARIANT_CHOICES,
                   help="Mitsuba backend; auto = cuda if a GPU works, else llvm if its probe "
                   "renders, else scalar (default: auto)")
    p.add_argument("--json", metavar="FILE", help="also write the ground truth here (- = stdout)")
    p.add_argument("--quiet", action="store_true", help="no progress line")

    p = sub.add_parser("check", help="validate a scene and say what the camera sees",
                       description="Validate SCENE and print, for the target and each beacon, "
                       "its virtual image, alpha, d_total, reflection point and how much of "
                       "its image reaches the camera through the mirror. No rendering.")
    _scene_arg(p)
    p.add_argument("--json", metavar="FILE", help="write the exact ground truth (- = stdout)")
    p.add_argument("--measurements", metavar="FILE",
                   help="write the exact (noise-free) measurements for `mirrorsim solve`")

    p = sub.add_parser("plot", help="top view of a scene (board, camera, mirror, rays)",
                       description="Draw the top view: board, camera and its field of view, "
                       "occluders, mirror, target, beacons, virtual images and rays.")
    _scene_arg(p)
    p.add_argument("--out", type=Path, help="PNG to write (default renders/<name>/<name>.top.png)")

    p = sub.add_parser("detect", help="measure alpha and d_total from a rendered frame",
                       description="Find the target's and the beacons' images in FRAME and "
                       "measure each one's angle of arrival and, by size constancy, its "
                       "d_total.  Uses only the image, the scene's camera block, the beacons' "
                       "known positions and heights, the objects' sizes, and the calibration "
                       "(`mirrorsim calibrate`, made and cached on first use).")
    p.add_argument("frame", type=Path, help="the rendered PNG")
    p.add_argument("--scene", type=Path, required=True, help="the scene file (camera, beacons)")
    p.add_argument("--json", metavar="FILE", help="write the measurements (- = stdout)")
    p.add_argument("--annotate", type=Path, metavar="OUT.png",
                   help="draw the detections on the frame")
    p.add_argument("--variant", default="auto", choices=VARIANT_CHOICES,
                   help="backend for a calibration render, if one is needed")

    p = sub.add_parser("calibrate", help="size-constancy constants for a scene's camera",
                       description="Render the target and the pencil in direct view at 100 cm, "
                       "facing SCENE's camera on its optical axis, measure them as the detector "
                       "does and cache K = s_px * d per camera and object.")
    _scene_arg(p)
    p.add_argument("--refresh", action="store_true", help="re-render even if cached")
    p.add_argument("--variant", default="auto", choices=VARIANT_CHOICES)
    p.add_argument("--json", metavar="FILE")

    p = sub.add_parser("evaluate", help="render, detect, solve and score against ground truth",
                       description="The main job: render SCENE (or reuse a render of the same "
                       "scene, spp and seed), detect the target and beacons, localize mirror and "
                       "target, and score everything against the exact ground truth.  Prints a "
                       "table; writes DIR/<name>.report.json, DIR/<name>.eval.png (truth vs "
                       "estimate with the 95 %% error ellipse) and the annotated frame(s).  A "
                       "scene with several beacons renders one frame per beacon and reports "
                       "the error as beacons are added.  Exit 0 whenever it ran.")
    _scene_arg(p)
    p.add_argument("--out", type=Path, help="output folder (default renders/<name>/)")
    p.add_argument("--json", metavar="FILE", help="also write the report here (- = stdout)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's, else 16)")
    p.add_argument("--seed", type=int)
    p.add_argument("--variant", default="auto", choices=VARIANT_CHOICES)
    p.add_argument("--quiet", action="store_true", help="no progress line")

    p = sub.add_parser("dataset", help="many random scenes, rendered, detected and scored",
                       description="Draw N random valid scenes from a spec (default "
                       "scenes/dataset_spec.yaml), render, detect, solve and score each, in "
                       "parallel worker processes (or on a Dask cluster), and write "
                       "DIR/dataset.parquet (a row per scene), DIR/scenes/*.yaml, "
                       "DIR/frames/ and a dataset card DIR/README.md.  Interrupted runs "
                       "resume with --resume; the same seed gives the same rows whatever "
                       "the number of workers.")
    p.add_argument("--n", type=int, required=True, help="number of scenes")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2) // 2),
                   help="worker processes (default: half the cores)")
    p.add_argument("--spec", type=Path, help="ranges of the random scenes (YAML)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the spec's)")
    p.add_argument("--variant", default="auto", choices=VARIANT_CHOICES)
    p.add_argument("--resume", action="store_true", help="finish an interrupted run")
    p.add_argument("--executor", default="local", choices=["local", "dask"])
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler (tcp://host:8786); default: a local cluster")
    p.add_argument("--quiet", action="store_true")

    p = sub.add_parser("errormodel", help="fit the detector's error model to a dataset",
                       description="Fit bias and spread of alpha and d_total/d against "
                       "distance, off-axis bearing, mirror incidence and image size; write "
                       "DIR/error_model.json (give it to solve, montecarlo or plan with "
                       "--error-model) and DIR/error_model.png.")
    p.add_argument("dataset", type=Path)
    p.add_argument("--out", type=Path, help="model file (default DIR/error_model.json)")

    p = sub.add_parser("solve", help="localize the mirror and the target from measurements",
                       description="Read MEASUREMENTS.json (INTERFACE.md: observer, target "
                       "alpha/d_total, beacons with positions) and estimate the mirror line and "
                       "the target.  One beacon and no sigma: the exact closed form; otherwise "
                       "weighted least squares, with the target's covariance and 95 % error "
                       "ellipse when `sigma` is given.")
    p.add_argument("measurements", type=Path)
    p.add_argument("--json", metavar="FILE", help="write the solution (- = stdout)")
    p.add_argument("--error-model", type=Path, metavar="FILE",
                   help="take sigma from an error model (`mirrorsim errormodel`) where the "
                   "file gives none")

    p = sub.add_parser("montecarlo", help="the paper's Table 1 protocol",
                       description="Table 1 of the paper: d_total = 5, alpha = 70 deg, Gaussian "
                       "noise with the table's sigmas, ITERATIONS draws per row; RMSE of the "
                       "reflector (the target's reflection point) and of the target, next to "
                       "the paper's.  The paper does not say where the mirror and beacon stand: "
                       "the options below set them.")
    p.add_argument("--iterations", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--alpha", type=float, default=70.0, help="target's alpha (deg)")
    p.add_argument("--d-total", type=float, default=5.0, help="target's d_total")
    p.add_argument("--d1", type=float, default=3.0, help="observer → mirror along the ray")
    p.add_argument("--incidence", type=float, default=30.0,
                   help="mirror's turn from facing the ray square-on (deg)")
    p.add_argument("--beacon-depth", type=float, default=0.5,
                   help="beacon's distance in front of the mirror")
    p.add_argument("--beacon-along", type=float, default=0.3,
                   help="beacon's offset along the mirror from the reflection point")
    p.add_argument("--sigma", nargs=2, type=float, action="append", metavar=("ALPHA", "D"),
                   help="a row of your own (deg, distance units); repeatable")
    p.add_argument("--error-model", type=Path, metavar="FILE",
                   help="add a row with the σ's of an error model (`mirrorsim errormodel`)")
    p.add_argument("--json", metavar="FILE")

    p = sub.add_parser("plan", help="beacon placement analysis and the best beacon position",
                       description="For SCENE's camera and target measurement: the paper's "
                       "placement numbers (eqs 7-21: step b, half-width a/2, N_bea, the three "
                       "paths), the exact region where a beacon is seen for every mirror "
                       "orientation within +-eps, and the beacon position on the board with the "
                       "least expected target error over a prior of mirror poses around the "
                       "scene's mirror, with a heat map.")
    _scene_arg(p)
    p.add_argument("--sigma-alpha", type=float, default=0.01, help="deg (default 0.01)")
    p.add_argument("--sigma-d", type=float, default=0.002, help="relative (default 0.002)")
    p.add_argument("--eps", type=float, default=5.0, help="orientation range ±eps (deg)")
    p.add_argument("--yaw-spread", type=float, default=3.0, help="prior yaw ± (deg)")
    p.add_argument("--d1-spread", type=float, default=2.0, help="prior mirror distance ± (cm)")
    p.add_argument("--step", type=float, default=1.0, help="grid step of the search (cm)")
    p.add_argument("--error-model", type=Path, metavar="FILE",
                   help="take the σ's from an error model instead")
    p.add_argument("--out", type=Path, help="PNG (default renders/<name>/<name>.plan.png)")
    p.add_argument("--json", metavar="FILE")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    warnings.showwarning = _one_line_warning
    try:
        return _COMMANDS[args.command](args)
    except (InputError, BadArgument) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except SolverError as exc:
        print(f"error: cannot solve: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except RuntimeError as exc:  # DetectionError, BackendError: the run itself failed
        if type(exc).__name__ not in ("DetectionError", "BackendError"):
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0


def _at_least(*checks: tuple[str, int | None, int]) -> None:
    """Refuse (exit 2) an option given below its least value; None means not given."""
    for flag, value, low in checks:
        if value is not None and value < low:
            raise BadArgument(f"{flag}: {value} must be ≥ {low}")


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"warning: {message}", file=sys.stderr)


def _load(path: Path):
    scene = load_scene(path)
    for w in scene.warnings:
        print(f"warning: {path}: {w}", file=sys.stderr)
    return scene


def _write_json(dest: str | None, data: dict) -> None:
    if dest is None:
        return
    text = json.dumps(data, indent=2) + "\n"
    if dest == "-":
        sys.stdout.write(text)
    else:
        Path(dest).write_text(text)


def _cmd_render(args) -> int:
    from mirrorsim.backend import BackendError
    from mirrorsim.render import render_scene

    scene = _load(args.scene)
    _at_least(("--spp", args.spp, 1), ("--seed", args.seed, 0))
    try:
        res = render_scene(scene, args.out, spp=args.spp, seed=args.seed,
                           variant=args.variant, progress=not args.quiet)
    except BackendError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    t = res.truth
    print(f"{scene.name}: {res.png} ({scene.camera.width}×{scene.camera.height_px}, "
          f"{t['render']['spp']} spp, {res.variant}, {res.seconds:.1f} s)")
    print(f"ground truth: {res.truth_json}")
    for label, e in [("target", t["target"])] + [(f"beacon {i}", b)
                                                  for i, b in enumerate(t["beacons"])]:
        print(f"  {label:<9} α {e['alpha_deg']:9.4f}°  d_total {e['d_total']:8.3f} cm  "
              f"in mirror: {e['visible_px']} px, bbox {e['bbox_px']}")
    _write_json(args.json, t)
    return 0


def _cmd_check(args) -> int:
    from mirrorsim import optics

    scene = _load(args.scene)
    cam = scene.camera
    print(f"{scene.name}: valid.  camera at {list(cam.position)}, height {cam.height:g} cm, "
          f"pan {cam.pan_deg:.3f}°, hfov {cam.hfov:g}°, {cam.width}×{cam.height_px} px, "
          f"fx {cam.fx:.2f} px")
    print(f"mirror: centre {list(scene.mirror.center)}, yaw {scene.mirror.yaw % 180:g}°, "
          f"{scene.mirror.size[0]:g} × {scene.mirror.size[1]:g} cm")
    print(f"{'object':<9} {'alpha°':>9} {'d_total':>8} {'d1':>7} {'d2':>7} "
          f"{'reflection pt':>16} {'on mirror':>9} {'u px':>7} {'h px':>6} {'seen':>5}")
    objs = [("target", scene.target)] + [(f"beacon {i}", b) for i, b in enumerate(scene.beacons)]
    for label, obj in objs:
        img = optics.mirror_image(cam, scene.mirror, obj.position)
        ext = optics.image_extent(scene, obj)
        vis = optics.visibility(scene, obj)
        rp = f"({img.reflection_point[0]:.2f}, {img.reflection_point[1]:.2f})"
        print(f"{label:<9} {img.alpha_deg:9.3f} {img.d_total:8.3f} {img.d1:7.2f} {img.d2:7.2f} "
              f"{rp:>16} {img.mirror_offset:+9.2f} {ext.u_axis:7.1f} {ext.height_px:6.1f} "
              f"{100 * vis.fraction:4.0f}%")
        if vis.reason:
            print(f"          {vis.reason}")
    direct = optics.direct_view_fraction(scene, scene.target)
    print("target is hidden from the camera's direct view (NLOS)" if direct == 0.0 else
          f"target is {100 * direct:.0f}% directly visible: not NLOS")
    truth = optics.ground_truth(scene)
    _write_json(args.json, truth)
    if args.measurements:
        _write_json(args.measurements, {
            "observer": list(cam.position),
            "target": {"alpha_deg": truth["target"]["alpha_deg"],
                       "d_total": truth["target"]["d_total"]},
            "beacons": [{"position": b["position"], "alpha_deg": b["alpha_deg"],
                         "d_total": b["d_total"]} for b in truth["beacons"]],
            "source": "exact geometry (mirrorsim check)"})
    return 0


def _cmd_plot(args) -> int:
    from mirrorsim.plot import plot_top_view

    scene = _load(args.scene)
    out = args.out or Path("renders") / scene.name / f"{scene.name}.top.png"
    print(plot_top_view(scene, out))
    return 0


def _cmd_detect(args) -> int:
    from mirrorsim.calibrate import calibrate
    from mirrorsim.detect import DetectorView, annotate, detect_frame, read_frame, write_png

    scene = _load(args.scene)
    view = DetectorView.from_scene(scene)
    image = read_frame(args.frame)
    cal = calibrate(view.camera, view.target_size, view.beacons[0].height, variant=args.variant)
    res = detect_frame(image, view, cal)
    t = res["target"]
    d = "not measured (clipped)" if t["d_total"] is None else f"{t['d_total']:.3f} cm"
    print(f"{args.frame}: target α {t['alpha_deg']:.4f}°  d_total {d}"
          + ("  [clipped]" if t["clipped"] else ""))
    for i, b in enumerate(res["beacons"]):
        print(f"  beacon {i} at {b['position']}: α {b['alpha_deg']:.4f}°  d_total "
              f"{b['d_total']:.3f} cm (mirror image)")
    for im in res["detector"]["images"]:
        if im["source"] == "direct":
            print(f"  beacon {im['beacon_index']} also seen directly at u = {im['u_axis']:.1f} "
                  "px (not used)")
    if args.annotate:
        write_png(args.annotate, annotate(image, res))
        print(f"  annotated: {args.annotate}")
    _write_json(args.json, res)
    return 0


def _cmd_calibrate(args) -> int:
    from mirrorsim.calibrate import D_REF, calibrate
    from mirrorsim.detect import FRONT_OFFSET

    scene = _load(args.scene)
    cal = calibrate(scene.camera, scene.target.size, scene.beacons[0].height,
                    variant=args.variant, refresh=args.refresh)
    cam = scene.camera
    print(f"camera {cam.width}×{cam.height_px}, hfov {cam.hfov:g}°, height {cam.height:g} cm "
          f"(fx {cam.fx:.2f} px)")
    print(f"  target {scene.target.size[1]:g} cm high: K = {cal.target_k:.1f} px·cm "
          f"({cal.target_k / (D_REF - FRONT_OFFSET['target']):.2f} px at 1 m; the paper's "
          "camera: 229 px)")
    print(f"  pencil's painted band: K = {cal.pencil_k:.1f} px·cm "
          f"({cal.pencil_k / (D_REF - FRONT_OFFSET['beacon']):.2f} px at 1 m)")
    _write_json(args.json, {"key": cal.key, "target_k": cal.target_k, "pencil_k": cal.pencil_k})
    return 0


def _cmd_evaluate(args) -> int:
    from mirrorsim.evaluate import evaluate_scene, report_table
    from mirrorsim.plot import plot_evaluation

    scene = _load(args.scene)
    _at_least(("--spp", args.spp, 1), ("--seed", args.seed, 0))
    out = args.out or Path("renders") / scene.name
    report = evaluate_scene(scene, out, spp=args.spp, seed=args.seed, variant=args.variant,
                            progress=not args.quiet)
    reused = all(f["reused"] for f in report["frames"])
    print(f"{scene.name}: {len(report['frames'])} frame(s), {report['render']['spp']} spp, "
          f"{report['render']['variant']}{' (reused)' if reused else ''}")
    print(report_table(report))
    path = out / f"{scene.name}.report.json"
    path.write_text(json.dumps(report, indent=2) + "\n")
    fig = plot_evaluation(scene, report, out / f"{scene.name}.eval.png")
    print(f"report: {path}\ntop view: {fig}\nannotated: "
          + ", ".join(f["annotated"] for f in report["frames"]))
    _write_json(args.json, report)
    return 0


def _cmd_dataset(args) -> int:
    from mirrorsim.dataset import DatasetError, run_dataset

    _at_least(("--n", args.n, 1), ("--seed", args.seed, 0), ("--workers", args.workers, 1),
              ("--spp", args.spp, 1))
    try:
        res = run_dataset(args.n, args.seed, args.out, workers=args.workers,
                          spec_path=args.spec, spp=args.spp, variant=args.variant,
                          resume=args.resume, executor=args.executor,
                          scheduler=args.scheduler, progress=not args.quiet)
    except DatasetError as exc:
        raise BadArgument(str(exc)) from None
    print(f"{args.out}: {res['rows']} rows ({res['computed']} computed now in "
          f"{res['seconds']:.0f} s, {res['per_minute']:.1f} scenes/min; "
          f"{res['already_done']} already done; {res['failed']} failed) → {res['parquet']}")
    return 0


def _cmd_errormodel(args) -> int:
    from mirrorsim import errormodel

    if not (args.dataset / "dataset.parquet").exists():
        raise BadArgument(f"{args.dataset}: no dataset.parquet here (run `mirrorsim dataset`)")
    cols = errormodel.read_columns(args.dataset)
    try:
        model = errormodel.fit(cols)
    except ValueError as exc:
        raise BadArgument(f"{args.dataset}: {exc}") from None
    out = args.out or args.dataset / "error_model.json"
    errormodel.write_model(model, out)
    png = errormodel.plot(cols, model, out.with_suffix(".png"))
    print(errormodel.summary(model))
    print(f"model: {out}\nplots: {png}")
    return 0


def _cmd_solve(args) -> int:
    from solver.measurements import load_measurements
    from solver.sltr import solve_measurements

    m = load_measurements(args.measurements)
    sigma = m.sigma
    if sigma is None and args.error_model:
        from mirrorsim.errormodel import load_sigma

        sigma = load_sigma(args.error_model)
    sol = solve_measurements(m.observer, m.beacons, m.targets, sigma)
    print(f"{args.measurements}: {sol.method}")
    print(f"  mirror  yaw {sol.mirror.yaw_deg:.4f}°  through ({sol.mirror.point[0]:.3f}, "
          f"{sol.mirror.point[1]:.3f})")
    print(f"  target  ({sol.target[0]:.4f}, {sol.target[1]:.4f})  reflection point "
          f"({sol.target_reflection_point[0]:.3f}, {sol.target_reflection_point[1]:.3f})")
    if sol.covariance is not None:
        major, minor, angle = sol.ellipse95()
        print(f"  95 % ellipse of the target: {major:.3f} × {minor:.3f} cm, major axis at "
              f"{angle:.1f}°")
    _write_json(args.json, sol.to_json())
    return 0


def _cmd_montecarlo(args) -> int:
    from solver.montecarlo import PAPER_TABLE1, Table1Geometry, table1

    if args.iterations < 2:
        raise BadArgument(f"--iterations: {args.iterations} must be ≥ 2")
    try:
        geometry = Table1Geometry(args.alpha, args.d_total, args.d1, args.incidence,
                                  args.beacon_depth, args.beacon_along)
        geometry.layout()
    except (ValueError, SolverError) as exc:
        raise BadArgument(f"geometry: {exc}") from None
    rows = PAPER_TABLE1 if not args.sigma else tuple(
        (a, d, float("nan"), float("nan")) for a, d in args.sigma)
    if args.error_model:
        from mirrorsim.errormodel import load_sigma

        em = load_sigma(args.error_model)
        rows = (*rows, (em.alpha_deg, em.d_total_rel * args.d_total, float("nan"), float("nan")))
    res = table1(args.iterations, geometry, args.seed, rows)
    g = res["geometry"]
    print(f"Table 1 protocol: {args.iterations} draws per row; target at alpha {g['alpha_deg']:g}°,"
          f" d_total {g['d_total']:g}; mirror through ({g['mirror_point'][0]:.3f}, "
          f"{g['mirror_point'][1]:.3f}) at yaw {g['mirror_yaw_deg']:.1f}°; beacon at "
          f"({g['beacon'][0]:.3f}, {g['beacon'][1]:.3f})")
    print(f"{'v(alpha)':>9} {'v(d)':>6} | {'paper ref':>9} {'paper tar':>9} | "
          f"{'ours ref':>9} {'ours tar':>9} {'yaw (deg)':>9}")
    for r in res["rows"]:
        print(f"{r['sigma_alpha_deg']:9.2f} {r['sigma_d']:6.2f} | {r['paper_rmse_ref']:9.3f} "
              f"{r['paper_rmse_tar']:9.3f} | {r['rmse_ref']:9.3f} {r['rmse_tar']:9.3f} "
              f"{r['rmse_yaw_deg']:9.2f}")
    _write_json(args.json, res)
    return 0


def _cmd_plan(args) -> int:
    from mirrorsim.planning import plan_scene, plan_summary
    from mirrorsim.plot import plot_plan
    from solver.sltr import Sigma

    scene = _load(args.scene)
    for flag, v in (("--sigma-alpha", args.sigma_alpha), ("--sigma-d", args.sigma_d),
                    ("--eps", args.eps), ("--step", args.step)):
        if not v > 0:
            raise BadArgument(f"{flag}: {v} must be > 0")
    if args.eps >= 45:
        raise BadArgument(f"--eps: {args.eps} must be < 45")
    sigma = Sigma(args.sigma_alpha, args.sigma_d)
    if args.error_model:
        from mirrorsim.errormodel import load_sigma

        sigma = load_sigma(args.error_model)
        args.sigma_alpha, args.sigma_d = sigma.alpha_deg, sigma.d_total_rel
    plan = plan_scene(scene, sigma, args.eps,
                      args.yaw_spread, args.d1_spread, args.step)
    summ = plan_summary(plan)
    p = summ["paper"]
    print(f"{scene.name}: target alpha {summ['target']['alpha_deg']:.3f}°, d_total "
          f"{summ['target']['d_total']:.2f} cm, mirror {scene.mirror.size[0]:g} cm wide, "
          f"eps ±{args.eps:g}°")
    print(f"  paper (eqs 9-18): step b = {p['b']:.3f} cm, a/2 = {p['half_a']:.3f} cm, "
          f"triangle {p['area']:.2f} cm², N_bea = 2·d_total/b = {p['n_beacons']:.1f}")
    q = summ["paper_eq15_perpendicular"]
    print(f"  eq 15 with the line perpendicular to the observation line (as its text says): "
          f"a/2 = {q['half_a']:.3f} cm")
    print(f"  exact region seen for every orientation: {summ['exact_region_area']:.0f} cm²; "
          "area vs d_total (paper / exact): " + ", ".join(
              f"{a['d_total']:g}: {a['paper']:.2f}/{a['exact']:.0f}"
              for a in summ["area_vs_d_total"]))
    L = summ["path_lengths"]
    print(f"  paths over {summ['n_steps']} steps: linear {L['linear']:.1f}, rectangular "
          f"{L['rectangular']:.1f}, saw-tooth {L['sawtooth']:.1f} cm")
    sb, bb = summ["scene_beacon"], summ["best_beacon"]
    print(f"  expected target RMSE at sigma ({args.sigma_alpha:g}°, {100 * args.sigma_d:g} %) "
          f"over {summ['mirror_poses']} mirror poses:")
    print(f"    scene's beacon {list(scene.beacons[0].position)}: {sb['rmse']:.3f} cm "
          f"(seen under {100 * sb['seen_fraction']:.0f}% of poses)")
    print(f"    best position ({bb['position'][0]:.1f}, {bb['position'][1]:.1f}): "
          f"{bb['rmse']:.3f} cm")
    out = args.out or Path("renders") / scene.name / f"{scene.name}.plan.png"
    print(f"  figure: {plot_plan(scene, plan, out)}")
    _write_json(args.json, summ)
    return 0


_COMMANDS = {"render": _cmd_render, "check": _cmd_check, "plot": _cmd_plot,
             "evaluate": _cmd_evaluate, "detect": _cmd_detect, "calibrate": _cmd_calibrate,
             "solve": _cmd_solve, "montecarlo": _cmd_montecarlo, "plan": _cmd_plan,
             "dataset": _cmd_dataset, "errormodel": _cmd_errormodel}


if __name__ == "__main__":
    sys.exit(main())
