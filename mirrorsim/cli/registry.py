"""The command registry and the options several commands share (one wording each)."""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mirrorsim.errors import BadArgument

if TYPE_CHECKING:  # the rest is imported where used: `mirrorsim --help` needs none of it
    from mirrorsim.formats.error_model import ErrorModel
    from mirrorsim.scene.model import Scene
    from solver.selfcal import SelfCalibration

VARIANT_CHOICES = ["auto", "cuda", "llvm", "scalar"]
IMAGE_SUFFIXES = (".png", ".pdf", ".svg")  # what a plot may be written as

Options = Callable[[argparse.ArgumentParser], None]
Handler = Callable[[argparse.Namespace], int]
COMMANDS: dict[str, tuple[str, str, Options, Handler]] = {}


def command(name: str, summary: str, description: str,
            *, options: Options) -> Callable[[Handler], Handler]:
    """Register the decorated handler as subcommand ``name``, with its ``options``."""
    def register(handler: Handler) -> Handler:
        COMMANDS[name] = (summary, description, options, handler)
        return handler
    return register


def output(p: argparse.ArgumentParser, flag: str, kind: str,
           *, suffixes: tuple[str, ...] = (), **kwargs) -> None:
    """Add an output option; ``kind`` "file", "dir" or "dataset" (a folder with its own
    claim, :func:`mirrorsim.formats.dataset_folder.claim_folder`) says how
    :func:`check_outputs` checks it before the command does any work."""
    action = p.add_argument(flag, **kwargs)
    p.set_defaults(outputs=[*(p.get_default("outputs") or []), (action.dest, flag, kind)])
    if suffixes:  # the file's format goes by its suffix (matplotlib, OpenCV)
        p.set_defaults(suffixes={**(p.get_default("suffixes") or {}), action.dest: suffixes})


def inputs(p: argparse.ArgumentParser, *named: tuple[str, str, str]) -> None:
    """Declare input paths as (dest, name shown, kind): "file", or "dataset" (a folder
    whose own files are all inputs); :func:`check_outputs` refuses an output over one."""
    p.set_defaults(inputs=[*(p.get_default("inputs") or []), *named])


def common(p: argparse.ArgumentParser, *, scene: bool = True, out: str | None = None,
           out_kind: str = "dir", json: str | None = None, spp: bool = False,
           variant: bool = False, quiet: bool = False, error_model: str | None = None,
           error_model_default: str = "the shipped model the scene's bench calls for: the "
           "bench model for a scene with bench imperfections, the ideal-bench model "
           "otherwise") -> None:
    """Add the shared options: SCENE, --out, --json, --spp/--seed, --variant, --quiet,
    --error-model (``error_model``: what it gives; ``error_model_default``: what is used
    without it)."""
    if scene:
        p.add_argument("scene", type=Path, help="scene file (YAML, see docs/scenes.md)")
        inputs(p, ("scene", "SCENE", "file"))
    if out:  # every such --out defaults to a place in renders/<name>/
        output(p, "--out", out_kind, type=Path, help=out,
               suffixes=IMAGE_SUFFIXES if out_kind == "file" else ())
        p.set_defaults(default_out=True)
    if json:
        output(p, "--json", "file", metavar="FILE", help=f"write {json} here (- = stdout)")
    if spp:
        from mirrorsim.scene.render_settings import MAX_SEED, RenderSettings

        spp_option(p, f"the scene's, else {RenderSettings().spp}")
        p.add_argument("--seed", type=int, help=f"sampler seed, 0..{MAX_SEED} (default: "
                       "the scene's, else 0)")
        sampler_option(p)
    if variant:
        p.add_argument("--variant", default="auto", choices=VARIANT_CHOICES,
                       help="Mitsuba backend; auto = cuda if a GPU works, else llvm if its "
                       "probe renders, else scalar (default: auto)")
    if quiet:
        p.add_argument("--quiet", action="store_true", help="no progress display")
    if error_model:
        inputs(p, ("error_model", "--error-model", "file"))
        p.add_argument("--error-model", type=Path, metavar="FILE",
                       help=f"an error model (`mirrorsim errormodel`): {error_model} (default: "
                       f"{error_model_default})")


