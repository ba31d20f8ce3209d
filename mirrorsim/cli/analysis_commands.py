"""The commands on measurements and many scenes: solve, montecarlo, plan, dataset,
errormodel."""

from __future__ import annotations

import sys
from dataclasses import replace
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
    finite,
    inputs,
    load,
    out_file,
    output,
    sampler_option,
    spp_option,
)
from mirrorsim.errors import BadArgument, BadParameter, RunFailed

MAX_ITERATIONS = 1_000_000  # draws per Monte Carlo row: about a second a row at the most


def _solve_options(p):
    p.add_argument("measurements", type=Path,
                   help="a measurements file (detect --json, check --measurements); - reads "
                        "it from standard input")
    inputs(p, ("measurements", "MEASUREMENTS", "file"))
    common(p, scene=False, json="the solution",
           error_model="each measurement's σ's; given, it replaces the file's `sigma`")
    calibrate_option(p)


@command("solve", "localize the mirror and the target from measurements",
         "Read MEASUREMENTS.json (observer, target alpha/d_total, beacons with positions; "
         "optionally `sigma` and `observer_pan_deg`) and estimate the mirror line and the "
         "target by weighted least squares (one beacon: the exact closed form), with the "
         "target's covariance and 95 % error ellipse.  The σ's: --error-model's if given "
         "(it wins over the file's `sigma`, and says so), else the file's `sigma`, else the "
         "shipped error model's.", options=_solve_options)
def _solve(args) -> int:
    from mirrorsim.cli.tables import solution_summary
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.formats.measurements import load_measurements
    from solver.lsq import solve_measurements

    m = load_measurements(args.measurements)
    calibration = calibration_of(args, len(m.beacons), len(m.targets))
    model = error_model_of(args)
    if model is not None and m.sigma is not None:
        print(f"note: --error-model {args.error_model} gives the σ's; the `sigma` of "
              f"{args.measurements} is not used", file=sys.stderr)
    if model is None and m.sigma is not None:
        sigma, source = m.sigma, f"`sigma` of {args.measurements}"
    else:
        # a measurements file holds no pixels: each kind's typical σ (its training rows'
        # RMS), the same for every beacon
        model = model or default_error_model()
        typical = model.typical
        sigma = replace(typical, beacons=typical.beacons * len(m.beacons))
        from mirrorsim.pipelines.evaluate import model_calibration

        calibration = model_calibration(model, calibration)  # a bench model's priors
        source = (f"{model.name()}'s typical σ's (a measurements file holds no image "
                  "features: `evaluate` gives each image its own)")
    sol = solve_measurements(m.observer, m.beacons, m.targets, sigma=sigma, calibration=calibration)
    print(f"σ's from {source}", file=sys.stderr)
    print(solution_summary(str(args.measurements), sol))
    emit(args, sol.to_json())
    return 0


def _montecarlo_options(p):
    from mirrorsim.scene.model import MAX_SEED

    p.add_argument("--iterations", type=int, default=200, help="draws per row (default 200)")
    p.add_argument("--seed", type=int, default=0, help=f"0..{MAX_SEED} (default 0)")
    p.add_argument("--alpha", type=float, default=70.0, help="target's alpha (deg)")
    p.add_argument("--d-total", type=float, default=5.0, help="target's d_total")
    p.add_argument("--d1", type=float, default=3.0, help="observer → mirror along the ray")
    p.add_argument("--incidence", type=float, default=30.0,
                   help="mirror's turn from facing the ray square-on (deg)")
    p.add_argument("--beacon-depth", type=float, default=0.5,
                   help="beacon's distance in front of the mirror")
    p.add_argument("--beacon-along", type=float, default=0.3,
                   help="beacon's offset along the mirror from the reflection point")
    p.add_argument("--sigma", nargs=2, type=float, action="append", metavar=("ALPHA", "DPCT"),
                   help="a row of your own: σ_α in degrees and σ_d in %% of d_total (0.2 = "
                   "0.2 %%; files hold it as a fraction, 0.002); repeatable")
    common(p, scene=False, json="the table", error_model="add a row with its typical σ's "
           "(relative σ_d times --d-total; the target's and the beacon's)")


@command("montecarlo", "the paper's Table 1 protocol",
         "Table 1 of the paper: d_total = 5, alpha = 70 deg, Gaussian noise with the table's "
         "sigmas, ITERATIONS draws per row; RMSE of the reflector (the target's reflection "
         "point) and of the target, next to the paper's.  The paper does not say where the "
         "mirror and beacon stand: the options below set them.", options=_montecarlo_options)
