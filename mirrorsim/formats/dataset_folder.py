"""A dataset's folder on disk: claiming it and its lock, its Parquet table (sealed and
verified against its rows) and its loader; its row files and description are
:mod:`mirrorsim.formats.dataset_rows`', its card :mod:`mirrorsim.formats.dataset_card`.
The layout is described in :mod:`mirrorsim.pipelines.dataset`.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.cache import checksum
from mirrorsim.formats.dataset_rows import (  # noqa: F401 (the folder's names, re-exported)
    DATASET_FORMAT,
    DatasetError,
    check_scene_files,
    collect_rows,
    dataset_digest,
    files_differ,
    read_description,
    read_row,
    reject_bad_rows,
    row_document,
    scene_files,
    scene_name,
    settings_digest,
)
from mirrorsim.formats.files import FRAME_SUFFIXES, atomic_path, jsonable, write_json
from solver.selfcal import priors_text

if TYPE_CHECKING:
    import pandas as pd

TABLE_SEAL = "mirrorsim.sha256"  # the Parquet schema's metadata key of its checksum


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
    return read_verified(folder)[0]


def read_verified(folder: str | Path) -> tuple[dict[str, list], list[table.DatasetRow]]:
    """A dataset's table as columns (:func:`read_table`) and the rows it was checked
    against, each verified (raises as :func:`read_table` does)."""
    path = Path(folder) / "dataset.parquet"
    arrow = _parquet(path)
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
    n_scenes = described["n"]
    # the table is its verified rows, value for value: a row file damaged since, or
    # missing, and another dataset's table of the same size (its own seal intact) are
    # found here
    rows = collect_rows(folder, n_scenes, described)
    if [r.index for r in rows] != cols["index"] or _arrow_of(rows, set(cols))[1] != \
            seal.decode():
        raise DatasetError(path, "its rows differ from the row files in rows/ (another "
                           "dataset's table, or one written before a row changed; resuming "
                           "the dataset writes the table again)")
    check_scene_files(folder, rows)
    _migrated(cols)
    missing = sorted(set(table.NAMES) - set(cols))
    if missing:
        raise DatasetError(path, f"missing columns {', '.join(missing[:4])}"
                           + (f" and {len(missing) - 4} more" if len(missing) > 4 else ""))
    return cols, rows


def _parquet(path: Path) -> Any:
    """The Parquet table at ``path``, or a one-line :class:`DatasetError`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not path.exists():
        raise DatasetError(path, "no such file (make it with `mirrorsim dataset`)")
    if not path.is_file():
        raise DatasetError(path, "not a file")
    try:
        arrow = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise DatasetError(path, f"not a readable Parquet table ({why})") from None
    return arrow


def _migrated(cols: dict[str, list]) -> None:
    """A table of older layouts (one resumed by a later version mixes them) given, in
    place, the values its rows' scenes had for the columns added since their layout (one
    beacon, plain; no priors); a column its own layout had stays missing."""
    schemas = cols.get("schema") or [None]
    if all(s in (*table.OLDER_SCHEMAS, table.SCHEMA) for s in schemas):
        beacons = cols.get("beacons") or [1] * len(schemas)
        older = [table.older_values(s, int(b or 1)) for s, b in zip(schemas, beacons,
                                                                     strict=True)]
        for c in set().union(*older) - set(cols):
            # a further beacon's column: null where a row has fewer beacons
            if c not in table.NAMES or all(c in o for o in older):
                cols[c] = [None if e else o.get(c) for e, o in zip(cols["error"], older,
                                                                    strict=True)]


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
    suffixes = (*FRAME_SUFFIXES, *(f"_b0{s}" for s in FRAME_SUFFIXES))
    df["frame"] = ["" if f else next(filter(None, (path_of(n, s, f) for s in suffixes)), None)
        for n, f in zip(df["scene"], failed, strict=True)]
    df["scene_file"] = [str(folder / "scenes" / f"{n}.yaml") for n in df["scene"]]
    df["measurements_file"] = [path_of(n, ".measurements.json", f)
                               for n, f in zip(df["scene"], failed, strict=True)]
    return df
