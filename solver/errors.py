"""The solver's exception classes (the solver imports nothing of mirrorsim).

:class:`InputError` is bad input a user can fix (a command exits with status 2);
:class:`SolverError` is input that the method cannot solve (status 1).
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: ``str(err)`` is one line naming the file, the key path and the value."""

    def __init__(self, file: object, key: str, message: str):
        # ``file``: a path or a name such as ``<measurements>``, shown as str(file)
        self.file, self.key, self.message = str(file), key, message
        # a file name with a newline or other control character would split the line
        shown = repr(self.file) if any(c < " " for c in self.file) else self.file
        super().__init__(f"{shown}: {key}: {message}" if key else f"{shown}: {message}")


class SolverError(ValueError):
    """Input the method cannot solve (degenerate geometry or impossible measurements)."""


class BadParameter(InputError):
    """A library function's parameter of the wrong type or out of range, named as the
    function names it: ``BadParameter("steps", "0 must be within 1..200")``.  The command
    line turns it into a ``BadArgument`` naming the flag; the library knows no flags."""

    def __init__(self, parameter: str, message: str):
        self.parameter = parameter
        super().__init__(parameter, "", message)
