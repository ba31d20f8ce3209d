"""A dataset's folder on disk: claiming it, its row files (sealed and verified), its
Parquet table (sealed and verified); its card is :mod:`mirrorsim.formats.dataset_card`.
The layout is described in :mod:`mirrorsim.pipelines.dataset`.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mirrorsim.errors import InputError
from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.cache import checksum, seal, unseal
from mirrorsim.formats.files import (
    atomic_path,
    jsonable,
    read_regular_bytes,
    write_json,
)
from solver.selfcal import priors_text

if TYPE_CHECKING:
    import pandas as pd

DATASET_FORMAT = "mirrorsim-dataset"
TABLE_SEAL = "mirrorsim.sha256"  # the Parquet schema's metadata key of its checksum


def scene_name(i: int) -> str:
    """File name of scene i."""
    return f"scene{i:06d}"



class DatasetError(InputError):
    """A run that cannot start (e.g. a folder holding another dataset): bad input;
    ``resumable``: the folder holds this very dataset, unfinished or not."""

    def __init__(self, folder: str | Path, message: str, resumable: bool = False):
        self.resumable = resumable
        super().__init__(folder, "", message)



def make_folders(out: Path, meta: dict) -> None:
    """The dataset's folders, and its description (written once: a resume keeps it)."""
    for sub in ("scenes", "frames", "rows"):
        if (out / sub).exists() and not (out / sub).is_dir():
            raise DatasetError(out / sub, "is not a folder: this is not a dataset's layout")
        (out / sub).mkdir(parents=True, exist_ok=True)
    meta_path = out / "dataset.json"
    # a resume that extends the dataset (claim_folder checked the rest) records its n
    if not meta_path.exists() or json.loads(meta_path.read_text()).get("n") != meta["n"]:
        write_json(meta_path, meta)



# held (flock) by the run writing a dataset, for as long as it runs: a second run on the
# same folder (a fresh one, or a --resume) is refused rather than computing the same
# scenes and writing the table and card over the first's.  The kernel drops it when the
# run ends, however it ends (kill -9 too): no stale lock to remove by hand
LOCK_NAME = ".mirrorsim-lock"


