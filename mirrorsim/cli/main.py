"""The ``mirrorsim`` command: argument parsing and printing only.

The commands live in :mod:`mirrorsim.cli.authoring_commands`,
:mod:`mirrorsim.cli.scene_commands`, :mod:`mirrorsim.cli.analysis_commands` and
:mod:`mirrorsim.cli.dataset_commands`, each handler declared beside its options.
Errors are told apart by class (:mod:`mirrorsim.errors`): bad input exits 2, a failed
run 1, each with one line on stderr.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import warnings
from typing import NoReturn

from mirrorsim import __version__
from mirrorsim.cli import (  # noqa: F401 (they register)
    analysis_commands,
    authoring_commands,
    dataset_commands,
    scene_commands,
)
from mirrorsim.cli.outputs import check_outputs, stdout_output
from mirrorsim.cli.registry import COMMANDS
from mirrorsim.errors import (
    DISK_CAUSES,
    BadArgument,
    BadParameter,
    SolverError,
    exit_status,
    one_line_warning,
    write_error,
)

# a library parameter whose flag is not "--" + its name with "-" for "_"
FLAG_OF = {"kind": "--path", "eps_deg": "--eps", "yaw_spread_deg": "--yaw-spread",
           "sigma.alpha_deg": "--sigma-alpha", "sigma.d_total_rel": "--sigma-d",
           "n_beacons": "--beacons", "position_sigma": "--beacon-sigma",
           "nuisances": "--calibrate"}

# the order of `mirrorsim --help`: the main job first
ORDER = ("evaluate", "render", "check", "plot", "detect", "calibrate", "budget", "dataset",
         "export", "errormodel", "solve", "montecarlo", "plan")


class _OneLineParser(argparse.ArgumentParser):
    """argparse's refusals (a flag's value of the wrong type, a flag given twice, a
    missing argument) in one line, as every other bad input is, not after the usage
    block; its subcommands' parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {self.prog}: {message} (see `{self.prog} --help`)\n")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser with every registered command; given the command line
    ``argv``, with the options of its command only (a command's options import what it
    needs, SciPy's optimizer for `track`: `mirrorsim --help` and `check` need none of
    that)."""
    parser = _OneLineParser(
        prog="mirrorsim",
        description="Physically rendered mirror space for NLOS localization (SLTR): render "
                    "scenes with exact ground truth, detect, solve and score them; datasets, "
                    "error models and beacon placement.")
    parser.add_argument("--version", action="version", version=f"mirrorsim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = None if argv is None else next((a for a in argv if not a.startswith("-")), "")
    for name in sorted(COMMANDS, key=lambda n: ORDER.index(n) if n in ORDER else len(ORDER)):
        summary, description, options, handler = COMMANDS[name]
        p = sub.add_parser(name, help=summary, description=description)
        if chosen is None or name == chosen:
            options(p)
        p.set_defaults(handler=handler)
    return parser


class _Interrupt:
    """The signal that stopped the run, if any: an interrupt can reach us wrapped in
    another exception (Dr.Jit turns one raised inside a render into a RuntimeError)."""

    signum: int | None = None

    @classmethod
    def handle(cls, signum: int, _frame) -> None:
        cls.signum = signum
        raise KeyboardInterrupt


def _interrupted() -> int:
    signum = _Interrupt.signum or signal.SIGINT
    print("interrupted" if signum == signal.SIGINT else "terminated", file=sys.stderr)
    return 128 + signum


# the commands that say every failure found in a scene file (the others say the first
# and count the rest)
LISTS_EVERY_FAILURE = ("check", "plot")

def main(argv: list[str] | None = None) -> int:
    """Run one command; return its exit status (130 after Ctrl-C, 143 after SIGTERM)."""
    _Interrupt.signum = None
    # the parser imports the commands' modules: under the entry point's handlers still
    # (:mod:`mirrorsim.cli.entry`), which end the process at once
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    # signals can be handled in the main thread only (a caller may run us in another)
    main_thread = threading.current_thread() is threading.main_thread()
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)
              if main_thread}
    for sig, handler in before.items():
        if handler is not signal.SIG_IGN:  # a background job's SIGINT stays ignored
            signal.signal(sig, _Interrupt.handle)
    try:
        return _run(args)
    finally:  # a caller in Python (a test, a notebook) gets its own handlers back
        for sig, handler in before.items():
            if handler is not None:  # None: installed outside Python, cannot be restored
                signal.signal(sig, handler)


def _run(args: argparse.Namespace) -> int:
    warnings.showwarning = one_line_warning
    try:
        check_outputs(args)
        if not stdout_output(args):
            return args.handler(args)
        # `--json -` (or another JSON output given as -): stdout carries the JSON alone
        # (it pipes into jq); what the command prints for people goes to stderr
        out = sys.stdout
        args.json_stdout = out
        with contextlib.redirect_stdout(sys.stderr):
            return args.handler(args)
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0
    except Exception as exc:
        if _Interrupt.signum is not None:
            return _interrupted()
        if isinstance(exc, OSError) and exc.errno in DISK_CAUSES:  # a write outside ours
            exc = write_error(exc.filename or "", exc, "cannot write")
        if isinstance(exc, BadParameter):  # the library names parameters, the user flags
            exc = BadArgument(flag_of(exc.parameter), exc.message)
        status = exit_status(exc)
        if status is None:
            raise
        what = "cannot solve: " if isinstance(exc, SolverError) else ""
        others = getattr(exc, "others", ())  # a scene file's further failures
        if others and args.command in LISTS_EVERY_FAILURE:  # a line each
            for e in (exc, *others):
                print(f"error: {e}", file=sys.stderr)
            return status
        more = (f" (and {len(others)} more: `mirrorsim check` lists them)" if others else "")
        print(f"error: {what}{exc}{more}", file=sys.stderr)
        return status


def flag_of(parameter: str) -> str:
    """The command-line flag of a library parameter (``odometry_sigma`` → ``--odometry-sigma``)."""
    return FLAG_OF.get(parameter, "--" + parameter.replace("_", "-"))


if __name__ == "__main__":
    sys.exit(main())
