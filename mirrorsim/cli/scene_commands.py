"""The commands that render a scene: render, detect, calibrate, evaluate, budget, track."""

from __future__ import annotations

import sys
from pathlib import Path

from mirrorsim.cli.outputs import out_folder
from mirrorsim.cli.registry import (
    beacon_sigma_of,
    beacon_sigma_option,
    calibrate_option,
    calibration_of,
    command,
    common,
    emit,
    error_model_of,
    inputs,
    load,
    output,
    preload,
    render_options,
    spp_option,
)
from mirrorsim.errors import BadArgument
from mirrorsim.formats.files import write_png


def _render_options(p):
    common(p, out="output folder (default renders/<name>/)", json="the ground truth",
            spp=True, variant=True, quiet=True)


@command("render", "render the frame and write its ground truth",
         "Render SCENE with Mitsuba 3 and write DIR/<name>.png (sRGB, 8-bit), DIR/<name>.json "
         "(exact ground truth, with each object's bbox_px and visible_px in the mirror from an "
         "object-id pass) and DIR/<name>.ids.png (the id labels).",
         options=_render_options)
def _render(args) -> int:
    from mirrorsim.cli.tables import render_summary
    from mirrorsim.pipelines.frame import render_to_files

    scene = render_options(args, load(args.scene))
    files = render_to_files(scene, out_folder(args, scene), variant=args.variant,
                            progress=not args.quiet)
    print(render_summary(scene, files))
    emit(args, files.truth.to_json())
    return 0


def _detect_options(p):
    p.add_argument("frame", type=Path, help="the frame (PNG, or JPEG)")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--capture", type=Path, metavar="FILE.capture.json",
                        help="the frame's capture record (`render` writes it beside the frame)")
    source.add_argument("--scene", type=Path,
                        help="a scene file: its capture record is made from it")
    inputs(p, ("frame", "FRAME", "file"), ("capture", "--capture", "file"),
           ("scene", "--scene", "file"))
    common(p, scene=False, json="the measurements", variant=True)
    output(p, "--annotate", "file", type=Path, metavar="OUT.png",
           help="draw the detections on the frame")


@command("detect", "measure alpha and d_total from a rendered frame",
         "Find the target's and the beacons' images in FRAME and measure each one's angle of "
         "arrival and, by size constancy, its d_total.  Uses only the image and its capture "
         "record (the camera as its mount reports it, the beacons' believed positions and "
         "heights, the target's size: never the mirror or where the target stands) and the "
         "calibration (`mirrorsim calibrate`, made and cached on first use).",
         options=_detect_options)
def _detect(args) -> int:
    from mirrorsim.cli.tables import detect_summary
    from mirrorsim.detection.detector import annotate
    from mirrorsim.formats.capture import CaptureRecord, load_capture
    from mirrorsim.pipelines.frame import measure_frame

    reference_error = 0.0  # a capture record cannot know its bench's calibration error
    if args.capture:
        # the path: measure_frame reads it and names it if it is another frame's record
        view, source = args.capture, f"capture {args.capture}"
    else:
        scene = load(args.scene)
        view, source = CaptureRecord.from_scene(scene), f"scene {args.scene}"
        reference_error = scene.bench.calibration_distance_error  # the bench's calibration
        _warn_if_another_camera(args.frame, view)
    m = measure_frame(args.frame, view, variant=args.variant, distance_error=reference_error,
                      source=source)
    print(detect_summary(str(args.frame), m.detection))
    if args.annotate:
        write_png(args.annotate, annotate(m.image, m.detection))
        print(f"  annotated: {args.annotate}")
    record = load_capture(view) if isinstance(view, Path | str) else view
    if record.geometry == "3d":  # the 3-D measurements (solve reads them), and the pixels
        from mirrorsim.pipelines.evaluate3d import frame_measurements3

        emit(args, {**frame_measurements3(m.detection, record).to_json(),
                    "detector": m.detection.to_json()["detector"]})
        return 0
    emit(args, m.detection.to_json())
    return 0


