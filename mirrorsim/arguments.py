"""The public API's one argument check: each ``mirrorsim.<name>`` function is wrapped
by :func:`checked`, which holds every argument to its parameter's type hint
(:func:`solver.arguments.conform`: None, a wrong type, NaN, a bool for a number, a
string for a bool refused as :class:`~mirrorsim.errors.BadParameter` naming the
parameter; numpy scalars taken as plain numbers) before the function does any work or
writes anything.  The public dataclasses check their own fields
(:func:`solver.arguments.check_fields`).
"""

from __future__ import annotations

import builtins
import functools
import inspect
import os
import typing
from collections.abc import Callable
from typing import Any

from numpy.typing import ArrayLike

from solver.arguments import ANY, checked_value
from solver.errors import BadParameter


class _Names(dict):
    """A function's module namespace in which a name it imports for type checking only
    (unknown at run time) is :data:`~solver.arguments.ANY`: its hint checks nothing."""

    def __missing__(self, _key: str) -> Any:
        return ANY


@functools.cache
def parameter_hints(fn: Callable) -> dict[str, Any]:
    """The resolved type hint of each of ``fn``'s parameters."""
    names = _Names(vars(builtins))
    names.update(vars(typing))
    names.update(getattr(fn, "__globals__", {}))
    names["ArrayLike"] = ArrayLike
    out = {}
    for name, annotation in getattr(fn, "__annotations__", {}).items():
        if name == "return":
            continue
        try:
            out[name] = (eval(annotation, {}, names)  # noqa: S307 (the code's own hints)
                         if isinstance(annotation, str) else annotation)
        except Exception:  # noqa: BLE001 (a hint that cannot be read checks nothing)
            out[name] = ANY
    return out


def check_arguments(fn: Callable, args: tuple, kwargs: dict) -> inspect.BoundArguments:
    """``fn``'s arguments bound, each held to its hint and made plain.

    Raises
    ------
    BadParameter
        The first argument its hint refuses, named.
    """
    bound = inspect.signature(fn).bind(*args, **kwargs)
    hints = parameter_hints(fn)
    for name, value in bound.arguments.items():
        if name in hints:
            try:
                bound.arguments[name] = checked_value(name, value, hints[name])
            except BadParameter as exc:
                raise _with_reader(exc, value) from None
    return bound


# a value read from a file, and the public reader of its file: a path given where the
# value is wanted is a slip the refusal can name the fix of
READERS = {"Scene": "ms.load_scene(path)", "ErrorModel": "ms.load_error_model(path)",
           "Measurements": "ms.load_measurements(path)"}


def _with_reader(exc: BadParameter, value: Any) -> BadParameter:
    """``exc`` with the reader to use where a path was given for a value a file holds."""
    if isinstance(value, str | os.PathLike):
        for name, reader in READERS.items():
            if exc.message.endswith(f"is not a {name}") or exc.message.endswith(
                    f"is not an {name}"):
                return BadParameter(exc.parameter, f"{exc.message} (read one with {reader})")
    return exc


def checked(fn: Callable) -> Callable:
    """``fn`` with its arguments checked (:func:`check_arguments`) before it runs."""
    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        bound = check_arguments(fn, args, kwargs)
        return fn(*bound.args, **bound.kwargs)
    return run