@contextlib.contextmanager
def writing(out: Path, meta: dict, resume: bool) -> Iterator[None]:
    """Claim ``out`` (:func:`claim_folder`) and hold its lock while the block runs."""
    claim_folder(out, meta, resume)  # before anything is written into it
    out.mkdir(parents=True, exist_ok=True)
    with open(out / LOCK_NAME, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise DatasetError(out, "another run is writing this dataset now: wait for it "
                               "to end (then resume it), or choose another folder") from None
        claim_folder(out, meta, resume)  # again, now alone: another run may have begun it
        if resume:  # its rows, verified only now that no other run writes them
            reject_bad_rows(out, meta["n"], meta["seed"])
        yield


def claim_folder(out: Path, meta: dict, resume: bool) -> None:
    """``out`` must be new or empty, or hold this command's dataset (with --resume)."""
    if out.exists() and not out.is_dir():
        raise DatasetError(out, "is a file, not a new or empty folder")
    meta_path = out / "dataset.json"
    if not meta_path.exists():
        others = sorted(p.name for p in out.iterdir() if p.name != LOCK_NAME) \
            if out.is_dir() else []
        if others:
            shown = ", ".join(others[:3])
            raise DatasetError(out, f"holds other files ({shown}, …), not a dataset: use a new "
                               "or empty folder")
        if resume:
            raise DatasetError(out, "there is no dataset here to resume")
        return
    old = read_description(out)
    if not resume:
        raise DatasetError(out, "already holds a dataset: resume it, or choose another "
                           "folder", resumable=True)
    if old.get("error_model_sha256") != meta.get("error_model_sha256"):
        raise DatasetError(out, "was made with another error model (its rows' σ's would "
                           "mix two models): resume it with the model it was made with, or "
                           "choose another folder")
    if old.get("calibrate") != meta.get("calibrate"):
        raise DatasetError(out, f"was made with other self-calibration settings "
                           f"({_calibration_words(old.get('calibrate'))}): resume it with "
                           "the same nuisances, beacon σ and priors, or choose another folder")
    # n may grow: scene i is drawn from (seed, i) alone, so the added scenes are the
    # ones a dataset of the larger n would have had
    differ = [f"{k} {old[k]} (now {meta[k]})" for k in ("seed", "spp") if old[k] != meta[k]]
    differ += [f"spec {d}" for d in _differences(old["spec"], meta["spec"])]
    if differ:
        raise DatasetError(out, f"holds a dataset made with other settings: "
                           f"{'; '.join(differ)}: resume it with the same ones, or choose "
                           "another folder")
    if meta["n"] < old["n"]:
        raise DatasetError(out, f"holds {old['n']} scenes: resume it with n ≥ {old['n']} "
                           f"(more scenes extend it), not {meta['n']}")


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


def _calibration_words(cal: Any) -> str:
    """A dataset's self-calibration settings in words (``none`` where it had none)."""
    if not isinstance(cal, dict) or not cal:
        return "none"
    try:
        return "; ".join(part for part in (
            f"nuisances {', '.join(cal['nuisances'])}" if cal.get("nuisances") else "",
            f"beacon σ {cal['position_sigma']:g} cm" if cal.get("position_sigma") else "",
            f"priors {priors_text(cal['priors'])}" if cal.get("priors") else "") if part) \
            or "none"
    except (TypeError, ValueError, KeyError):  # a hand-edited record: shown as it is
        return str(cal)


def _differences(old: Any, new: Any, key: str = "", most: int = 3) -> list[str]:
    """Where two specs differ, as ``key.path old (now new)``, at most ``most`` of them
    (a spec's ``beacon.count`` is where ``--beacons`` goes, for one)."""
    if isinstance(old, dict) and isinstance(new, dict):
        out: list[str] = []
        for k in sorted(set(old) | set(new), key=str):
            path = f"{key}.{k}" if key else str(k)
            if k not in old or k not in new:
                out.append(f"{path} {old.get(k, 'absent')} (now {new.get(k, 'absent')})")
            else:
                out += _differences(old[k], new[k], path, most)
        return out[:most]
    return [] if old == new else [f"{key} {old} (now {new})"]


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


def read_row(path: Path, index: int, seed: int, digest: str | None = None
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
            row = read_row(path, i, seed, digest)
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


def collect_rows(out: Path, n: int, seed: int | None = None) -> list[table.DatasetRow]:
    """The finished rows of scenes 0..n-1, in index order, each verified (``seed``: the
    dataset's, read from its ``dataset.json`` when not given)."""
    out = Path(out)
    if seed is None:
        seed = read_description(out)["seed"]
    digest = dataset_digest(out)
    rows = []
    for i in range(n):
        p = out / "rows" / f"{scene_name(i)}.json"
        if p.exists():
            try:
                rows.append(read_row(p, i, seed, digest))
            except ValueError as exc:
                raise DatasetError(p, f"not a row of this dataset ({exc}); resuming the "
                                   "dataset redoes it") from None
    return rows


def _arrow_of(rows: list[table.DatasetRow], only: set[str] | None = None):
    """The rows as an Arrow table (unsealed), and the checksum of its contents: what
    :func:`write_table` writes, and (``only`` a table's columns: an older layout's table
    lacks the columns its rows are read with since) what :func:`read_table` holds a
    table to."""
    import pyarrow as pa

    cols: dict[str, list] = {}
    keys = sorted({k for r in rows for k in r.columns if only is None or k in only},
                  key=lambda k: (k not in ("index", "scene", "error"), k))
    for k in keys:
        cols[k] = [r.columns.get(k) for r in rows]
    arrow = pa.table(cols) if rows else pa.table({"index": pa.array([], pa.int64())})
    return arrow, checksum(jsonable(arrow.to_pydict()))


def write_table(out: Path, rows: list[table.DatasetRow]) -> Path:
    """All rows as one Parquet table (pyarrow), written atomically."""
    import pyarrow.parquet as pq

    arrow, digest = _arrow_of(rows)
    # sealed like a row file: a table edited or written by another tool is not fitted
    arrow = arrow.replace_schema_metadata({TABLE_SEAL: digest})
    path = Path(out) / "dataset.parquet"
    with atomic_path(path) as tmp:
        pq.write_table(arrow, tmp)
    return path


def read_table(folder: str | Path) -> dict[str, list]:
    """A dataset's table as columns (name → list), verified: a readable Parquet file
    whose checksum matches its contents, with rows, at least one of them a success, and
    every declared column.

    Raises
    ------
    DatasetError
        Saying which of these fails.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(folder) / "dataset.parquet"
    if not path.exists():
        raise DatasetError(path, "no such file (make it with `mirrorsim dataset`)")
    if not path.is_file():
        raise DatasetError(path, "not a file")
    try:
        arrow = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DatasetError(path, f"not a readable Parquet table ({why})") from None
    cols = arrow.to_pydict()
    seal = (arrow.schema.metadata or {}).get(TABLE_SEAL.encode())
    if seal is None:
        raise DatasetError(path, "carries no checksum (written by an older mirrorsim or "
                           "another tool; resuming the dataset redoes its unsealed rows and "
                           "writes it again)")
    if seal.decode() != checksum(jsonable(cols)):
        raise DatasetError(path, "its checksum does not match its contents (edited, or not "
                           "written by `mirrorsim dataset`, which writes it again from the "
                           "verified rows when the dataset is resumed)")
    n = len(cols.get("index", []))
    if n == 0:
        raise DatasetError(path, "holds no rows")
    failed = int(n - table.usable_rows(cols).sum())
    if failed == n:
        raise DatasetError(path, f"all {n} rows failed (their `error` column says why)")
    described = read_description(folder)
    n_scenes, seed = described["n"], described["seed"]
    # the table is its verified rows, value for value: a row file damaged since, or
    # missing, and another dataset's table of the same size (its own seal intact) are
    # found here
    rows = collect_rows(folder, n_scenes, seed)
    if [r.index for r in rows] != cols["index"] or _arrow_of(rows, set(cols))[1] != \
            seal.decode():
        raise DatasetError(path, "its rows differ from the row files in rows/ (another "
                           "dataset's table, or one written before a row changed; resuming "
                           "the dataset writes the table again)")
    check_scene_files(folder, rows)
    schemas = cols.get("schema") or [None]
    if all(s in (*table.OLDER_SCHEMAS, table.SCHEMA) for s in schemas):
        # a table of older layouts (one resumed by a later version mixes them): each row
        # takes the values its scene had for the columns added since its layout (one
        # beacon, plain; no priors); a column its own layout had stays missing
        older = [table.older_values(s) for s in schemas]
        for c in set().union(*older) - set(cols):
            if all(c in o for o in older):
                cols[c] = [None if e else o[c] for e, o in zip(cols["error"], older,
                                                                strict=True)]
    missing = sorted(set(table.NAMES) - set(cols))
    if missing:
        raise DatasetError(path, f"missing columns {', '.join(missing[:4])}"
                           + (f" and {len(missing) - 4} more" if len(missing) > 4 else ""))
    return cols


def load_dataset(folder: str | Path) -> pd.DataFrame:
    """A dataset's table, verified (:func:`read_table`), as a pandas DataFrame with each
    scene's frame, scene file and measurements file beside its columns (``frame``,
    ``scene_file``, ``measurements_file``: paths; empty for a failed scene, None for a
    file missing from a scene that did not fail, which one warning names).  Every file a
    row records is checked against its SHA-256 (a damaged one is refused).  The same
    Parquet file loads without mirrorsim (``pandas.read_parquet``), unverified."""
    import pandas as pd

    folder = Path(folder)
    df = pd.DataFrame(read_table(folder))
    frames = folder / "frames"

    def path_of(name: str, suffix: str, failed: bool) -> str | None:
        p = frames / name / f"{name}{suffix}"
        return "" if failed else str(p) if p.exists() else None

    failed = df["error"].astype(bool)
    # a scene of several beacons has a frame per beacon (<scene>_b<k>): the first's
    df["frame"] = ["" if f else next(filter(None, (path_of(n, s, f) for s in (
        ".png", ".jpg", "_b0.png", "_b0.jpg"))), None)
        for n, f in zip(df["scene"], failed, strict=True)]
    df["scene_file"] = [str(folder / "scenes" / f"{n}.yaml") for n in df["scene"]]
    df["measurements_file"] = [path_of(n, ".measurements.json", f)
                               for n, f in zip(df["scene"], failed, strict=True)]
    return df
