"""The ``mirrorsim`` command's entry point: signals first, then the heavy imports.

Importing the commands and building the parser takes most of a second (NumPy, SciPy's
optimizer): a Ctrl-C then would raise inside a module's initialisation (a traceback, or
an abort inside a C extension).  So until the parser is built, SIGINT and SIGTERM end
the process at once with the status of an interrupt (128 + the signal); afterwards
:func:`mirrorsim.cli.main.main` handles them as exceptions, so that a run (and Mitsuba,
imported by the commands that render) stops cleanly.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys


def _exit_now(signum: int, _frame) -> None:
    os.write(2, b"interrupted\n" if signum == signal.SIGINT else b"terminated\n")
    os._exit(128 + signum)


def _end_on_signals() -> None:
    """SIGINT and SIGTERM end the process at once (one ignored by the caller, a
    background job's SIGINT, stays ignored)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, _exit_now)


def main() -> int:
    """Run the command line (the console script)."""
    _end_on_signals()
    from mirrorsim.cli.main import main as run

    status = run()
    # past the run, a late signal ends the process at once again; and after an interrupt
    # the interpreter's clean-up is skipped: Dr.Jit's threads may still be finishing a
    # kernel, and calling back into a finalizing interpreter aborts it
    _end_on_signals()
    if status >= 128:
        with contextlib.suppress(OSError):  # a reader that went away
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(status)
    return status


if __name__ == "__main__":
    sys.exit(main())
