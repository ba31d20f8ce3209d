"""Writing files safely: atomic replacement and strict JSON.

Every output appears atomically: it is written under a temporary name beside its
destination and renamed once complete, so a reader never sees half a file and an
interrupted run leaves the old file (or none).  JSON is strict: NaN and infinities
become ``null``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np


def jsonable(value: Any) -> Any:
    """``value`` with numpy scalars and arrays made plain, and NaN/±inf made ``None``."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, Path):
        return str(value)
    return value


def dumps(data: Any, indent: int | None = 2) -> str:
    """Strict JSON text of ``data`` (see :func:`jsonable`), with a final newline."""
    return json.dumps(jsonable(data), indent=indent, allow_nan=False) + "\n"


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path``; renamed onto it when the block ends cleanly.

    The temporary name keeps the destination's suffix, so writers that choose a format
    by suffix (matplotlib, OpenCV, Mitsuba) write the right one.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_json(path: str | Path, data: Any) -> Path:
    """Write strict JSON atomically."""
    return write_text(path, dumps(data))


def emit_json(dest: str | Path | None, data: Any) -> None:
    """Write strict JSON to a file, to stdout for ``"-"``, or nowhere for None."""
    if dest is None:
        return
    if str(dest) == "-":
        sys.stdout.write(dumps(data))
    else:
        write_json(dest, data)


def read_json_cache(path: Path) -> dict:
    """A JSON cache file's contents ({} if missing or unreadable)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def write_json_cache(path: Path, data: dict) -> None:
    """Replace a JSON cache file atomically; an unwritable cache only costs a redo."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, data)
    except OSError:
        pass
