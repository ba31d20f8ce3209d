"""One argument check for the public API: each argument against its type hint.

The public functions (``mirrorsim.<name>``) are wrapped by
:func:`mirrorsim.arguments.checked`, and the public dataclasses call
:func:`check_fields` first thing in ``__post_init__``; both hold each value to
:func:`conform`.  They read the parameter's own type hint, so a parameter's type is
declared once, in its signature.  Before any work or write, a wrong argument raises
:class:`BadParameter` (an :class:`~solver.errors.InputError`, exit 2 on the command
line) naming it:

* ``None`` where the hint does not allow it; a value of another type;
* NaN or an infinity where a number is wanted; a ``bool`` where a number is wanted
  (``True`` is an int to Python, never a count to a user); a string where a bool is
  wanted (``"no"`` is true to Python);
* a numpy scalar where a number is right is taken, and passed on as a plain ``int`` or
  ``float`` (a numpy number would write itself as ``np.float64(0.3)`` in a file).

Ranges (a count ≥ 1, a seed's bound) stay with each function, which knows them; this
checks what every function shares.  A hint this module cannot resolve
(a name imported for type checking only) accepts anything.
"""

from __future__ import annotations

import collections.abc as cabc
import dataclasses
import functools
import math
import typing
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from solver.errors import BadParameter


class _Unresolved:
    """A hint that names something this module cannot see: anything is taken."""

    def __getattr__(self, _name: str) -> _Unresolved:
        return self

    def __or__(self, _other: object) -> _Unresolved:
        return self

    __ror__ = __or__

    def __getitem__(self, _item: object) -> _Unresolved:
        return self


ANY = _Unresolved()


_UNION = type(int | None)  # types.UnionType, the type of ``X | Y``


@functools.cache
def field_hints(cls: type) -> dict[str, Any]:
    """A dataclass's fields' resolved hints (one it cannot resolve: :data:`ANY`)."""
    try:
        return typing.get_type_hints(cls)
    except Exception:  # noqa: BLE001 (a name imported for type checking only)
        return {f.name: ANY for f in dataclasses.fields(cls)}


