"""The commands on many scenes: dataset (make one), errormodel (fit the detector's
error model to one, and test it on another)."""

from __future__ import annotations

import sys
from pathlib import Path

from mirrorsim.cli.registry import (
    at_least,
    calibrate_option,
    calibration_of,
    command,
    common,
    default_workers,
    emit,
    error_model_of,
    inputs,
    output,
    sampler_option,
    spp_option,
)
from mirrorsim.errors import BadArgument, BadParameter, RunFailed


def _dataset_options(p):
    from mirrorsim.pipelines.dataset import EXECUTORS, MAX_SCENES, MAX_WORKERS

    p.add_argument("--n", type=int, required=True, help=f"number of scenes, 1..{MAX_SCENES}")
    from mirrorsim.scene.render_settings import MAX_SEED

    p.add_argument("--seed", type=int, required=True,
                   help=f"the dataset's seed, 0..{MAX_SEED} (scene i is drawn from (seed, i))")
    output(p, "--out", "dataset", type=Path, required=True,
           help="a new or empty folder, or (with --resume) one of its datasets")
    p.add_argument("--workers", type=int, default=default_workers(),
                   help=f"worker processes, 1..{MAX_WORKERS} (default: half the cores; more "
                        "than the cores, or than the available memory holds at 1 GiB each, "
                        "is capped)")
    p.add_argument("--spec", type=Path, help="ranges of the random scenes (YAML)")
    inputs(p, ("spec", "--spec", "file"))
    spp_option(p, "the spec's")
    sampler_option(p)
    from mirrorsim.pipelines.score import KEPT_BY_DEFAULT

    p.add_argument("--keep", nargs="*", action="extend", default=[],
                   choices=KEPT_BY_DEFAULT,
                   help="files to write beside each frame besides its PNG, capture record "
                   "and truth: ids (the id labels), annotated (the detections drawn); "
                   "default none")
    from mirrorsim.scene.render_settings import AOVS

    p.add_argument("--aov", type=lambda v: tuple(v.split(",")), default=(), metavar="NAMES",
                   help="besides each frame, from Mitsuba's aov integrator: "
                   f"{','.join(AOVS)} (<frame>.depth.npy: cm along each ray to the first "
                   "surface; <frame>.normals.npy: its unit normal; float32)")
    p.add_argument("--beacons", type=int, metavar="N",
                   help="beacons a scene, each drawn from the spec's beacon ranges and "
                   "rendered in a frame of its own (default: the spec's beacon.count, 1)")
    calibrate_option(p)  # needs --beacons (or a spec's beacon.count) that carries them
    common(p, scene=False, variant=True, quiet=True,
           error_model="each row's measurement σ's, which weight its solve and make its "
                       "ellipse")
    p.add_argument("--resume", action="store_true",
                   help="finish an interrupted run, or extend one to a larger --n (the same "
                   "seed and settings: the added scenes are those a run of that --n makes)")
    p.add_argument("--executor", default="local", choices=EXECUTORS)
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler (tcp://host:8786); default: a local cluster")


def _dataset_calibration(args):
    """--calibrate, --prior and --beacon-sigma checked as the spec's scenes are solved: a
    3-D spec's in 3-D, the others in the plane (which refuses the pitch)."""
    from mirrorsim.pipelines.random_scenes import load_spec

    return calibration_of(args, three_d=load_spec(args.spec).is_3d)


@command("dataset", "many random scenes, rendered, detected and scored",
         "Draw N random valid scenes from a spec (default scenes/dataset_spec.yaml), render, "
         "detect, solve and score each, in parallel worker processes (or on a Dask cluster), "
         "and write DIR/dataset.parquet (a row per scene), DIR/scenes/*.yaml, DIR/frames/ and a "
         "dataset card DIR/README.md.  Interrupted runs resume with --resume; the same seed "
         "gives the same rows whatever the number of workers.", options=_dataset_options)
def _dataset(args) -> int:
    from mirrorsim.formats.dataset_folder import DatasetError
    from mirrorsim.pipelines.dataset import MAX_SCENES, MAX_WORKERS, run_dataset
    from mirrorsim.pipelines.workers import max_workers
    from mirrorsim.scene.render_settings import MAX_SEED

    at_least(("--n", args.n, 1, MAX_SCENES), ("--seed", args.seed, 0, MAX_SEED),
             ("--workers", args.workers, 1, MAX_WORKERS))
    calibration = _dataset_calibration(args)
    from mirrorsim.scene.render_settings import AOVS

    bad = [a for a in args.aov if a not in AOVS]
    if bad:
        raise BadArgument("--aov", f"{bad[0]!r}: choose from {','.join(AOVS)}")
    if args.spp is not None:  # checked as every scene's render settings are
        from mirrorsim.scene.render_settings import RenderSettings

        RenderSettings(spp=args.spp)
    workers = args.workers
    if args.executor == "local":
        most, why = max_workers()
        if workers > most:
            print(f"warning: --workers {workers} capped to {most} ({why})", file=sys.stderr)
            workers = most
    try:
        res = run_dataset(args.n, args.seed, args.out, workers=workers,
                          spec_path=args.spec, spp=args.spp, sampler=args.sampler,
                          variant=args.variant, keep=(*args.keep, *args.aov), resume=args.resume,
                          executor=args.executor, scheduler=args.scheduler,
                          progress=not args.quiet, calibration=calibration,
                          beacons=args.beacons,
                          error_model=error_model_of(args))
    except BadParameter as exc:
        if exc.parameter != "nuisances":
            raise
        raise BadArgument("--calibrate", f"{exc.message}: draw more with --beacons or the "
                          "spec's beacon.count") from None
    except DatasetError as exc:
        if not exc.resumable:
            raise
        raise DatasetError(args.out, "already holds a dataset: pass --resume to finish it, "
                           "or choose another --out") from None
    except RunFailed as exc:  # the rows done so far are kept: say how to finish
        raise RunFailed(f"{exc}; rerun with --resume") from None
    print(f"{args.out}: {res.rows} rows ({res.computed} computed now in "
          f"{res.seconds:.0f} s, {res.per_minute:.1f} scenes/min; "
          f"{res.already_done} already done; {res.failed} failed) → {res.parquet}")
    if res.retry:
        i, why = next(iter(res.retry.items()))
        print(f"error: {len(res.retry)} scene(s) failed for a reason outside the scene "
              f"(scene {i}: {why}); they have no row: rerun with --resume", file=sys.stderr)
        return 1
    return 0


def _export_options(p):
    from mirrorsim.pipelines.dataset_exports import EXPORTS

    p.add_argument("dataset", type=Path, help="a dataset folder (`mirrorsim dataset --out`)")
    p.add_argument("--to", nargs="+", choices=EXPORTS, default=list(EXPORTS),
                   help="what to write into it (default all): coco (DIR/coco.json), hf "
                   "(DIR/metadata.jsonl and the card's Hugging Face front matter), croissant "
                   "(DIR/croissant.json, with DIR/metadata.jsonl)")


@command("export", "a dataset's frames for learning pipelines: COCO, Hugging Face, Croissant",
         "Verify a dataset's table, rows and files, then write its frames' annotations "
         "(masks, boxes, keypoints, the mirror's virtual camera) as COCO's instances and "
         "keypoints (DIR/coco.json), as a Hugging Face dataset (DIR/metadata.jsonl and the "
         "card's front matter: datasets.load_dataset(DIR, split='train')) and as Croissant "
         "(DIR/croissant.json).  `mirrorsim dataset` writes all three itself; this is for a "
         "folder made earlier (a frame made before annotations gets them from its scene "
         "file and its id pass, rendered again) or changed since.", options=_export_options)
def _export(args) -> int:
    from mirrorsim.pipelines.dataset_exports import write_exports

    for kind, path in write_exports(args.dataset, tuple(args.to)).items():
        print(f"{kind}: {path}")
    return 0


def _errormodel_options(p):
    p.add_argument("dataset", type=Path, nargs="?",
                   help="the dataset to fit (omit it to only --test a model)")
    inputs(p, ("dataset", "the dataset DIR", "dataset"), ("test", "--test", "dataset"))
    output(p, "--out", "file", type=Path,
           help="model file, *.json (default DIR/error_model.json; its plots go beside it, "
           "*.png, and with --test *.reliability.png)")
    p.add_argument("--test", type=Path, metavar="HELDOUT",
                   help="a dataset the model was not fitted on: print the coverage of the "
                   "target's 50/90/95 %% ellipses, the median Mahalanobis distance and each "
                   "measurement's errors within 1σ/2σ (beside what its law's Student-t puts there)")
    common(p, scene=False, json="the validation (with --test)",
           error_model="the model to --test, when no DATASET is fitted",
           error_model_default="the shipped model the held-out spec's benches call for")
    output(p, "--plot", "file", type=Path, metavar="PNG", suffixes=(".png",),
           help="the reliability diagram (with --test; default: beside a model fitted "
           "here, none for a model given with --error-model, whose folder is yours)")


@command("errormodel", "fit the detector's error model to a dataset, and test it on another",
         "Fit each measurement's σ (target and beacon, alpha and d_total) as a function of what "
         "its frame shows (the image's height in pixels, its angle off the optical axis, its "
         "edges' contrast, the frame's noise and JPEG quality): the scale of a Student-t, "
         "its degrees of freedom fitted with it (the detector's errors are heavier-tailed "
         "than a Gaussian's), and the target's tail that says where the solve's ellipses "
         "are drawn; the domain it was fitted on (a scene "
         "outside it gets a warning) and, for a spec with a bench block, the benches' shared "
         "errors as tolerances the solver estimates with priors; and the errors' bias against "
         "geometry and bench (to explain them).  Needs at least "
         "30 usable rows of each kind (five per coefficient of a σ law); a law whose σ's "
         "over its own rows span more than a factor 10000, or move by more than a factor 30 "
         "when it is refitted on 20 resamples of its rows, is refused as unstable, and one "
         "that moves beyond 4 is kept with a warning.  "
         "Writes DIR/error_model.json (give it to evaluate, dataset, budget, track, solve, "
         "montecarlo or plan with --error-model) and DIR/error_model.png.  With --test "
         "HELDOUT: solve each held-out row again with the model's σ's (and its bench's "
         "priors) and say whether its ellipses hold; without DATASET or --error-model, the "
         "shipped model the held-out spec's benches call for.",
         options=_errormodel_options)
def _errormodel(args) -> int:
    from mirrorsim.cli.analysis_tables import error_model_summary
    from mirrorsim.cli.plots import plot_error_model
    from mirrorsim.formats import dataset_table as table
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines import errormodel

    if args.dataset is None and args.test is None:
        raise BadArgument("DATASET", "give a dataset to fit, or --test HELDOUT to test a model")
    if args.dataset is not None and args.error_model:
        raise BadArgument("--error-model", "it names a model to --test; give it or a DATASET "
                          "to fit, not both")
    for flag, value in (("--json", args.json), ("--plot", args.plot)):
        if value is not None and args.test is None:
            raise BadArgument(flag, "it writes the validation: give --test HELDOUT too")
    if args.out is not None and args.out.suffix != ".json":
        raise BadArgument("--out", f"{args.out}: the model is JSON: give a *.json path (its "
                          "plots go beside it as *.png)")
    if args.test is not None:  # a held-out set the validation cannot take: before a fit
        try:
            table.require_planar(errormodel.read_columns(args.test))
        except ValueError as exc:
            raise BadArgument(str(args.test), str(exc)) from None
    out = None
    if args.dataset is not None:
        out = args.out or args.dataset / "error_model.json"
        plots = out.with_suffix(".png")
        if args.out is not None and plots.exists() and not args.out.exists():
            # the plots' file, named by us, is someone else's unless it came with the model
            raise BadArgument("--out", f"{args.out}: its plots would go over {str(plots)!r}, "
                              "which is not a model's: choose another name")
        cols = errormodel.read_columns(args.dataset)
        try:
            model = errormodel.with_its_ellipsoid(
                errormodel.fit(cols, errormodel.provenance_of(args.dataset, cols),
                               errormodel.spec_of(args.dataset).get("bench")),
                args.dataset, cols)
        except ValueError as exc:
            raise BadArgument(str(args.dataset), str(exc)) from None
        errormodel.write_model(model, out)
        png = plot_error_model(cols, model, plots)
        print(error_model_summary(model))
        print(f"model: {out}\nplots: {png}")
    else:  # the shipped model the held-out benches call for, as evaluate chooses it
        model = error_model_of(args) or default_error_model(
            "bench" if errormodel.spec_of(args.test).get("bench") else "ideal")
    if args.test is not None:
        _test_model(args, model, out)
    return 0


def _test_model(args, model, out: Path | None) -> None:
    from mirrorsim.pipelines import errormodel, uncertainty

    try:
        v = uncertainty.validate(model, errormodel.read_columns(args.test))
    except ValueError as exc:
        raise BadArgument(str(args.test), str(exc)) from None
    name = args.error_model or out or model.name()
    print(f"{name} on {args.test}:")
    print("\n".join(uncertainty.report_lines(v)))
    plot = args.plot or (out.with_suffix(".reliability.png") if out is not None else None)
    if plot is not None:
        print(f"reliability diagram: "
              f"{uncertainty.reliability_plot(v, plot, f'{name} on {args.test}')}")
    emit(args, v.to_json())