def _warn_if_another_camera(frame: Path, view) -> None:
    """A frame measured with a scene's camera while the capture record written beside it
    (by render) describes another (a frame of exp1 measured with the default scene's
    pan gave α 2.5° off, without a word): say so, and measure as asked."""
    from mirrorsim.errors import InputError
    from mirrorsim.formats.capture import load_capture

    beside = frame.with_name(f"{frame.stem}.capture.json")
    if not beside.is_file():
        return
    try:
        cam = load_capture(beside).camera
    except InputError:  # a damaged record is not this check's to report
        return
    mine = view.camera
    differs = [f"{what} {a} (scene) vs {b} (record)" for what, a, b in (
        ("position", tuple(mine.position), tuple(cam.position)),
        ("resolution", tuple(mine.resolution), tuple(cam.resolution)),
        ("hfov", round(mine.hfov, 6), round(cam.hfov, 6)),
        ("pan", round(mine.pan_deg, 6), round(cam.pan_deg, 6))) if a != b]
    if differs:
        print(f"warning: {beside} beside the frame records another camera "
              f"({'; '.join(differs)}): measuring with --scene's; give --capture {beside} "
              "to measure with the frame's own", file=sys.stderr)


def _calibrate_options(p):
    common(p, json="the constants", variant=True)
    p.add_argument("--refresh", action="store_true", help="re-render even if cached")


@command("calibrate", "size-constancy constants for a scene's camera",
         "Render the target and the pencil in direct view at 100 cm, facing SCENE's camera on "
         "its optical axis, measure them as the detector does and cache K = s_px * d per "
         "camera and object.  A scene's calibration.distance_error stands them that much "
         "farther while 100 cm is assumed, as its bench did.",
         options=_calibrate_options)
def _calibrate(args) -> int:
    from mirrorsim.pipelines.calibrate import D_REF, calibrate

    scene = load(args.scene)
    cam = scene.camera
    cal = calibrate(cam, scene.target.size, scene.beacons[0].height, variant=args.variant,
                    refresh=args.refresh,
                    distance_error=scene.bench.calibration_distance_error,
                    subsampled=scene.bench.jpeg_quality is not None)  # for its JPEG frames
    print(f"camera {cam.width}×{cam.height_px}, hfov {cam.hfov:g}°, height {cam.height:g} cm "
          f"(fx {cam.fx:.2f} px)")
    print(f"  target {scene.target.size[1]:g} cm high: K = {cal.target_k:.1f} px·cm "
          f"({cal.height_px('target', D_REF):.2f} px at 1 m; the paper's camera: 229 px)")
    print(f"  pencil's painted band: K = {cal.pencil_k:.1f} px·cm "
          f"({cal.height_px('beacon', D_REF):.2f} px at 1 m)")
    others = sorted({b.height for b in scene.beacons} - {scene.beacons[0].height})
    if others:  # it said nothing of them
        print(f"note: this K is the {scene.beacons[0].height:g} cm pencil's (beacon 0); the "
              f"{', '.join(f'{h:g}' for h in others)} cm pencils get theirs when each is "
              "measured in a frame of its own (evaluate)", file=sys.stderr)
    emit(args, {"key": cal.key, **cal.constants()})
    return 0