def _kind(tp: Any) -> str:
    """What a hint wants, in words: ``a number``, ``a Scene``, ``a str or a path``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, _UNION):
        return " or ".join(_kind(a) for a in typing.get_args(tp) if a is not type(None))
    if tp is ArrayLike:
        return "an array of numbers"
    if tp in (float, int):
        return "a whole number" if tp is int else "a number"
    if tp is bool:
        return "True or False"
    if tp is str:
        return "a string"
    if getattr(tp, "__name__", "") in ("Path", "PathLike"):
        return "a path"
    if origin in (tuple, list, cabc.Sequence):
        args = typing.get_args(tp)
        fixed = origin is tuple and args and args[-1] is not Ellipsis
        count = f"{len(args)} " if fixed else ""
        return f"a {origin.__name__} of {count}{_plural(_kind(args[0])) if args else 'values'}"
    if origin in (dict, cabc.Mapping):
        args = typing.get_args(tp)
        return (f"a mapping of {_plural(_kind(args[0]))} to {_plural(_kind(args[1]))}"
                if len(args) == 2 and args[1] is not Any else "a mapping")
    if origin is cabc.Callable or tp is cabc.Callable:
        return "a function"
    name = getattr(tp, "__name__", str(tp))
    return f"{'an' if name[:1].lower() in 'aeiou' else 'a'} {name}"


def _plural(kind: str) -> str:
    """``a number`` → ``numbers``; ``a tuple of numbers`` → ``tuples of numbers``."""
    words = kind.split(" ")
    if words[0] in ("a", "an"):
        words = words[1:]
    words[0] += "s"
    return " ".join(words)


class Refused(Exception):
    """The value does not conform (the message says how)."""


def conform(value: Any, tp: Any) -> Any:
    """``value`` as the hint ``tp`` takes it (numpy scalars made plain; a list where a
    tuple is wanted made a tuple), or :class:`Refused`."""
    if tp is ANY or tp is Any or isinstance(tp, typing.TypeVar):
        return value
    origin = typing.get_origin(tp)
    if tp is None or tp is type(None):
        if value is None:
            return None
        raise Refused("not None")
    if origin in (typing.Union, _UNION) or tp is ArrayLike:
        if tp is ArrayLike:
            return _array(value)
        for arg in typing.get_args(tp):
            try:
                return conform(value, arg)
            except Refused:
                continue
        raise Refused(_kind(tp))
    if value is None:
        raise Refused(_kind(tp))
    if tp in (bool, int, float, str):
        return _scalar(value, tp)
    if origin in (tuple, list, cabc.Sequence):
        return _sequence(value, tp, origin)
    if origin in (dict, cabc.Mapping) or tp in (dict, cabc.Mapping):
        return _mapping(value, tp)
    if origin is cabc.Callable or tp is cabc.Callable:
        if callable(value):
            return value
        raise Refused("a function")
    if origin is typing.Literal:
        if value in typing.get_args(tp):
            return value
        raise Refused(" or ".join(repr(a) for a in typing.get_args(tp)))
    if isinstance(tp, type):
        if isinstance(value, tp):
            return value
        raise Refused(_kind(tp))
    return value  # a hint of a form this module does not check


def _scalar(value: Any, tp: type) -> Any:
    """``value`` as a ``bool``, ``int``, ``float`` or ``str`` (a 0-d array, a numpy
    scalar taken as the plain one; NaN and infinities refused as numbers)."""
    if isinstance(value, np.ndarray) and value.shape == () and tp in (int, float, bool):
        value = value[()]  # a 0-d array is a number (numpy's reductions give them)
    if tp is bool:
        if isinstance(value, bool | np.bool_):
            return bool(value)
        raise Refused("True or False")
    if tp is int:
        if isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_):
            return int(value)
        raise Refused("a whole number")
    if tp is float:
        if isinstance(value, int | float | np.integer | np.floating) and not isinstance(
                value, bool | np.bool_):
            if not math.isfinite(float(value)):
                raise Refused("a finite number")
            return float(value)
        raise Refused("a number")
    if tp is str:
        if isinstance(value, str):
            return value
        raise Refused("a string")
    raise AssertionError(tp)  # (conform calls it with those four only)


def _mapping(value: Any, tp: Any) -> Any:
    """``value`` as a mapping of the hint's key and value types."""
    if not isinstance(value, cabc.Mapping):
        raise Refused("a mapping")
    args = typing.get_args(tp)
    if len(args) == 2:
        try:
            return {conform(k, args[0]): conform(v, args[1]) for k, v in value.items()}
        except Refused:  # an item's refusal, said of the whole
            raise Refused(_kind(tp)) from None
    return value


def _sequence(value: Any, tp: Any, origin: Any) -> Any:
    if isinstance(value, str | bytes) or not isinstance(value, cabc.Sequence | np.ndarray):
        raise Refused(_kind(tp))
    args = typing.get_args(tp)
    try:
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise Refused(_kind(tp))
            items = [conform(v, a) for v, a in zip(value, args, strict=True)]
        else:
            items = [conform(v, args[0]) for v in value] if args else list(value)
    except Refused:  # an item's refusal, said of the whole
        raise Refused(_kind(tp)) from None
    return tuple(items) if origin is tuple else items


def _array(value: Any) -> Any:
    """An array of finite numbers (a point, a list of them)."""
    if value is None or isinstance(value, str | bytes | bool | np.bool_):
        raise Refused("an array of numbers")
    try:
        arr = np.asarray(value, float)
    except (TypeError, ValueError):
        raise Refused("an array of numbers") from None
    if not np.all(np.isfinite(arr)):
        raise Refused("an array of finite numbers")
    return value


def shown(value: Any) -> str:
    """A value as a refusal shows it: its repr, short, and its type where that helps."""
    if value is None:
        return "None"
    text = repr(value)
    text = text if len(text) <= 40 else text[:37] + "…"
    return f"{text} (a {type(value).__name__})" if not isinstance(
        value, float | int) or isinstance(value, bool) else text


def checked_value(name: str, value: Any, tp: Any) -> Any:
    """:func:`conform`'s value, or :class:`BadParameter` naming ``name``."""
    try:
        return conform(value, tp)
    except Refused as why:
        raise BadParameter(name, f"{shown(value)} is not {why}") from None


def check_fields(obj: Any) -> None:
    """A (frozen) dataclass's fields checked against their hints and made plain: the
    first thing its ``__post_init__`` does."""
    hints = field_hints(type(obj))
    for f in dataclasses.fields(obj):
        if f.name in hints:
            value = getattr(obj, f.name)
            plain = checked_value(f.name, value, hints[f.name])
            if plain is not value:
                object.__setattr__(obj, f.name, plain)
