"""Typed reading of parsed YAML or JSON with one-line errors naming file and key path.

One reader serves every input file: scenes, dataset specs and measurements.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import yaml

from mirrorsim.errors import SceneError
from mirrorsim.scene.model import MAX_RESOLUTION
from solver.errors import BadParameter, InputError


def show(value: Any) -> str:
    """A short rendering of an input value for error messages."""
    if isinstance(value, str):
        return repr(value) if len(value) <= 40 else repr(value[:37] + "...")
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list) and len(value) > 4:
        return f"a list of {len(value)} items"
    if value is None:
        return "nothing (null)"
    return str(value)


def read_input_text(path: str | Path, error_class: type[InputError] = InputError) -> str:
    """The text of an input file, or ``error_class`` with one line: missing, not a
    regular file (a FIFO would wait for a writer for ever), unreadable, not UTF-8 text."""
    path = Path(path)
    try:
        if not path.is_file():
            raise error_class(path, "", "no such file" if not path.exists() else
                              "not a regular file (a folder, FIFO, device or socket)")
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:  # a Parquet or an image given for a JSON or YAML file
        raise error_class(path, "", "cannot read: not UTF-8 text (a binary file?)") from None
    except OSError as exc:
        raise error_class(path, "", f"cannot read: {exc.strerror or exc}") from None


class _DuplicateKey(ValueError):
    def __init__(self, key: str):
        super().__init__(key)
        self.key = key


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict:
    """A JSON object's pairs as a dict, refusing a key given twice (as the scene reader
    refuses one in YAML)."""
    out: dict = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(k)
        out[k] = v
    return out


def read_stdin_text(error_class: type[InputError] = InputError) -> str:
    """Standard input's text (a command's ``-`` input, for a pipe), strictly UTF-8: the
    locale's decoding would let a binary stream through as escaped characters."""
    try:
        return sys.stdin.buffer.read().decode("utf-8")
    except UnicodeDecodeError:
        raise error_class("<stdin>", "", "cannot read: not UTF-8 text (a binary "
                          "stream?)") from None


def read_json(path: str | Path, error_class: type[InputError] = InputError) -> Any:
    """Parse a JSON file, raising ``error_class`` with one line for a missing, unreadable,
    malformed or absurdly nested one."""
    return parse_json(read_input_text(path, error_class), path, error_class)


def parse_json(text: str, path: str | Path, error_class: type[InputError] = InputError) -> Any:
    """Parse JSON text read from ``path`` (named in messages) as :func:`read_json` does."""
    try:
        return json.loads(text, object_pairs_hook=_unique_keys)
    except _DuplicateKey as exc:
        raise error_class(path, exc.key, "given twice in one object (JSON would keep the "
                          "last silently): give it once") from None
    except json.JSONDecodeError as exc:
        raise error_class(path, "", f"malformed JSON: line {exc.lineno}, column "
                          f"{exc.colno}: {exc.msg}") from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise error_class(path, "", f"malformed JSON: {str(exc).splitlines()[0]}") from None
    except RecursionError:
        raise error_class(path, "", "malformed JSON: nested too deeply") from None