def _montecarlo(args) -> int:
    from mirrorsim.cli.analysis_tables import montecarlo_table
    from mirrorsim.scene.model import MAX_SEED
    from solver.measurements import D_TOTAL_RANGE_CM, SIGMA_ALPHA_MAX_DEG, SIGMA_D_REL_MAX
    from solver.montecarlo import Table1Geometry, table1, table_rows
    from solver.sltr import SolverError

    at_least(("--iterations", args.iterations, 2), ("--seed", args.seed, 0, MAX_SEED))
    if args.iterations > MAX_ITERATIONS:
        raise BadArgument("--iterations", f"{args.iterations} must be ≤ {MAX_ITERATIONS}")
    finite(args, "alpha", "d_total", "d1", "incidence", "beacon_depth", "beacon_along", "sigma")
    # the protocol's lengths are in the table's units; a measured d_total's range bounds
    # them, so that no row turns to inf
    lo, hi = D_TOTAL_RANGE_CM
    for flag, value in (("--d-total", args.d_total), ("--d1", args.d1),
                        ("--beacon-depth", args.beacon_depth),
                        ("--beacon-along", abs(args.beacon_along))):
        if value > hi:
            raise BadArgument(flag, f"{value:g}: must be ≤ {hi:g}")
    for flag, value in (("--alpha", args.alpha), ("--incidence", args.incidence)):
        if abs(value) > 360:  # a bearing of 1e300° has no digits left below the turn
            raise BadArgument(flag, f"{value:g}°: give an angle within ±360°")
    if not lo <= args.d_total:
        raise BadArgument("--d-total", f"{args.d_total:g}: must be ≥ {lo:g}")
    if not 0 < args.d1 < args.d_total:
        raise BadArgument("--d1", f"{args.d1:g}: need 0 < d1 < d_total ({args.d_total:g})")
    for a, d in args.sigma or []:
        if not (0 <= a <= SIGMA_ALPHA_MAX_DEG and 0 <= d <= 100 * SIGMA_D_REL_MAX):
            raise BadArgument("--sigma", f"{a:g} {d:g}: need 0 ≤ σ_α ≤ "
                              f"{SIGMA_ALPHA_MAX_DEG:g}° and 0 ≤ σ_d ≤ "
                              f"{100 * SIGMA_D_REL_MAX:g} (% of d_total)")
    # the command line's σ_d is in %; the solver's a fraction
    args.sigma = [(a, d / 100.0) for a, d in args.sigma or []] or None
    try:
        geometry = Table1Geometry(args.alpha, args.d_total, args.d1, args.incidence,
                                  args.beacon_depth, args.beacon_along)
        geometry.layout()
    except (ValueError, SolverError) as exc:
        raise BadArgument("geometry", str(exc)) from None
    model = error_model_of(args)
    rows = table_rows(args.sigma, None if model is None else model.typical, geometry)
    res = table1(args.iterations, geometry, args.seed, rows=rows)
    print(montecarlo_table(res))
    emit(args, res.to_json())
    return 0


def _plan_options(p):
    common(p, out="PNG (default renders/<name>/<name>.plan.png)", out_kind="file",
           json="the analysis")
    p.add_argument("--sigma-alpha", type=float, help="σ_α, deg, for every measurement "
                   "(with --sigma-d; default: the error model's typical σ's per object)")
    p.add_argument("--sigma-d", type=float, metavar="PCT",
                   help="σ_d in %% of d_total (0.2 = 0.2 %%; files hold it as a fraction, "
                   "0.002)")
    p.add_argument("--eps", type=float, default=5.0,
                   help="orientation range ±eps (deg; 1 ≤ eps < 45, default 5)")
    p.add_argument("--yaw-spread", type=float, default=3.0, help="prior yaw ± (deg)")
    p.add_argument("--d1-spread", type=float, default=2.0, help="prior mirror distance ± (cm)")
    p.add_argument("--step", type=float, default=1.0, help="grid step of the search (cm)")
    p.add_argument("--beacons", type=int, default=1, metavar="N",
                   help="place N beacons, one at a time, each where it lowers the expected "
                   "target error most (with --calibrate's nuisances estimated alongside); "
                   "prints what each buys (default 1)")
    calibrate_option(p)
    common(p, scene=False, error_model="its typical σ's per object (target, beacon)")