def _evaluate_options(p):
    common(p, out="output folder (default renders/<name>/)", json="the report", spp=True,
            variant=True, quiet=True, error_model="each measurement's σ's, which weight the "
            "solver and make the 95 %% ellipse")
    from mirrorsim.pipelines.score import EXTRA_FILES

    calibrate_option(p)
    p.add_argument("--keep", nargs="*", action="extend", default=[], choices=(*EXTRA_FILES, "plot"),
                   help="write also: ids, each frame's object-id labels (<name>.ids.png); "
                        "annotated, each frame with its detections drawn "
                        "(<name>.annotated.png); depth and normals, each frame's from "
                        "Mitsuba's aov integrator (<name>.depth.npy, <name>.normals.npy); "
                        "plot, the top view of truth and estimate with the 95 %% error "
                        "ellipse (<name>.eval.png).  Each costs 0.1-2 s, so none by default")
    p.add_argument("--board-pose", action="store_true",
                   help="measure the camera's pan, pitch and roll on the pegboard's holes "
                        "seen in each frame and correct every α and d_total (in 3-D each "
                        "elevation too) by them: the bench calibrates its mount (its pan "
                        "then known to ~0.002°; a --prior on pan gives way to it); a mount "
                        "off by up to ±3.2° in pan, pitch and roll.  About 1 s a frame")
    p.add_argument("--geometry", choices=("auto", "3d", "planar"), default="auto",
                   help="3d: measure each image's elevation and solve for the mirror's "
                        "plane (its lean) and the target in 3-D, beside the planar solve "
                        "of the same frames; planar: in the board's plane; auto (default): "
                        "3d for a scene with a raised object (position [x, y, z]) or a "
                        "leaning mirror (mirror.lean), planar otherwise")


@command("evaluate", "render, detect, solve and score against ground truth",
         "The main job: render SCENE (or reuse a render of the same scene, spp and seed), detect "
         "the target and beacons, localize mirror and target, and score everything against the "
         "exact ground truth.  Prints a table; writes the frame, its ground truth and capture "
         "record, DIR/<name>.report.json and, with --keep, the id labels, the annotated "
         "frame(s) and a top view.  A scene with several beacons renders one frame per beacon "
         "and reports the error as beacons are added.  Exit 0 whenever it ran.",
         options=_evaluate_options)
def _evaluate(args) -> int:
    from mirrorsim.cli.tables import report_table
    from mirrorsim.formats.files import write_json
    from mirrorsim.pipelines.evaluate import check_board_pose, check_geometry, evaluate_scene

    scene = render_options(args, load(args.scene))
    three_d = check_geometry(scene, args.geometry) == "3d"  # each image: 3 readings, or 2
    calibration = calibration_of(args, len(scene.beacons), three_d=three_d)  # before rendering
    if "plot" in args.keep:
        preload("mirrorsim.cli.plots")  # matplotlib imports while the frame renders
    model = error_model_of(args)  # read and checked before anything is written
    check_board_pose(scene, args.board_pose, calibration)
    check_geometry(scene, args.geometry, calibration=calibration)
    if three_d and "plot" in args.keep:
        raise BadArgument("--keep", "plot: the top view draws a planar report; give "
                           "--geometry planar for it")
    out = out_folder(args, scene)
    report = evaluate_scene(scene, out, variant=args.variant, progress=not args.quiet,
                            keep=tuple(k for k in args.keep if k != "plot"),
                            error_model=model, calibration=calibration,
                            board_pose=args.board_pose, geometry=args.geometry)
    print(f"{scene.name}: {len(report.frames)} frame(s), {report.render.spp} spp, "
          f"{report.render.variant}{' (reused)' if report.reused else ''}")
    if three_d:
        from mirrorsim.cli.tables3d import report3_table

        print(report3_table(report, scene))
    else:
        print(report_table(report, scene))
    for line in report.model_warnings:
        print(f"warning: error model: {line}", file=sys.stderr)
    print(f"report: {write_json(out / f'{scene.name}.report.json', report.to_json())}")
    if "plot" in args.keep:
        from mirrorsim.cli.plots import plot_evaluation

        print(f"top view: {plot_evaluation(scene, report, out / f'{scene.name}.eval.png')}")
    if "annotated" in args.keep:
        print("annotated: " + ", ".join(f.annotated for f in report.frames))
    emit(args, report.to_json())
    return 0


def _budget_options(p):
    common(p, out="output folder (default renders/<name>/budget/)", json="the budget", spp=True,
           variant=True, quiet=True, error_model="each measurement's σ's (the solver's "
           "weights)")
    calibrate_option(p, beacon_sigma_alone=False)
    from mirrorsim.pipelines.score import EXTRA_FILES

    p.add_argument("--keep", nargs="*", action="extend", default=[], choices=EXTRA_FILES,
                   help="files to write beside each run's frame besides its image, capture "
                   "record and truth: ids (the id labels), annotated (the detections drawn), "
                   "depth and normals (Mitsuba's aov integrator); default none")