class _Once(argparse.Action):
    """Store an option's value, refusing the option a second time: for a list in one
    value (``--prior pan=0.3,scale=0.006``), a repeat would otherwise drop the first
    silently, where a name repeated inside the value is refused."""

    def __call__(self, _parser, namespace, values, _option_string=None):
        seen = f"_given_{self.dest}"
        if getattr(namespace, seen, False):
            raise argparse.ArgumentError(self, "given twice: give it once (a list in one "
                                         "value, comma-separated)")
        setattr(namespace, seen, True)
        setattr(namespace, self.dest, values)


def spp_option(p: argparse.ArgumentParser, default: str) -> None:
    """``--spp N``: samples per pixel in the mirror's image (``default``: what it is when
    not given, in words); declared once for every command that renders."""
    from mirrorsim.scene.render_settings import MAX_SPP

    p.add_argument("--spp", type=int, help=f"samples per pixel in the mirror's image, "
                   f"1..{MAX_SPP} (default: {default})")


def calibrate_option(p: argparse.ArgumentParser, beacon_sigma_alone: bool = True) -> None:
    """``--calibrate pan,scale[,power][,pitch]``, ``--beacon-sigma CM`` and ``--prior NAME=σ,…``:
    self-calibration's settings (:func:`calibration_of`); ``beacon_sigma_alone`` False:
    the command takes --beacon-sigma only with --calibrate."""
    p.add_argument("--calibrate", default=None, metavar="pan,scale[,power][,pitch]",
                   action=_Once,
                   help="estimate bench errors shared by every measurement with the mirror "
                   "(self-calibration; needs 2+ beacons, 3+ for pan, scale and power): pan, "
                   "an offset on "
                   "every alpha (the mount's pan reading); scale, a factor on every d_total "
                   "(the calibration); power, the mirror's curvature 1/R, which moves each "
                   "image by its own amount; pitch, an offset on every elevation (the "
                   "3-D solve alone); comma-separated")
    beacon_sigma_option(p, ("" if beacon_sigma_alone else "with --calibrate only: ")
                        + "each beacon's offset is then estimated with that prior, and the "
                        "ellipse includes it")
    p.add_argument("--prior", default=None, metavar="NAME=SIGMA,...", action=_Once,
                   help="what the bench knows of some of --calibrate's nuisances before the "
                   "frames, as a σ each: pan and pitch in degrees, scale as a fraction "
                   "(0.006: 0.6 %%), "
                   "power in 1/cm; e.g. pan=0.3,scale=0.006 for a pan reading good to about "
                   "±0.5° and a reference distance to ±1 cm at 100 cm.  Each such nuisance "
                   "is then estimated with that prior (default: none, each free but pan, "
                   "which takes the error model's shared α offset where it has one; a pan "
                   "prior adds to it)")


def calibration_of(args: argparse.Namespace, n_beacons: int | None = None,
                   n_targets: int = 1, *, three_d: bool | None = None) -> SelfCalibration:
    """--calibrate, --beacon-sigma and --prior as one checked value (and, where
    ``n_beacons`` is known, that the measurements can carry the nuisances: each image
    gives three readings in 3-D, two in the plane), before any work is done; a bad one
    names its flag.  ``three_d`` False: a planar solve, which refuses the pitch; None:
    not known yet (the names and a planar count only)."""
    from solver.errors import SolverError
    from solver.selfcal import (
        SelfCalibration,
        check_nuisance_sigma,
        check_nuisances,
        check_planar,
        parse_priors,
    )

    names = tuple(comma_items(args.calibrate, "--calibrate"))
    try:
        priors = parse_priors(",".join(comma_items(args.prior, "--prior")))
    except ValueError as exc:
        raise BadArgument("--prior", str(exc)) from None
    try:  # the names always; the count only where the beacons are known
        if three_d is False:  # before the count: more beacons would not help
            check_planar(SelfCalibration(names))
        check_nuisances(names, n_beacons, n_targets, priors=priors,
                        readings=3 if three_d else 2)
    except SolverError as exc:
        raise BadArgument("--calibrate", str(exc)) from None
    try:
        check_nuisance_sigma(priors, names)
    except SolverError as exc:
        raise BadArgument("--prior", str(exc)) from None
    return SelfCalibration(names, beacon_sigma_of(args), priors)


def comma_items(text: str | None, flag: str) -> list[str]:
    """A comma list as given to ``flag`` (None: not given, no items), each item stripped;
    an empty item (``''``, ``pan,``, ``pan,,scale``) is refused: it is a slip, not a
    request for nothing."""
    if text is None:
        return []
    items = [item.strip() for item in text.split(",")]
    if not all(items):
        raise BadArgument(flag, f"{text!r} has an empty item: give names separated by "
                          "commas, each once (e.g. pan,scale)")
    return items


