"""The commands on measurements: solve, montecarlo, plan (the dataset commands are
:mod:`mirrorsim.cli.dataset_commands`')."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from mirrorsim.cli.outputs import out_file
from mirrorsim.cli.registry import (
    at_least,
    calibrate_option,
    calibration_of,
    command,
    common,
    emit,
    error_model_of,
    finite,
    inputs,
    load,
)
from mirrorsim.errors import BadArgument

MAX_ITERATIONS = 1_000_000  # draws per Monte Carlo row: about a second a row at the most


def _solve_options(p):
    p.add_argument("measurements", type=Path,
                   help="a measurements file (detect --json, check --measurements); - reads "
                        "it from standard input")
    inputs(p, ("measurements", "MEASUREMENTS", "file"))
    common(p, scene=False, json="the solution",
           error_model="each measurement's σ's; given, it replaces the file's `sigma`",
           error_model_default="the file's `sigma`, else the shipped ideal-bench model's "
           "typical σ's")
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
    from solver.lsq3 import Measurements3

    m = load_measurements(args.measurements)
    if isinstance(m, Measurements3):
        return _solve3(args, m)
    calibration = calibration_of(args, len(m.beacons), len(m.targets), three_d=False)
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
        from mirrorsim.pipelines.solving import model_calibration

        calibration = model_calibration(model, calibration)  # a bench model's priors
        source = (f"{model.name()}'s typical σ's (a measurements file holds no image "
                  "features: `evaluate` gives each image its own)")
    sol = solve_measurements(m.observer, m.beacons, m.targets, sigma=sigma, calibration=calibration)
    print(f"σ's from {source}", file=sys.stderr)
    _warn_if_loose(sol.target_covariance, sol.target, m.observer)
    print(solution_summary(str(args.measurements), sol))
    emit(args, sol.to_json())
    return 0


def _solve3(args, m) -> int:
    """``solve`` of 3-D measurements (an observer with a height, each image with an
    elevation): the mirror's plane, its lean and the target in 3-D."""
    from mirrorsim.cli.tables3d import solution3_summary
    from mirrorsim.formats.error_model_file import default_error_model
    from mirrorsim.pipelines.evaluate3d import solved3, with_shared_pan
    from mirrorsim.pipelines.solving import model_calibration
    from solver.selfcal import SelfCalibration

    calibration = calibration_of(args, len(m.beacons), 1, three_d=True)
    model = error_model_of(args)
    source, shared, scale = f"`sigma` of {args.measurements}", 0.0, 1.0
    if model is not None or m.sigma is None:
        model = model or default_error_model()
        t, e = model.typical, model.typical_elevations
        b = t.beacons[0]
        m = replace(m, sigma=((b.alpha_deg, e[1] if e else b.alpha_deg, b.d_total_rel),)
                    * len(m.beacons) + ((t.target.alpha_deg, e[0] if e else t.target.alpha_deg,
                                         t.target.d_total_rel),))
        source = f"{model.name()}'s typical σ's" + (
            "" if e else ", the elevation's taken as the azimuth's (a measurements file "
                         "holds no pixels)")
        # a bench model's shared errors with their priors, as the planar solve takes them;
        # a 3-D model's ellipsoid widened as its training rows call for
        calibration, shared = model_calibration(model, calibration), t.shared_alpha_deg
        scale = model.ellipsoid_scale
    nuisances, priors = with_shared_pan(calibration, shared)
    fit = solved3(m, SelfCalibration(nuisances, calibration.position_sigma, priors), scale)
    print(f"σ's from {source}", file=sys.stderr)
    _warn_if_loose(fit.target_covariance, fit.target, m.observer)
    print(solution3_summary(str(args.measurements), fit))
    emit(args, fit.to_json())
    return 0


def _warn_if_loose(covariance, target, observer) -> None:
    """:func:`~mirrorsim.cli.tables.loose_fit_warning`'s warning, where there is one, on
    stderr as the command's other warnings (not through ``warnings``, which a filter
    would turn into an error or hide, and which says a repeated one once)."""
    from mirrorsim.cli.tables import loose_fit_warning

    said = loose_fit_warning(covariance, target, observer)
    if said is not None:
        print(f"warning: {said}", file=sys.stderr)


def _montecarlo_options(p):
    from mirrorsim.scene.render_settings import MAX_SEED

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
    p.add_argument("--lean", type=float, default=0.0,
                   help="3-D: the mirror's lean (deg, its top away from its face; within "
                   "±10)")
    p.add_argument("--target-z", type=float, default=0.0,
                   help="3-D: the target's base above the board (the table's units)")
    p.add_argument("--beacon-z", type=float, default=0.0,
                   help="3-D: the beacon's base above the board")
    p.add_argument("--camera-height", type=float, default=0.0,
                   help="3-D: the camera above the board (with any of these four "
                   "non-zero, each image is seen at azimuth, elevation and d_total and "
                   "solved in 3-D, beside the planar solve of the same draws)")
    p.add_argument("--sigma-elevation", type=float, default=None, metavar="DEG",
                   help="3-D: the elevation's σ (deg; default each image's σ_α)")
    p.add_argument("--sigma", nargs=2, type=float, action="append", metavar=("ALPHA", "DPCT"),
                   help="a row of your own: σ_α in degrees and σ_d in %% of d_total (0.2 = "
                   "0.2 %%; files hold it as a fraction, 0.002); repeatable")
    common(p, scene=False, json="the table", error_model="add a row with its typical σ's "
           "(relative σ_d times --d-total; the target's and the beacon's)",
           error_model_default="no such row")