@command("plan", "beacon placement analysis and the best beacon position",
         "For SCENE's camera and target measurement: the paper's placement numbers (eqs 7-21: "
         "step b, half-width a/2, N_bea, the three paths), the exact region where a beacon is "
         "seen for every mirror orientation within +-eps, and the beacon position on the board "
         "with the least expected target error over a prior of mirror poses around the scene's "
         "mirror, with a heat map.", options=_plan_options)
def _plan(args) -> int:
    from mirrorsim.cli.analysis_tables import plan_text
    from mirrorsim.cli.plots import plot_plan
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines.planning import plan_scene
    from solver.measurements import SIGMA_D_REL_MAX, SIGMA_D_REL_MIN, ObjectSigmas, Sigma

    finite(args, "sigma_alpha", "sigma_d", "eps", "yaw_spread", "d1_spread", "step")
    if (args.sigma_alpha is None) != (args.sigma_d is None):
        raise BadArgument("--sigma-alpha" if args.sigma_alpha is None else "--sigma-d",
                          "give --sigma-alpha and --sigma-d together")
    if args.sigma_alpha is not None and args.error_model:
        raise BadArgument("--error-model", "give either it or --sigma-alpha/--sigma-d")
    if args.sigma_d is not None and not (100 * SIGMA_D_REL_MIN <= args.sigma_d
                                         <= 100 * SIGMA_D_REL_MAX):
        raise BadArgument("--sigma-d", f"{args.sigma_d:g}: need {100 * SIGMA_D_REL_MIN:g} ≤ "
                          f"σ_d ≤ {100 * SIGMA_D_REL_MAX:g} (% of d_total)")
    scene = load(args.scene)
    sigma = (ObjectSigmas.same(Sigma(args.sigma_alpha, args.sigma_d / 100.0))
             if args.sigma_alpha is not None
             else (error_model_of(args) or default_error_model()).typical)
    plan = plan_scene(scene, sigma, args.eps, yaw_spread_deg=args.yaw_spread,
                      d1_spread=args.d1_spread, step=args.step,
                      n_beacons=args.beacons, calibration=calibration_of(args))
    summ = plan.to_json()
    print(plan_text(scene, plan))
    out = out_file(args, scene, f"{scene.name}.plan.png")
    print(f"  figure: {plot_plan(scene, plan, out)}")
    emit(args, summ)
    return 0


def _dataset_options(p):
    from mirrorsim.pipelines.dataset import EXECUTORS, MAX_SCENES, MAX_WORKERS

    p.add_argument("--n", type=int, required=True, help=f"number of scenes, 1..{MAX_SCENES}")
    from mirrorsim.scene.model import MAX_SEED

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
    from mirrorsim.pipelines.score import EXTRA_FILES

    p.add_argument("--keep", nargs="*", action="extend", default=[], choices=EXTRA_FILES,
                   help="files to write beside each frame besides its PNG, capture record "
                   "and truth: ids (the id labels), annotated (the detections drawn); "
                   "default none")
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
    from mirrorsim.scene.model import MAX_SEED

    at_least(("--n", args.n, 1, MAX_SCENES), ("--seed", args.seed, 0, MAX_SEED),
             ("--workers", args.workers, 1, MAX_WORKERS))
    calibration = calibration_of(args)
    if args.spp is not None:  # checked as every scene's render settings are
        from mirrorsim.scene.model import RenderSettings

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
                          variant=args.variant, keep=tuple(args.keep), resume=args.resume,
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
                   "measurement's errors within 1σ/2σ")
    common(p, scene=False, json="the validation (with --test)",
           error_model="the model to --test, when no DATASET is fitted")
    output(p, "--plot", "file", type=Path, metavar="PNG", suffixes=(".png",),
           help="the reliability diagram (with --test; default: beside a model fitted "
           "here, none for a model given with --error-model, whose folder is yours)")


@command("errormodel", "fit the detector's error model to a dataset, and test it on another",
         "Fit each measurement's σ (target and beacon, alpha and d_total) as a function of what "
         "its frame shows (the image's height in pixels, its angle off the optical axis, its "
         "edges' contrast, the frame's noise and JPEG quality), with a tail factor that "
         "holds 95 %% of the errors within 1.96 σ, the domain it was fitted on (a scene "
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
            model = errormodel.fit(cols, errormodel.provenance_of(args.dataset, cols),
                                   errormodel.spec_of(args.dataset).get("bench"))
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
