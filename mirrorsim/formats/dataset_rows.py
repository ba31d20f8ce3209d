"""A dataset's row files and its description: each row sealed with the digest of the
dataset's settings and the SHA-256 of its scene's files, verified before it is trusted
(a resume redoes what fails; a reader refuses it); ``dataset.json`` read with each key
of its type.  The folder, its lock and its table are
:mod:`mirrorsim.formats.dataset_folder`'s.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path
from typing import Any

from mirrorsim.errors import InputError
from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.cache import checksum, seal, unseal
from mirrorsim.formats.files import jsonable, read_regular_bytes

DATASET_FORMAT = "mirrorsim-dataset"


def scene_name(i: int) -> str:
    """File name of scene i."""
    return f"scene{i:06d}"


class DatasetError(InputError):
    """A run that cannot start (e.g. a folder holding another dataset): bad input;
    ``resumable``: the folder holds this very dataset, unfinished or not."""

    def __init__(self, folder: str | Path, message: str, resumable: bool = False):
        self.resumable = resumable
        super().__init__(folder, "", message)


# what a dataset.json's keys hold: (key, what, test); ``spp`` None: the spec's
_DESCRIBED = (
    ("n", "a whole number ≥ 1", lambda v: _whole(v) and v >= 1),
    ("seed", "a whole number ≥ 0", lambda v: _whole(v) and v >= 0),
    ("spp", "a whole number ≥ 1 or null", lambda v: v is None or (_whole(v) and v >= 1)),
    ("spec", "a mapping (the spec's ranges)", lambda v: isinstance(v, dict)),
)


def _whole(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def read_description(out: str | Path) -> dict:
    """A dataset's ``dataset.json``, verified: a mirrorsim dataset's, each of its keys of
    the type it holds (a hand-edited ``"n": "8"`` is named as a string, not compared).

    Raises
    ------
    DatasetError
        Naming the file and, where one is wrong, the key, its value and what it holds.
    """
    path = Path(out) / "dataset.json"
    try:
        old = json.loads(read_regular_bytes(path))
    except (OSError, ValueError, RecursionError) as exc:
        raise DatasetError(path, f"not a readable dataset description ({exc})") from None
    if not isinstance(old, dict) or old.get("format", DATASET_FORMAT) != DATASET_FORMAT:
        raise DatasetError(path, "not a mirrorsim dataset's description")
    for key, what, ok in _DESCRIBED:
        if key not in old:
            raise DatasetError(path, f"{key}: missing (not a mirrorsim dataset's description)")
        if not ok(old[key]):
            value = old[key]
            raise DatasetError(path, f"{key}: {value!r} (a {type(value).__name__}) is not "
                               f"{what}")
    return old


# the settings a row comes out of (n aside: it may grow), as dataset.json holds them
_SETTINGS = ("format", "seed", "spp", "spec", "error_model_sha256", "calibrate")


def settings_digest(meta: dict) -> str:
    """The digest of a dataset's settings that each of its row files carries (under
    ``"dataset"``): a sealed row of another dataset of the same seed but other settings
    (spp, spec, error model, self-calibration) was taken as this one's."""
    return checksum(jsonable({k: meta.get(k) for k in _SETTINGS}))[:16]


def dataset_digest(out: Path) -> str:
    """:func:`settings_digest` of the dataset in ``out`` (its ``dataset.json``)."""
    return settings_digest(read_description(out))


def row_document(row: table.DatasetRow, digest: str | None) -> dict:
    """A row file's contents: the row and (where given) the digest of its dataset's
    settings, sealed."""
    return seal({**row.to_json(), **({"dataset": digest} if digest else {})})


def read_row(path: Path, index: int, seed: int, *, digest: str | None = None
             ) -> table.DatasetRow:
    """Scene ``index``'s row file, verified: its checksum, its declared columns, and that
    it is this dataset's (its index and seed, and where ``digest`` is given and the row
    carries one, its settings: rows made before the digest carry none).

    Raises
    ------
    ValueError
        Why it is not trusted.
    """
    try:
        data = unseal(json.loads(read_regular_bytes(path)), path.name)
        made = data.pop("dataset", None)
        if digest is not None and made is not None and made != digest:
            raise ValueError("a row made with other settings (spp, spec, error model or "
                             "self-calibration) than this dataset's")
        row = table.DatasetRow.from_json(data)
        found = (row.index, row.columns.get("seed"))
    except KeyError as exc:
        raise ValueError(f"no {exc} column") from None
    except OSError as exc:
        raise ValueError(f"unreadable ({exc.strerror or exc})") from None
    except (ValueError, TypeError, RecursionError) as exc:
        raise ValueError(str(exc) or type(exc).__name__) from None
    if found != (index, seed):
        raise ValueError(f"the row of scene {found[0]} of seed {found[1]}, not of scene "
                         f"{index} of seed {seed}")
    return row