@command("budget", "error budget of a bench: each imperfection alone, then all",
         "Render, detect, solve and score SCENE on an ideal bench, with each of its bench "
         "imperfections alone (camera.pan_error, camera.pitch, mirror.curvature_radius, "
         "calibration.distance_error, beacons[i].known_position... see docs/scenes.md) and with "
         "all of them (a scene with a raised object or a leaning mirror: solved in 3-D, each "
         "image's elevation measured too).  Prints each source's measurement deltas and "
         "target error beside the "
         "first-order prediction (the solver's Jacobian times the measured deltas); writes "
         "DIR/budget.json and a tornado chart DIR/budget.png; each run's frames in its own "
         "sub-folder.",
         options=_budget_options)
def _budget(args) -> int:
    from mirrorsim.cli.analysis_tables import budget_table
    from mirrorsim.cli.plots import plot_budget
    from mirrorsim.formats.files import write_json
    from mirrorsim.pipelines.budget import budget_runs, check_budget_calibration, run_budget
    from mirrorsim.scene.imperfections import sources

    scene = render_options(args, load(args.scene))
    # before anything renders or is written
    calibration = check_budget_calibration(
        scene, calibration_of(args, len(scene.beacons), three_d=scene.is_3d))
    model = error_model_of(args)  # read and checked before anything is written
    found = sources(scene)
    if not found:
        print(f"warning: {scene.name}: no bench imperfections in {args.scene}: only the "
              "ideal bench is evaluated (see docs/scenes.md, Bench imperfections)",
              file=sys.stderr)
    out = out_folder(args, scene, "budget")
    from mirrorsim.progress import progress_bar

    # one bar over the budget's runs (each a render, a detection and a solve), its rate
    # and ETA; the runs' own render bars would flash beneath it, so they are not shown
    runs = budget_runs(scene)
    with progress_bar(runs, unit="run", desc="budget", enabled=not args.quiet) as bar:
        def step(label: str, k: int, _runs: int) -> None:
            bar.update(k - 1 - bar.n)  # run k begins: k − 1 are done
            if hasattr(bar, "set_postfix_str"):
                bar.set_postfix_str(label)
        budget = run_budget(scene, out, variant=args.variant, progress=False,
                            on_step=step, error_model=model,
                            calibration=calibration, keep=tuple(args.keep))
        bar.update(runs - bar.n)
    print(budget_table(budget))
    path = write_json(out / "budget.json", budget.to_json())
    fig = plot_budget(budget, out / "budget.png")
    print(f"budget: {path}\ntornado chart: {fig}")
    emit(args, budget.to_json())
    return 0


def _track_options(p):
    from mirrorsim.pipelines.track import MAX_ODOMETRY_SIGMA, MAX_STEPS, MAX_TRACK_SEED
    from mirrorsim.pipelines.track_paths import HEADINGS, PATHS

    common(p, out="output folder (default renders/<name>/track/)", json="the track report",
           variant=True, quiet=True, error_model="the filter's measurement σ's (the beacon's "
           "typical ones)")
    p.add_argument("--path", default="rectangular", metavar="|".join(PATHS),
                   help="the beacon's path (paper eqs 19-21; default rectangular)")
    p.add_argument("--heading", default="view", metavar="|".join(HEADINGS),
                   help="where the steps of b run: view (default), along the beacon's "
                        "reflected line of sight away from the glass, as the start pose's "
                        "measurement shows it; camera, along the camera's line to the "
                        "beacon, towards the camera.  Of the ways to walk it (b forwards or "
                        "back, side a left or right), the first kept stays on the board, "
                        "clear of the mirror, the target and walls as the start pose shows "
                        "them and of fixed beacons; then the one with the most poses "
                        "predicted seen in the glass, then forwards, then with images "
                        "nearest the target's in α")
    p.add_argument("--steps", type=int, default=20,
                   help=f"moves after the start, 1..{MAX_STEPS} (default 20)")
    p.add_argument("--odometry-sigma", type=float, default=0.1, metavar="CM",
                   help="the beacon's motion error per move and axis, cm, 0.."
                        f"{MAX_ODOMETRY_SIGMA:g} (default 0.1)")
    beacon_sigma_option(p, "the fixed beacons (the scene's beacons after the first, "
                        "which stand still) weigh the filter's mirror with that σ")
    p.add_argument("--seed", type=int, default=0,
                   help=f"seeds the odometry noise, the filter and the renders, "
                        f"0..{MAX_TRACK_SEED} (default 0)")
    p.add_argument("--side", type=float, default=4.0, metavar="CM",
                   help="a: the path's width across its heading, at most the board's "
                        "size; a path that leaves the board is refused (default 4)")
    p.add_argument("--step", type=float, default=1.0, metavar="CM",
                   help="b: the path's step along its heading, at most the board's size "
                        "(default 1)")
    spp_option(p, "the scene's")