class Reader:
    """Reads typed values, raising ``error_class`` with the file, key path and value.

    Parameters
    ----------
    source : str or Path
        The file named in messages.
    error_class : type
        An :class:`InputError` subclass to raise.
    """

    def __init__(self, source: str | Path, error_class: type[InputError] = InputError):
        self.source = str(source)
        self.error_class = error_class

    def fail(self, key: str, message: str) -> InputError:
        """The error to raise for ``key`` (not raised here, so callers ``raise`` it)."""
        return self.error_class(self.source, key, message)

    def built(self, key: str, cls: type, **fields: Any) -> Any:
        """``cls(**fields)``, a model dataclass that checks its own values: a value it
        refuses (a ``BadParameter`` naming its field) is refused here under ``key``."""
        try:
            return cls(**fields)
        except BadParameter as exc:
            raise self.fail(f"{key}.{exc.parameter}" if key else exc.parameter,
                            exc.message) from None

    def mapping(self, value: Any, key: str, required: set[str] | tuple[str, ...],
                *, optional: set[str] | tuple[str, ...] = ()) -> dict:
        """A mapping with exactly the allowed keys and all the required ones."""
        allowed = set(required) | set(optional)
        if not isinstance(value, dict):
            raise self.fail(key or "(top level)", f"expected a mapping, got {show(value)}")
        prefix = f"{key}." if key else ""
        for k in value:
            if not isinstance(k, str) or k not in allowed:
                raise self.fail(f"{prefix}{k}",
                                f"unknown key (allowed here: {', '.join(sorted(allowed))})")
        for k in sorted(required):
            if k not in value:
                raise self.fail(f"{prefix}{k}", "missing required key")
        return value

    def number(self, value: Any, key: str, *, positive: bool = False, low: float | None = None,
               high: float | None = None) -> float:
        """A finite number, optionally > 0 and within [low, high]."""
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"expected a number, got {show(value)}")
        try:
            v = float(value)
        except OverflowError:  # an integer of hundreds of digits
            raise self.fail(key, f"{show(value)[:20]}… is not a finite number") from None
        if not math.isfinite(v):
            raise self.fail(key, f"{show(value)} is not a finite number")
        if positive and v <= 0.0:
            raise self.fail(key, f"{show(value)} must be > 0")
        if low is not None and v < low:
            raise self.fail(key, f"{show(value)} must be ≥ {low:g}")
        if high is not None and v > high:
            raise self.fail(key, f"{show(value)} must be ≤ {high:g}")
        return v

    def integer(self, value: Any, key: str, *, low: int | None = None,
                high: int | None = None) -> int:
        """An integer within [low, high] (either bound optional)."""
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"expected an integer, got {show(value)}")
        if low is not None and value < low:
            raise self.fail(key, f"{value} must be ≥ {low}")
        if high is not None and value > high:
            raise self.fail(key, f"{value} must be ≤ {high}")
        return value

    def pair(self, value: Any, key: str, *, positive: bool = False,
             high: float | None = None) -> tuple[float, float]:
        """A list of two numbers (each ≤ ``high`` where given)."""
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise self.fail(key, f"expected a list of two numbers, got {show(value)}")
        return (self.number(value[0], f"{key}[0]", positive=positive, high=high),
                self.number(value[1], f"{key}[1]", positive=positive, high=high))


    def point(self, value: Any, key: str) -> tuple[tuple[float, float], float]:
        """A position on the board, ``[x, y]``, or raised, ``[x, y, z]``: (x, y) and z,
        the height of the object's base above the board (cm; 0 when omitted, never
        below the board)."""
        if not isinstance(value, list | tuple) or len(value) not in (2, 3):
            raise self.fail(key, f"expected [x, y] or [x, y, z] (cm), got {show(value)}")
        xy = self.pair(list(value[:2]), key)
        if len(value) == 2:
            return xy, 0.0
        z = self.number(value[2], f"{key}[2]")
        if z < 0.0:
            raise self.fail(f"{key}[2]", f"{show(value[2])} lies below the board: a height "
                            "above it must be ≥ 0")
        return xy, z


def point_list(xy: tuple[float, float], z: float) -> list[float]:
    """A position as a file writes it (what :meth:`Reader.point` reads): [x, y] on the
    board, [x, y, z] raised."""
    return [*xy, z] if z else list(xy)


def read_resolution(r: Reader, res: Any, key: str) -> tuple[int, int]:
    """[width, height] in px, each within 2..MAX_RESOLUTION."""
    if not isinstance(res, list | tuple) or len(res) != 2:
        raise r.fail(key, f"expected [width, height] in px, got {show(res)}")
    return (r.integer(res[0], f"{key}[0]", low=2, high=MAX_RESOLUTION[0]),
            r.integer(res[1], f"{key}[1]", low=2, high=MAX_RESOLUTION[1]))


class _StrictLoader(yaml.SafeLoader):
    """Safe loading that also refuses duplicate keys (a silent override otherwise)."""


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False):
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark
            )
        seen.add(key)
    return loader.construct_mapping(node, deep)


_StrictLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping
)


def read_yaml(path: str | Path) -> Any:
    """Parse a YAML file strictly (safe tags only, no duplicate keys).

    Raises
    ------
    SceneError
        If the file is missing, unreadable or malformed.
    """
    text = read_input_text(path, SceneError)
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SceneError(path, "", f"malformed YAML: {where}{problem}") from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise SceneError(path, "", f"malformed YAML: {str(exc).splitlines()[0]}") from None
    except RecursionError:
        raise SceneError(path, "", "malformed YAML: nested too deeply") from None
