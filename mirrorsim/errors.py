"""The exception classes that reach the user, and the exit status of each.

Bad input (a file, a key or an option the user can fix) exits with status 2;
a run that failed (nothing usable in a frame, a backend that does not work here,
measurements the solver cannot solve) exits with status 1.  The CLI maps classes to
statuses with :func:`exit_status`; nothing is told apart by name.
"""

from __future__ import annotations

import sys
from typing import TextIO

from solver.errors import InputError, SolverError

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1

__all__ = ["InputError", "SolverError", "SceneError", "BadParameter", "BadArgument", "OutputError",
           "RunFailed",
           "DetectionError", "BackendError", "EXIT_BAD_INPUT", "EXIT_FAILED", "exit_status",
           "one_line_warning"]


class SceneError(InputError):
    """A bad scene or dataset-spec file.  ``others``: the further failures found in the
    same file (independent of this one; ``mirrorsim check`` lists them all)."""

    others: tuple[SceneError, ...] = ()


class BadParameter(InputError):
    """A library function's parameter out of range, named as the function names it:
    ``BadParameter("steps", "0 must be within 1..200")``.  The command line turns it into
    a :class:`BadArgument` naming the flag; the library knows no flags."""

    def __init__(self, parameter: str, message: str):
        self.parameter = parameter
        super().__init__(parameter, "", message)


class BadArgument(InputError):
    """A command-line option out of range: ``BadArgument("--workers", "0 must be ≥ 1")``
    (raised by :mod:`mirrorsim.cli` only)."""

    def __init__(self, option: str, message: str):
        super().__init__(option, "", message)


class OutputError(InputError):
    """An output path that cannot be written (exit 2): ``OutputError(path, message)``."""

    def __init__(self, path, message: str):
        super().__init__(path, "", message)


class RunFailed(RuntimeError):
    """The run itself failed (exit status 1); the message says why."""


class DetectionError(RunFailed):
    """Nothing usable was found in a frame (the message says what)."""


class BackendError(RunFailed):
    """The requested Mitsuba variant does not work on this machine."""


def exit_status(exc: BaseException) -> int | None:
    """The exit status for an exception the user should see as one line, else None."""
    if isinstance(exc, InputError):
        return EXIT_BAD_INPUT
    if isinstance(exc, RunFailed | SolverError):
        return EXIT_FAILED
    return None


def one_line_warning(message: Warning | str, category: type[Warning],  # noqa: ARG001
                     filename: str, lineno: int, file: TextIO | None = None,  # noqa: ARG001
                     line: str | None = None) -> None:  # noqa: ARG001
    """``warnings.showwarning`` for the command line (and its worker processes): one
    ``warning:`` line on stderr, without the source line."""
    print(f"warning: {message}", file=sys.stderr)
