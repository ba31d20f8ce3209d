"""Writing files safely: atomic replacement and strict JSON.

Every output appears atomically: it is written under a temporary name beside its
destination and renamed once complete, so a reader never sees half a file and an
interrupted run leaves the old file (or none).  JSON is strict: NaN and infinities
become ``null``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import re
import stat
import sys
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from mirrorsim.errors import OutputError, write_error

if TYPE_CHECKING:
    from matplotlib.figure import Figure

if TYPE_CHECKING:
    import numpy as np

PROBE_BYTES = 64 * 1024  # written and synced where outputs will go: a full disk says so
# the mark of a folder mirrorsim made (or found empty) for its outputs: it writes the
# files it names itself only into such a folder, never among a user's other files
OUTPUT_MARK = ".mirrorsim"


def default_out(scene_name: str) -> Path:
    """Where a scene's files go unless told otherwise: ``renders/<name>/``."""
    return Path("renders") / scene_name


def jsonable(value: Any, nonfinite_as_null: bool = True) -> Any:
    """``value`` with numpy scalars and arrays made plain, and (``nonfinite_as_null``)
    NaN/±inf made ``None``; without it they stay, for a reader that refuses them by
    name (a scene's edits)."""
    import numpy as np  # here, not at the top: the command line's start-up imports this
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, nonfinite_as_null) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v, nonfinite_as_null) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), nonfinite_as_null)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        v = float(value)
        return v if math.isfinite(v) or not nonfinite_as_null else None
    if isinstance(value, Path):
        return str(value)
    return value


def dumps(data: Any, indent: int | None = 2) -> str:
    """Strict JSON text of ``data`` (see :func:`jsonable`), with a final newline."""
    return json.dumps(jsonable(data), indent=indent, allow_nan=False) + "\n"


