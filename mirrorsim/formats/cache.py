"""mirrorsim's cache: one verified file per entry (backend probes, calibrations).

Each entry is its own file, ``<root>/<kind>/<hash of its key>.json``, written
atomically, so concurrent runs never lose each other's entries (a shared file rewritten
by each would keep only the last writer's).  An entry carries its full key and a
checksum of its key and value; one that is unreadable, for another key, damaged or not
of the expected shape is not trusted: it is redone, with a ``warning:`` line.  The root
is ``MIRRORSIM_CACHE_DIR``, else ``$XDG_CACHE_HOME/mirrorsim``, else
``~/.cache/mirrorsim``.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mirrorsim.errors import DiskError, OutputError
from mirrorsim.formats.files import jsonable, read_regular_bytes, write_json

FORMAT = "mirrorsim-cache-1"


def cache_root() -> Path:
    """The cache folder (``MIRRORSIM_CACHE_DIR`` overrides)."""
    root = os.environ.get("MIRRORSIM_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "mirrorsim")
    return Path(root)


def entry_path(kind: str, key: str) -> Path:
    """The file of entry ``key`` of ``kind`` ("backend", "calibration")."""
    return cache_root() / kind / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.json"


def checksum(data: Any) -> str:
    """SHA-256 of ``data``'s canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def seal(data: dict) -> dict:
    """``data`` as it is written (:func:`~mirrorsim.formats.files.jsonable`: NaN as null,
    numpy numbers plain) with the checksum of its contents under ``"sha256"`` (a frame's
    truth file, a dataset's row file)."""
    plain = jsonable(data)
    return {**plain, "sha256": checksum(plain)}


def unseal(data: object, what: str) -> dict:
    """The contents of a sealed document (see :func:`seal`), verified.

    Raises
    ------
    ValueError
        If it is not a mapping, has no checksum, or its checksum does not match.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{what} is not a JSON object")
    data = dict(data)
    if "sha256" not in data:
        raise ValueError(f"{what} carries no checksum (damaged, or from an older mirrorsim)")
    if data.pop("sha256") != checksum(data):
        raise ValueError(f"{what}'s checksum does not match its contents")
    return data


def read_entry(kind: str, key: str, check: Callable[[dict], None] | None = None
               ) -> dict | None:
    """The value cached for ``key``, verified; None when there is none or it fails
    verification (then with a warning: the caller redoes it).

    ``check(value)`` raises ``ValueError``, ``KeyError`` or ``TypeError`` for a value of
    the wrong shape (a missing key, a wrong type, inconsistent numbers).
    """
    path = entry_path(kind, key)
    try:
        data = read_regular_bytes(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        return _distrust(path, f"unreadable ({exc.strerror})")
    try:
        entry = json.loads(data)  # bytes: a file that is not UTF-8 fails here, a ValueError
        if not isinstance(entry, dict) or entry.get("format") != FORMAT:
            raise ValueError("not a mirrorsim cache entry")
        value = entry["value"]
        if entry.get("key") != key:
            raise ValueError("an entry for another key")
        if entry.get("sha256") != checksum({"key": key, "value": value}):
            raise ValueError("its checksum does not match its contents")
        if not isinstance(value, dict):
            raise TypeError("its value is not a mapping")
        if check is not None:
            check(value)
    except (ValueError, KeyError, TypeError, RecursionError) as exc:
        return _distrust(path, str(exc) or type(exc).__name__)
    return value


def write_entry(kind: str, key: str, value: dict) -> None:
    """Cache ``value`` for ``key`` (atomically); an unwritable cache only costs a redo."""
    entry = {"format": FORMAT, "key": key, "value": value,
             "sha256": checksum({"key": key, "value": value})}
    path = entry_path(kind, key)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, entry)
    except (OSError, OutputError, DiskError):  # atomic writes report a failure as these
        pass


def _distrust(path: Path, why: str) -> None:
    warnings.warn(f"cache entry {str(path)!r} not trusted ({why}); redoing it",
                  RuntimeWarning, stacklevel=3)
    return None
