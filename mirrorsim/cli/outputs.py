"""A run's outputs, checked before any work is done and claimed when it starts: the
output folder and files (writable, not an input, not each other, not inside the run's
own folder), stdout given once."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from mirrorsim.errors import BadArgument, InputError, OutputError, write_error
from mirrorsim.formats.files import (
    check_inputs_outside,
    check_output_dir,
    check_output_file,
    claim_output_folder,
    claim_run_folder,
    default_out,
)

# a dataset folder's own files: a run that reads the dataset writes over none of them
DATASET_FILES = ("dataset.json", "dataset.parquet", "README.md")

if TYPE_CHECKING:  # `mirrorsim --help` imports none of the scene model
    from mirrorsim.scene.model import Scene


DATASET_FOLDERS = ("rows", "scenes", "frames")


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work is done (exit 2): unwritable output paths, an output
    folder holding files mirrorsim did not write, an output file that is one of the
    run's own inputs, that another output also names, or that lies in the run's output
    folder (whose names the run gives)."""
    checking = ["--out"]  # the flag being checked, for an OSError from any check below
    try:
        _check_outputs(args, checking)
    except OSError as exc:  # a name too long, a loop of links, an unreadable folder
        raise write_error(exc.filename or "", exc, checking[0]) from None


def stdout_output(args: argparse.Namespace) -> str | None:
    """The flag of the one output given as ``-`` (stdout), or None; two are refused, as
    their documents would run together."""
    dashes = [flag for dest, flag, kind in getattr(args, "outputs", None) or []
              if kind == "file" and str(getattr(args, dest, None)) == "-"]
    if len(dashes) > 1:
        raise BadArgument(dashes[1], f"- (stdout), which {dashes[0]} writes to already: "
                          "give one of them a file")
    return dashes[0] if dashes else None


def _check_outputs(args: argparse.Namespace, checking: list[str]) -> None:
    # a missing input is bad input whatever the outputs' state (a full disk found by the
    # outputs' probe below would otherwise make a typo in a path a failed run)
    for name, source in _file_inputs(args):
        if source is not None and str(source) != "-" and not Path(source).exists():
            raise InputError(source, "", f"{name}: no such file")
    files: dict[Path, str] = {}
    for dest, flag, kind in getattr(args, "outputs", None) or []:
        value = getattr(args, dest)
        checking[0] = flag
        if kind in ("dir", "dataset"):
            if value is None and getattr(args, "default_out", False):
                check_output_dir(default_out("x").parent, flag, ours=False)
            check_output_dir(value, flag, ours=kind == "dir")
            if kind == "dir" and value is not None:
                check_inputs_outside(value, _file_inputs(args), flag)
            continue
        check_output_file(value, flag)
        _check_not_an_input(args, value, flag)
        allowed = (getattr(args, "suffixes", None) or {}).get(dest)
        if value is not None and allowed and Path(value).suffix.lower() not in allowed:
            raise OutputError(value, f"{flag}: the format goes by the file's suffix: use "
                              f"{', '.join(allowed)}")
        if value is not None and str(value) != "-":
            target = Path(value).resolve()
            if target in files:
                raise OutputError(value, f"{flag}: {files[target]} writes this file too")
            files[target] = flag
    if getattr(args, "out", None) is not None and files:
        _check_files_outside(args, Path(args.out))


def _check_files_outside(args: argparse.Namespace, folder: Path) -> None:
    """No file output of the run inside ``folder``, the run's output folder."""
    if not any(kind in ("dir", "dataset")
               for _d, _f, kind in getattr(args, "outputs", None) or []):
        return
    folder = folder.resolve()
    for dest, flag, kind in getattr(args, "outputs", None) or []:
        value = getattr(args, dest)
        if kind == "file" and value is not None and str(value) != "-" and \
                Path(value).resolve().is_relative_to(folder):
            raise OutputError(value, f"{flag}: inside the run's output folder {str(folder)!r}, "
                              "whose file names the run gives: put it elsewhere")


def _file_inputs(args: argparse.Namespace) -> list[tuple[str, object]]:
    """The run's input files as (name shown, path) pairs."""
    return [(name, getattr(args, dest, None))
            for dest, name, kind in getattr(args, "inputs", None) or [] if kind == "file"]


def out_folder(args: argparse.Namespace, scene: Scene, sub: str = "") -> Path:
    """The run's output folder, claimed with its inputs kept out (:func:`claim_run_folder`):
    ``--out``, else ``renders/<name>/<sub>``; no file output of the run may lie inside it."""
    out = args.out if args.out is not None else default_out(scene.name) / sub
    _check_files_outside(args, out)
    return claim_run_folder(out, "--out", _file_inputs(args))


def out_file(args: argparse.Namespace, scene: Scene, name: str) -> Path:
    """A file output: ``--out``, else ``name`` in the scene's claimed folder
    ``renders/<name>/``."""
    if args.out is not None:
        return args.out
    return claim_output_folder(default_out(scene.name), "--out") / name


def _check_not_an_input(args: argparse.Namespace, value, flag: str) -> None:
    if value is None or str(value) == "-":
        return
    target = Path(value).resolve()
    for dest, name, kind in getattr(args, "inputs", None) or []:
        source = getattr(args, dest, None)
        if source is None:
            continue
        source = Path(source).resolve()
        if kind == "dataset":
            read = target.parent == source and target.name in DATASET_FILES or any(
                target.is_relative_to(source / sub) for sub in DATASET_FOLDERS)
        else:
            read = target == source
        if read:
            raise OutputError(value, f"{flag}: this run reads it ({name}); writing there "
                              "would lose it: choose another file")