def scene_files(out: Path, name: str) -> dict[str, str]:
    """The SHA-256 of each file of scene ``name`` in ``out/frames/<name>/`` (its frames,
    truth, capture records, measurements; none where the scene wrote none), for its row."""
    folder = Path(out) / "frames" / name
    if not folder.is_dir():
        return {}
    return {p.name: hashlib.sha256(read_regular_bytes(p)).hexdigest()
            for p in sorted(folder.iterdir()) if p.is_file() and not p.name.startswith(".")}


def files_differ(out: Path, row: table.DatasetRow) -> tuple[list[Path], list[Path]]:
    """Of the files ``row`` records, those missing and those whose bytes differ from its
    SHA-256s."""
    folder = Path(out) / "frames" / row["scene"]
    missing, damaged = [], []
    for name, digest in row.files.items():
        path = folder / name
        try:
            found = hashlib.sha256(read_regular_bytes(path)).hexdigest()
        except FileNotFoundError:
            missing.append(path)
            continue
        except OSError:
            found = ""
        if found != digest:
            damaged.append(path)
    return missing, damaged


def check_scene_files(out: Path, rows: list[table.DatasetRow]) -> None:
    """Every file the rows record, checked against its SHA-256: one damaged or replaced
    (another scene's) is refused in one line naming it; the missing ones (a folder of
    frames deleted to save space) are named in one warning, the table's values standing.

    Raises
    ------
    DatasetError
        Naming the first file whose bytes differ from its row's record.
    """
    missing: list[Path] = []
    for row in rows:
        gone, damaged = files_differ(out, row)
        if damaged:
            raise DatasetError(damaged[0], "its bytes differ from the SHA-256 its row holds "
                               f"(rows/{row['scene']}.json): damaged or replaced since; "
                               "resuming the dataset redoes its scene")
        missing += gone
    if missing:
        shown = ", ".join(p.name for p in missing[:4])
        more = f" and {len(missing) - 4} more" if len(missing) > 4 else ""
        warnings.warn(f"{out}: {len(missing)} of its scenes' files are missing ({shown}{more}): "
                      "the table's values stand; a missing frame's path reads as None",
                      RuntimeWarning, stacklevel=3)


def reject_bad_rows(out: Path, n: int, seed: int) -> None:
    """Move each row file that fails verification to ``rows/rejected/`` (kept, not lost),
    with a warning: its scene is redone."""
    digest = dataset_digest(out)
    for i in range(n):
        path = out / "rows" / f"{scene_name(i)}.json"
        if not path.exists():
            continue
        try:
            row = read_row(path, i, seed, digest=digest)
            gone, damaged = files_differ(out, row)
            if gone or damaged:
                raise ValueError(f"its scene's file {(gone or damaged)[0].name} is "
                                 f"{'missing' if gone else 'damaged or replaced'}")
        except ValueError as exc:
            aside = _aside(out / "rows" / "rejected", path.name)
            path.replace(aside)
            warnings.warn(f"{str(path)!r} not trusted ({exc}); moved to {str(aside)!r}, "
                          "its scene is redone", RuntimeWarning, stacklevel=2)


def _aside(folder: Path, name: str) -> Path:
    """A new path for a rejected file in ``folder``: a second rejection of the same
    scene keeps the first."""
    if folder.exists() and not folder.is_dir():
        raise DatasetError(folder, "is not a folder: this is not a dataset's layout")
    folder.mkdir(exist_ok=True)
    aside, k = folder / name, 1
    while aside.exists():
        aside, k = folder / f"{Path(name).stem}.{k}.json", k + 1
    return aside


def collect_rows(out: Path, n: int, meta: dict | None = None) -> list[table.DatasetRow]:
    """The finished rows of scenes 0..n-1, in index order, each verified against the
    dataset's settings (``meta``: its description, read from ``dataset.json`` when not
    given: a caller that holds it does not read the file again)."""
    out = Path(out)
    meta = read_description(out) if meta is None else meta
    seed, digest = meta["seed"], settings_digest(meta)
    rows = []
    for i in range(n):
        p = out / "rows" / f"{scene_name(i)}.json"
        if p.exists():
            try:
                rows.append(read_row(p, i, seed, digest=digest))
            except ValueError as exc:
                raise DatasetError(p, f"not a row of this dataset ({exc}); resuming the "
                                   "dataset redoes it") from None
    return rows