@command("track", "the moving beacon of the paper's Section 4 on rendered frames",
         "The scene's first beacon follows the path from its start; every pose is rendered "
         "and detected from its capture record (the believed position: start plus the "
         "commanded moves; the true one also carries --odometry-sigma of noise per move), "
         "and a particle filter estimates the mirror, then the target, step by step.  Poses "
         "where the beacon's mirror image is not found are recorded as unseen and skipped.  "
         "The scene's other beacons stand still beside it: each is rendered alone and "
         "measured once, and weighs the filter's mirror from the start.  "
         "Prints a table per step; writes DIR/track.json, DIR/track.png (errors against the "
         "step) and DIR/track.gif (the top view with the filter's mirror lines), the frames "
         "in DIR/poses/.", options=_track_options)
def _track(args) -> int:
    from mirrorsim.cli.analysis_tables import track_table
    from mirrorsim.cli.plots import animate_track, plot_track
    from mirrorsim.cli.registry import at_least
    from mirrorsim.formats.files import write_json
    from mirrorsim.pipelines.scenes import refuse_3d
    from mirrorsim.pipelines.track import (
        MAX_TRACK_SEED,
        check_fixed_beacons,
        check_options,
        run_track,
    )

    # before the scene is read (run_track checks again, for callers other than the CLI)
    check_options(args.path, args.steps, args.odometry_sigma, side=args.side, step=args.step,
                  heading=args.heading)
    at_least(("--seed", args.seed, 0, MAX_TRACK_SEED))
    position_sigma = beacon_sigma_of(args)
    scene = load(args.scene)
    refuse_3d(scene, "track")
    if args.spp is not None:  # --seed is the run's (each pose's render seed follows it)
        scene = scene.with_render(spp=args.spp)
    check_options(args.path, args.steps, args.odometry_sigma, side=args.side, step=args.step,
                  heading=args.heading, board=scene.board.size)  # side and step within the board
    check_fixed_beacons(scene, position_sigma)  # before the folder is made
    model = error_model_of(args)  # read and checked before anything is written
    out = out_folder(args, scene, "track")
    from mirrorsim.progress import progress_bar

    # each pose is a render and a detection (seconds): a bar with its rate and ETA
    with progress_bar(args.steps + 1, unit="pose", desc="track", enabled=not args.quiet
                      ) as bar:
        report = run_track(scene, out, kind=args.path, steps=args.steps,
                           odometry_sigma=args.odometry_sigma, seed=args.seed, side=args.side,
                           step=args.step, heading=args.heading, variant=args.variant,
                           on_pose=lambda k, _n: bar.update(k - bar.n),  # pose k begins
                           error_model=model, position_sigma=position_sigma)
        bar.update(bar.total - bar.n)
    print(track_table(report))
    path = write_json(out / "track.json", report.to_json())
    png = plot_track(report, out / "track.png")
    gif = animate_track(scene, report, out / "track.gif")
    print(f"report: {path}\nplot: {png}\nanimation: {gif}")
    emit(args, report.to_json())
    return 0