def beacon_sigma_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--beacon-sigma CM``: how well the beacons' believed positions are known."""
    p.add_argument("--beacon-sigma", type=float, default=0.0, metavar="CM", action=_Once,
                   help="how well each beacon's position is known, cm per axis (default 0: "
                   f"exactly); {what} (positions read off a pegboard by hand: ~0.1)")


def beacon_sigma_of(args: argparse.Namespace) -> float:
    """--beacon-sigma, checked: the solver's rule for a position σ
    (:func:`solver.selfcal.check_position_sigma`), and at most MAX_BEACON_SIGMA cm."""
    from solver.errors import SolverError
    from solver.selfcal import check_position_sigma

    v = args.beacon_sigma
    try:
        check_position_sigma(v)
    except SolverError as exc:
        raise BadArgument("--beacon-sigma", str(exc)) from None
    if v > MAX_BEACON_SIGMA:
        raise BadArgument("--beacon-sigma", f"{v:g} must be ≤ {MAX_BEACON_SIGMA:g} cm")
    return float(v)


# a beacon known to worse than this is no known position
MAX_BEACON_SIGMA = 10.0


def emit(args: argparse.Namespace, data: Any) -> None:
    """``--json``'s document: to its file, or (``-``) to stdout alone (the command's
    printed lines went to stderr, :func:`mirrorsim.cli.main._run`)."""
    from mirrorsim.formats.files import emit_json

    emit_json(args.json, data, getattr(args, "json_stdout", None))


def error_model_of(args: argparse.Namespace) -> ErrorModel | None:
    """The model of ``--error-model``, or None where it is not given."""
    if not args.error_model:
        return None
    from mirrorsim.formats.error_model_file import load_error_model

    return load_error_model(args.error_model)


def at_least(*checks: tuple) -> None:
    """Refuse (exit 2) an option given below its least value, or above its most where a
    check names one: ``(flag, value, low)`` or ``(flag, value, low, high)``; None means
    not given."""
    for flag, value, low, *high in checks:
        if value is not None and value < low:
            raise BadArgument(flag, f"{value} must be ≥ {low}")
        if value is not None and high and value > high[0]:
            raise BadArgument(flag, f"{value} must be ≤ {high[0]}")


def finite(args: argparse.Namespace, *dests: str) -> None:
    """Refuse NaN or infinite values of float options (argparse's float takes "nan")."""
    for dest in dests:
        values = getattr(args, dest)
        for v in (values if isinstance(values, list) else [values]):
            for x in (v if isinstance(v, list) else [v]):
                if x is not None and not math.isfinite(x):
                    raise BadArgument("--" + dest.replace("_", "-"), f"{x} is not a finite number")


def sampler_option(p: argparse.ArgumentParser) -> None:
    """--sampler, for commands that render."""
    from mirrorsim.scene.render_settings import SAMPLERS, RenderSettings

    p.add_argument("--sampler", choices=SAMPLERS,
                   help="Mitsuba sampler (default: the scene's render.sampler, else "
                   f"{RenderSettings().sampler}); see docs/performance.md")


def render_options(args: argparse.Namespace, scene: Scene) -> Scene:
    """The scene with --spp, --seed and --sampler where given: the render settings enter
    the scene here, once, and are checked as every scene's are (a bad one names its
    flag)."""
    given = {k: getattr(args, k, None) for k in ("spp", "seed", "sampler")}
    given = {k: v for k, v in given.items() if v is not None}
    return scene.with_render(**given) if given else scene


def load(path: Path) -> Scene:
    """Load a scene and print its warnings on stderr."""
    from mirrorsim.pipelines.scenes import load_scene

    scene = load_scene(path)
    for w in scene.warnings:
        print(f"warning: {path}: {w}", file=sys.stderr)
    return scene


def preload(module: str) -> None:
    """Import ``module`` in a background thread: a command that will need it later
    (matplotlib for a plot) imports it while Mitsuba renders, which releases the GIL."""
    import importlib
    import threading

    threading.Thread(target=importlib.import_module, args=(module,), daemon=True).start()


def default_workers() -> int:
    """Half the cores (a render uses several threads per worker)."""
    return max(1, (os.cpu_count() or 2) // 2)