@command("montecarlo", "the paper's Table 1 protocol",
         "Table 1 of the paper: d_total = 5, alpha = 70 deg, Gaussian noise with the table's "
         "sigmas, ITERATIONS draws per row; RMSE of the reflector (the target's reflection "
         "point) and of the target, next to the paper's.  The paper does not say where the "
         "mirror and beacon stand: the options below set them.", options=_montecarlo_options)
def _montecarlo(args) -> int:
    from mirrorsim.cli.analysis_tables import montecarlo_table
    from mirrorsim.scene.render_settings import MAX_SEED
    from solver.measurements import D_TOTAL_RANGE_CM, SIGMA_ALPHA_MAX_DEG, SIGMA_D_REL_MAX
    from solver.montecarlo import Table1Geometry, table1, table_rows
    from solver.sltr import SolverError

    at_least(("--iterations", args.iterations, 2), ("--seed", args.seed, 0, MAX_SEED))
    if args.iterations > MAX_ITERATIONS:
        raise BadArgument("--iterations", f"{args.iterations} must be ≤ {MAX_ITERATIONS}")
    finite(args, "alpha", "d_total", "d1", "incidence", "beacon_depth", "beacon_along", "sigma",
           "lean", "target_z", "beacon_z", "camera_height", "sigma_elevation")
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
    rise = _rise(args)
    if not rise.flat:
        return _montecarlo3(args, geometry, rise, None if model is None else model.typical)
    rows = table_rows(args.sigma, None if model is None else model.typical, geometry)
    res = table1(args.iterations, geometry, args.seed, rows=rows)
    print(montecarlo_table(res))
    emit(args, res.to_json())
    return 0


def _rise(args):
    """The 3-D options as a :class:`~solver.montecarlo3.Rise`, each within its bounds."""
    from mirrorsim.scene.model import MAX_LEAN_DEG
    from solver.measurements import D_TOTAL_RANGE_CM, SIGMA_ALPHA_MAX_DEG
    from solver.montecarlo3 import Rise

    if abs(args.lean) > MAX_LEAN_DEG:
        raise BadArgument("--lean", f"{args.lean:g}°: must be within ±{MAX_LEAN_DEG:g}°")
    for flag, value in (("--target-z", args.target_z), ("--beacon-z", args.beacon_z),
                        ("--camera-height", args.camera_height)):
        if not 0.0 <= value <= D_TOTAL_RANGE_CM[1]:
            raise BadArgument(flag, f"{value:g}: must be within 0…{D_TOTAL_RANGE_CM[1]:g}")
    if args.sigma_elevation is not None and not 0 <= args.sigma_elevation <= SIGMA_ALPHA_MAX_DEG:
        raise BadArgument("--sigma-elevation", f"{args.sigma_elevation:g}°: must be within "
                          f"0…{SIGMA_ALPHA_MAX_DEG:g}°")
    return Rise(args.lean, args.target_z, args.beacon_z, args.camera_height)


def _montecarlo3(args, geometry, rise, typical) -> int:
    """The protocol in 3-D (``montecarlo --lean/--target-z/…``)."""
    from mirrorsim.cli.analysis_tables import montecarlo3_table
    from solver.montecarlo import table_rows
    from solver.montecarlo3 import layout3, table3
    from solver.sltr import SolverError

    try:
        lay = layout3(geometry, rise)
    except SolverError as exc:
        raise BadArgument("--lean", f"{rise.lean_deg:g}°: {exc}") from None
    rows = table_rows(args.sigma, typical, geometry,
                      d_totals=(lay.target_seen[2], lay.beacon_seen[2]))
    res = table3(args.iterations, geometry, rise, rows=rows, rng=args.seed,
                 sigma_elevation_deg=args.sigma_elevation)
    print(montecarlo3_table(res))
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
    common(p, scene=False, error_model="its typical σ's per object (target, beacon)",
           error_model_default="the shipped ideal-bench model's, unless --sigma-alpha and "
           "--sigma-d give them")


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
                      n_beacons=args.beacons,
                      calibration=calibration_of(args, three_d=False))
    summ = plan.to_json()
    print(plan_text(scene, plan))
    out = out_file(args, scene, f"{scene.name}.plan.png")
    print(f"  figure: {plot_plan(scene, plan, out)}")
    emit(args, summ)
    return 0