def read_regular_bytes(path: str | Path) -> bytes:
    """The bytes of a file mirrorsim reads back (a cache entry, a frame, a row), which
    must be a regular file: a FIFO put in its place made the read wait for a writer for
    ever.  OSError for anything else, as for an unreadable file."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO's open does not wait either
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file (a folder, FIFO, device or "
                          "socket)", str(path))
        with os.fdopen(fd, "rb") as f:
            fd = -1  # the file object closes it
            return f.read()
    finally:
        if fd >= 0:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path``; renamed onto it when the block ends cleanly.

    The temporary name keeps the destination's suffix, so writers that choose a format
    by suffix (matplotlib, OpenCV, Mitsuba) write the right one.  A failing write (a full
    disk, no permission) leaves nothing behind and raises :class:`OutputError`.
    """
    path = Path(path)
    _sweep_stale(path)
    tmp = path.with_name(f".{path.stem}{_TMP_MARK}{os.getpid()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        raise write_error(path, exc, "cannot write") from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)


_SWEPT: set[Path] = set()  # folders swept by this process: once each, not on every write
# in every temporary file's name, so that the sweep below removes only files mirrorsim
# made (".plan.tmp2024.yaml" was a user's own file, and was swept away)
_TMP_MARK = ".mirrorsim-tmp"


def _sweep_stale(path: Path) -> None:
    """Remove the temporary files left in ``path``'s folder by earlier writes whose
    process is gone (a run killed with SIGKILL between writing and renaming); once per
    folder and process, since listing a folder of a million rows costs."""
    folder = path.parent.absolute()
    if folder in _SWEPT:
        return
    _SWEPT.add(folder)
    try:
        found = [p for p in folder.iterdir() if p.name.startswith(".") and _TMP_MARK in p.name]
    except OSError:
        return
    for tmp in found:
        m = re.fullmatch(r"\..*" + re.escape(_TMP_MARK) + r"(\d+)(\.[^.]*)?", tmp.name)
        if m and int(m[1]) != os.getpid() and not _alive(int(m[1])):
            with contextlib.suppress(OSError):
                tmp.unlink()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def check_output_file(path: str | Path | None, option: str) -> None:
    """Refuse (OutputError, exit 2) a file output that cannot be written, before any work:
    a missing parent folder, a folder in its place, no permission, a full disk."""
    if path is None or str(path) == "-":
        return
    path = Path(path)
    _not_a_broken_link(path, option)
    if path.is_dir():
        raise OutputError(path, f"{option}: is a folder; a file is wanted here")
    if path.exists() and not path.is_file():
        raise OutputError(path, f"{option}: not a regular file (a device, pipe or socket)")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(path, f"{option}: no such folder {str(parent)!r}")
    _probe(parent, path, option)


def check_output_dir(path: str | Path | None, option: str, ours: bool = True) -> None:
    """Refuse a folder output that cannot be made or written (its parent must exist), or
    (``ours``) one that holds files mirrorsim did not write (see
    :func:`claim_output_folder`)."""
    if path is None:
        return
    path = Path(path)
    _not_a_broken_link(path, option)
    if ours and path.is_dir():
        _check_ours(path, option)
    if path.exists() and not path.is_dir():
        raise OutputError(path, f"{option}: is a file; a folder is wanted here")
    if path.is_dir():
        _probe(path, path, option)
        return
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise OutputError(path, f"{option}: no such folder {str(parent)!r} (make it first)")
    _probe(parent, path, option)


def claim_output_folder(path: str | Path, option: str) -> Path:
    """``path`` as mirrorsim's output folder: made (with each missing parent) and marked,
    or taken if empty or already marked.

    Raises
    ------
    OutputError
        If it holds files mirrorsim did not write, or cannot be made.
    """
    path = Path(path)
    _not_a_broken_link(path, option)
    made = []
    p = path
    while not p.exists() and p != p.parent:
        made.append(p)
        p = p.parent
    try:
        for d in reversed(made):
            try:
                d.mkdir()
            except FileExistsError:  # another run made it meanwhile: its, then ours
                continue
            (d / OUTPUT_MARK).touch()
        if not made or not (path / OUTPUT_MARK).exists():
            _check_ours(path, option)
            (path / OUTPUT_MARK).touch()
    except OSError as exc:
        raise write_error(path, exc, f"{option}: cannot make or write the folder") from None
    return path


def check_inputs_outside(folder: str | Path, inputs: Iterable[tuple[str, str | Path | None]],
                         option: str) -> None:
    """Refuse an input file inside ``folder``, a run's output folder, whose file names
    the run gives (one may be the input's).  ``inputs``: (what it is, its path) pairs,
    a path None or ``-`` skipped."""
    folder = Path(folder).resolve()
    for name, source in inputs:
        # a scene made in memory has a source that names no file ("<scene>")
        if source is not None and str(source) not in ("", "-") and Path(source).is_file() \
                and Path(source).resolve().is_relative_to(folder):
            raise OutputError(folder, f"{option}: holds this run's input {name} "
                              f"({str(source)!r}), and the run names the files it writes "
                              "there: move the input out, or choose another folder")


def claim_run_folder(path: str | Path, option: str,
                     inputs: Iterable[tuple[str, str | Path | None]] = ()) -> Path:
    """A library run's output folder: :func:`claim_output_folder`, after refusing any of
    ``inputs`` inside it (:func:`check_inputs_outside`), so that a script calling the
    library keeps the command line's promises (no user's folder written into, no input
    written over)."""
    check_inputs_outside(path, inputs, option)
    return claim_output_folder(path, option)


def _check_ours(folder: Path, option: str) -> None:
    if (folder / OUTPUT_MARK).exists():
        return
    names = sorted(p.name for p in folder.iterdir())
    if names:
        shown = ", ".join(repr(n) for n in names[:3]) + (", …" if len(names) > 3 else "")
        raise OutputError(folder, f"{option}: holds files mirrorsim did not write ({shown}); "
                          "choose a new or empty folder")


def _not_a_broken_link(path: Path, option: str) -> None:
    if path.is_symlink() and not path.exists():
        raise OutputError(path, f"{option}: a symbolic link to nothing (dangling or looping)")


def _probe(folder: Path, path: Path, option: str) -> None:
    """Create, fill and remove a small file in ``folder``: the only sure test that it
    can be written (root ignores permission bits; a full disk fails only on writing)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".mirrorsim-probe") as f:
            f.write(b"\0" * PROBE_BYTES)
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise write_error(path, exc, f"{option}: cannot write in {str(folder)!r}") from None


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


# a frame's file: a lossless PNG, or a JPEG where the bench stores JPEG
FRAME_SUFFIXES = (".png", ".jpg")


def frame_suffix(jpeg_quality: int | None) -> str:
    """The suffix of a frame stored at ``jpeg_quality`` (None: lossless)."""
    return FRAME_SUFFIXES[0] if jpeg_quality is None else FRAME_SUFFIXES[1]


def encode_png(pixels: np.ndarray) -> bytes:
    """8-bit pixels (H, W, 3) RGB or (H, W) grey as PNG bytes.

    zlib level 1 and no row filter: on a rendered frame's sampling noise the filters
    cost time and save no bytes (benchmarks/pieces.py's PNG piece; docs/performance.md).
    """
    import cv2

    params = [cv2.IMWRITE_PNG_COMPRESSION, 1]
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):  # OpenCV ≥ 4.12: older ones filter adaptively
        params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    return _encode(pixels, ".png", params)


def encode_jpeg(pixels: np.ndarray, quality: int) -> bytes:
    """8-bit RGB pixels as JPEG bytes of ``quality`` (1–100; OpenCV's libjpeg, 4:2:0
    chroma subsampling as cameras store them)."""
    import cv2

    return _encode(pixels, ".jpg", [cv2.IMWRITE_JPEG_QUALITY, int(quality)])


def decode_image(data: bytes) -> np.ndarray | None:
    """8-bit RGB pixels of PNG or JPEG bytes (None where they cannot be decoded), without
    OpenCV's own messages on stderr."""
    import cv2
    import numpy as np

    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    finally:
        cv2.utils.logging.setLogLevel(level)
    return None if bgr is None else bgr[..., ::-1]


def _encode(pixels: np.ndarray, ext: str, params: list[int]) -> bytes:
    import cv2
    import numpy as np

    px = np.ascontiguousarray(pixels[..., ::-1] if pixels.ndim == 3 else pixels)
    ok, buf = cv2.imencode(ext, px, params)
    if not ok:
        raise ValueError(f"cannot encode an image of shape {pixels.shape} as {ext}")
    return buf.tobytes()


def write_png(path: str | Path, pixels: np.ndarray) -> Path:
    """Write 8-bit pixels (RGB or grey) as a PNG atomically."""
    data = encode_png(pixels)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def save_figure(fig: Figure, path: str | Path, dpi: int = 110) -> Path:
    """Write a matplotlib figure as a PNG atomically (tight layout), and close it."""
    import matplotlib.pyplot as plt

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(out) as tmp:
            # tight layout rather than bbox_inches="tight": one drawing instead of two
            fig.set_layout_engine("tight")
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
    return out


def write_json(path: str | Path, data: Any) -> Path:
    """Write strict JSON atomically."""
    return write_text(path, dumps(data))


def emit_json(dest: str | Path | None, data: Any, stdout: TextIO | None = None) -> None:
    """Write strict JSON to a file, to stdout (or the ``stdout`` given) for ``"-"``, or
    nowhere for None."""
    if dest is None:
        return
    if str(dest) == "-":
        (stdout or sys.stdout).write(dumps(data) + "\n")
    else:
        write_json(dest, data)
