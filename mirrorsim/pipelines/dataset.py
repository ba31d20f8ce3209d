"""Datasets for error modelling: many random scenes rendered, detected, solved and scored.

Layout of a dataset folder::

    DIR/scenes/<name>.yaml    each scene as a normal scene file (rerun one alone with
                              `mirrorsim evaluate`)
    DIR/frames/<name>/…       its frame, capture record and ground truth (with --keep
                              ids, annotated: its id labels, the annotated frame)
    DIR/rows/<name>.json      its finished row (written last, atomically: a row file
                              exists only for a complete scene), sealed with the
                              checksum of its contents and the digest of the
                              dataset's settings; on --resume a row that fails
                              verification is moved to rows/rejected/ and redone
    DIR/dataset.parquet       all rows, one per scene, in index order
    DIR/README.md             the dataset card
    DIR/dataset.json          how it was made (seed, n, spec, spp): --resume checks it
    DIR/.mirrorsim-lock       locked by the run writing the dataset (a second is refused)

Scene i is drawn from ``SeedSequence(seed, spawn_key=(i,))`` (the same as
``SeedSequence(seed).spawn(n)[i]``) and rendered with seed i, so a row depends on
(seed, i) alone: the same seed gives the same rows whatever the number of workers or
interruptions.  A scene that fails for its own reason (no valid draw, nothing detected,
unsolvable) is a row with ``error``; one that fails for a reason outside it (an
interrupt, a dead worker, memory, disk) leaves no row and is redone on ``--resume``.
Work runs in worker processes (:mod:`mirrorsim.pipelines.workers`) or on a Dask cluster.
"""

from __future__ import annotations

import hashlib
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from mirrorsim.errors import BadParameter, DetectionError, InputError, SolverError
from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.dataset_card import write_card
from mirrorsim.formats.dataset_folder import (
    DATASET_FORMAT,
    collect_rows,
    make_folders,
    row_document,
    scene_files,
    scene_name,
    settings_digest,
    write_table,
    writing,
)
from mirrorsim.formats.dataset_rows import DatasetError
from mirrorsim.formats.error_model import ErrorModel
from mirrorsim.formats.error_model_file import default_error_model, load_error_model
from mirrorsim.formats.files import dumps, write_json, write_text
from mirrorsim.pipelines.dataset_exports import dataset_frames as frames_in_rows
from mirrorsim.pipelines.dataset_exports import export_rows
from mirrorsim.pipelines.dataset_row import row_of, row_of3
from mirrorsim.pipelines.random_scenes import DatasetSpec, NoValidScene
from mirrorsim.pipelines.workers import run_dask, run_local, usable_cores
from mirrorsim.progress import progress_bar
from solver.selfcal import PLAIN, SelfCalibration, check_nuisances, check_planar

# where the scenes run: warm local worker processes, or a Dask cluster
EXECUTORS = ("local", "dask")
# a worker retires past this resident memory; measured on llvm_ad_rgb, a warm worker
# holds ~500 MiB after its first full-size scene and no more after 30 (docs/results.md,
# "Datasets and the error model"), so this only stops a leak that another Mitsuba might bring
MAX_WORKER_RSS_MB = 3072
MAX_SCENES = 1_000_000  # a documented bound on --n
# a documented bound on --workers: more local processes than any machine's cores is a
# slip (the run caps them to the machine's anyway), and a Dask cluster sizes itself
MAX_WORKERS = 1024
# failures that belong to the scene (recorded as its row); all else is redone on resume
SCENE_FAILURES = (InputError, DetectionError, SolverError, NoValidScene)


@dataclass(frozen=True)
class SceneResult:
    """What became of scene ``index``: its row (a failure of the scene itself recorded in
    it, ``error``), or, for a failure from outside the scene, no row and ``retry`` why
    (a resumed run redoes it)."""

    index: int
    row: table.DatasetRow | None
    retry: str = ""


def process_one(i: int, seed: int, spec: DatasetSpec, *, out: str, spp: int | None,
                variant: str, keep: tuple[str, ...] = (),
                error_model: ErrorModel | None = None,
                calibration: SelfCalibration = PLAIN, digest: str | None = None
                ) -> SceneResult:
    """Draw, render, detect, solve and score scene i; write its files, the measurements
    the solver saw (``frames/<scene>/<scene>.measurements.json``, for ``solve``) and its
    row (with ``digest``, its dataset's
    :func:`~mirrorsim.formats.dataset_folder.settings_digest`, where given).
    ``calibration``: self-calibration, as
    :func:`~mirrorsim.pipelines.evaluate.evaluate_scene` takes it."""
    from mirrorsim.pipelines.evaluate import evaluate_into
    from mirrorsim.pipelines.evaluate3d import evaluate_into3
    from mirrorsim.pipelines.random_scenes import sample_scene, to_yaml

    out_dir = Path(out)
    name = scene_name(i)
    t0 = time.perf_counter()
    row: dict = {"index": i, "scene": name, "seed": seed, "schema": table.SCHEMA}
    try:
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(i,)))
        scene = sample_scene(spec, rng, name)
        scene = scene.with_render(spp=spp or scene.render.spp, seed=i)
        write_text(out_dir / "scenes" / f"{name}.yaml", to_yaml(scene))
        t1 = time.perf_counter()
        with warnings.catch_warnings():  # a spec that draws JPEG frames knows it does
            warnings.filterwarnings("ignore", message=".*a JPEG frame")
            # into the dataset's own folder (claimed by run_dataset); a 3-D spec's scenes
            # solved in 3-D
            evaluate = evaluate_into3 if spec.is_3d else evaluate_into
            rep = evaluate(scene, out_dir / "frames" / name, variant=variant, progress=False,
                           keep=keep, error_model=error_model, calibration=calibration)
        seen = rep.seen if spec.is_3d else rep.measurements
        write_json(out_dir / "frames" / name / f"{name}.measurements.json", seen.to_json())
        row.update(row_of3(scene, rep) if spec.is_3d else row_of(scene, rep))
        row["seconds_sample"] = t1 - t0
        row["error"] = ""
    except SCENE_FAILURES as exc:  # the scene's own: recorded, one bad scene must not stop a run
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=3)
    except Exception as exc:  # outside the scene: no row, so a resumed run redoes it
        return SceneResult(i, None, f"{type(exc).__name__}: {exc}")
    row["seconds_total"] = time.perf_counter() - t0
    # the row records its scene's files: a frame damaged or replaced later is found by
    # --resume (which redoes the scene), load_dataset and errormodel
    done = replace(table.DatasetRow.from_json(row), files=scene_files(out_dir, name))
    write_json(out_dir / "rows" / f"{name}.json", row_document(done, digest))
    return SceneResult(i, done)


def _calibrate_models(spec: DatasetSpec, variant: str, progress: bool) -> None:
    """Calibrate each of the spec's camera models once, before the workers start, so
    that they all find K in the cache (with ranges instead of models, or a drawn pencil
    height, each scene calibrates its own camera as it comes)."""
    from mirrorsim.pipelines.calibrate import calibrate
    from mirrorsim.pipelines.random_scenes import camera_models

    cams, height = camera_models(spec), spec.beacon_height
    # a calibration distance error drawn per scene: each scene calibrates as it comes
    error = spec.calibration_error
    if (cams is None or isinstance(height, list) or isinstance(error, list)
            or spec.target_size is None):
        return
    with progress_bar(len(cams), desc="calibrating camera models", unit="model",
                      enabled=progress, leave=False) as bar:
        for cam in cams:
            calibrate(cam, spec.target_size, float(height), variant=variant,
                      distance_error=float(error))
            bar.update()


# ------------------------------------------------------------------- the run


@dataclass(frozen=True)
class DatasetRun:
    """A dataset run's summary: rows in the table, computed now, found done, failed (a
    row with an error), and the scenes to retry (index → why: no row)."""

    rows: int
    computed: int
    already_done: int
    failed: int
    retry: dict[int, str]
    parquet: Path
    seconds: float
    per_minute: float


def _check_run_parameters(n, seed, workers, spp, sampler, executor, keep, variant) -> None:
    """Every parameter of :func:`run_dataset` that can be checked before anything is
    written (a bad one had failed after the folder was claimed, or in every scene)."""
    from mirrorsim.pipelines.score import check_keep
    from mirrorsim.rendering.backend import check_variant
    from mirrorsim.scene.render_settings import MAX_SEED, RenderSettings, is_whole

    for name, v, lo, hi in (("n", n, 1, MAX_SCENES), ("seed", seed, 0, MAX_SEED),
                            ("workers", workers, 1, MAX_WORKERS)):
        if not is_whole(v) or not lo <= v <= hi:
            raise BadParameter(name, f"{v!r} must be a whole number within {lo}.."
                               f"{hi}")
    # the render settings' own check (None: the spec's, checked when it is read)
    RenderSettings(**{k: v for k, v in (("spp", spp), ("sampler", sampler)) if v is not None})
    check_variant(variant)
    if executor not in EXECUTORS:
        raise BadParameter("executor", f"{executor!r}: choose {' or '.join(EXECUTORS)}")
    check_keep(keep)


def _holds(path: str | None, digest: str) -> bool:
    """Whether the model file ``path`` holds the model of ``digest``: a model read from a
    file and then changed in memory (``dataclasses.replace``) still names that file."""
    if path is None:
        return False
    try:
        found = load_error_model(path)
    except InputError:
        return False
    return _digest(found) == digest


def _digest(model: ErrorModel) -> str:
    """What a dataset records of its error model: the SHA-256 of its file's contents."""
    return hashlib.sha256(dumps(model.to_json()).encode()).hexdigest()


def run_dataset(n: int, seed: int, out: str | Path, *, workers: int = 1,
                spec_path: str | Path | None = None, spp: int | None = None,
                sampler: str | None = None, variant: str = "auto", resume: bool = False,
                keep: tuple[str, ...] = (), executor: str = "local",
                scheduler: str | None = None, progress: bool = True,
                max_rss_mb: float = MAX_WORKER_RSS_MB,
                error_model: ErrorModel | None = None,
                calibration: SelfCalibration = PLAIN, beacons: int | None = None) -> DatasetRun:
    """Make (or finish) a dataset of ``n`` scenes; return a summary.

    The scenes run in worker processes (started afresh, ``spawn``; one with
    ``workers=1`` too), which import the calling script again: call this under
    ``if __name__ == "__main__":``.

    ``error_model`` gives each row's measurements their σ's (default: the model shipped
    for the ideal bench); a dataset is resumed only with the model it was started with.
    ``calibration``: each scene solved self-calibrated (its rows' ``est_*`` columns),
    which needs the spec's ``beacon.count`` (or ``beacons``, which replaces it) to carry
    its nuisances.

    Raises
    ------
    DatasetError
        If ``out`` is not a new or empty folder, or (with ``resume``) one of this
        command's datasets made with the same settings.
    BadParameter
        For ``n`` outside 1..MAX_SCENES, a negative ``seed``, ``workers`` below 1, an
        ``spp`` outside 1..MAX_SPP, an unknown ``sampler``, ``executor`` or ``keep``;
        for nuisances the spec's beacons cannot carry.
    """
    from mirrorsim.rendering.backend import choose_variant

    _check_run_parameters(n, seed, workers, spp, sampler, executor, keep, variant)
    # plain numbers from here on (numpy's would write themselves into files otherwise)
    n, seed, workers, spp = int(n), int(seed), int(workers), None if spp is None else int(spp)
    out, spec = Path(out), _run_spec(spec_path, sampler=sampler, beacons=beacons,
                                     calibration=calibration)
    model, meta = _model_and_meta(spec, error_model, n=n, seed=seed, spp=spp,
                                  spec_path=spec_path, calibration=calibration)
    with writing(out, meta, resume):  # claimed, and locked while it runs
        make_folders(out, meta)
        chosen = choose_variant(variant)  # the probe runs once here rather than in every worker
        _calibrate_models(spec, chosen, progress)
        # a job is its scene's index and the run's seed; the rest is the run's, by name
        job = partial(process_one, spec=spec, out=str(out), spp=spp, variant=chosen,
                      keep=tuple(keep), error_model=model, calibration=calibration,
                      digest=settings_digest(meta))
        done = {p.stem for p in (out / "rows").glob("scene*.json")}
        todo = [i for i in range(n) if scene_name(i) not in done]
        t_start = time.perf_counter()
        retry = _run_scenes(out, todo, seed, job=job, executor=executor, workers=workers,
                            scheduler=scheduler, max_rss_mb=max_rss_mb, progress=progress)
        wall = time.perf_counter() - t_start
        rows = collect_rows(out, n)  # against dataset.json as it is on disk
        _write_table_and_card(out, meta, rows, variant=chosen)
        return DatasetRun(rows=len(rows), computed=len(todo) - len(retry),
                          already_done=n - len(todo), failed=sum(bool(r.error) for r in rows),
                          retry=retry, parquet=out / "dataset.parquet", seconds=wall,
                          per_minute=len(todo) / wall * 60 if todo and wall else 0.0)


def _write_table_and_card(out: Path, meta: dict, rows: list[table.DatasetRow], *,
                          variant: str) -> None:
    """The table, the card, and the frames as learning pipelines take them (COCO, the
    Hub's front matter and Croissant: :mod:`~mirrorsim.pipelines.dataset_exports`)."""
    write_table(out, rows)
    write_card(out, meta, rows, variant=variant)
    if frames_in_rows(rows):  # (a dataset of failed draws alone has none)
        try:
            export_rows(out, rows, meta)
        except DatasetError as exc:  # the run's rows stand; `mirrorsim export` redoes it
            warnings.warn(f"{out}: its frames were not exported ({exc})", RuntimeWarning,
                          stacklevel=2)


def _run_spec(spec_path: str | Path | None, *, sampler: str | None, beacons: int | None,
              calibration: SelfCalibration) -> DatasetSpec:
    """The run's spec: the file's, with the sampler and the beacon count given (part of
    the spec, so that ``--resume`` checks them), able to carry the nuisances."""
    from mirrorsim.pipelines.random_scenes import load_spec

    spec = load_spec(spec_path)
    if sampler is not None:
        spec = spec.with_sampler(sampler)
    if beacons is not None:
        spec = spec.with_beacon_count(beacons)
    try:  # before anything is written (a planar spec's scenes refuse the pitch)
        if not spec.is_3d:
            check_planar(calibration)
        check_nuisances(calibration.nuisances, spec.beacon_count, 1, priors=calibration.priors,
                        readings=3 if spec.is_3d else 2)
    except SolverError as exc:
        raise BadParameter("nuisances", f"{exc} (scenes of {spec.beacon_count} beacon(s) "
                           f"drawn from {spec_path or 'the default spec'})") from None
    return spec


def _model_and_meta(spec: DatasetSpec, error_model: ErrorModel | None, *, n: int, seed: int,
                    spp: int | None, spec_path: str | Path | None,
                    calibration: SelfCalibration) -> tuple[ErrorModel, dict]:
    """The run's error model (the user's, or the one shipped for the spec's benches: a
    spec with a bench block draws imperfections, as evaluate chooses it for a scene), and
    what ``dataset.json`` records of the run: its settings (a resume compares them), the
    model's digest, and for the card the files it came from."""
    shipped = default_error_model("bench" if spec.data.get("bench") else "ideal")
    model = error_model or shipped
    meta = {"format": DATASET_FORMAT, "n": n, "seed": seed, "spp": spp, "spec": spec.data,
            "error_model_sha256": _digest(model),
            # for the card's command only (not settings: a resume compares none of them)
            "spec_file": None if spec_path is None else str(spec_path),
            "error_model_shipped": _digest(model) == _digest(shipped)}
    if not meta["error_model_shipped"] and _holds(model.source, meta["error_model_sha256"]):
        meta["error_model_file"] = model.source  # the card names its file
    if calibration.nuisances or calibration.position_sigma:
        # (absent otherwise, as in datasets without them; priors only where given)
        meta["calibrate"] = {"nuisances": list(calibration.nuisances),
                             "position_sigma": calibration.position_sigma,
                             **({"priors": dict(calibration.priors)}
                                if calibration.priors else {})}
    return model, meta


def _run_scenes(out: Path, todo: list[int], seed: int, *, job: Callable[..., SceneResult],
                executor: str, workers: int, scheduler: str | None, max_rss_mb: float,
                progress: bool) -> dict[int, str]:
    """Each scene of ``todo`` through ``job``, with one bar; the scenes to retry (index →
    why: no row)."""
    retry: dict[int, str] = {}

    def is_done(i: int) -> bool:
        return i in retry or (out / "rows" / f"{scene_name(i)}.json").exists()

    bar = progress_bar(len(todo), unit="scene", enabled=progress, desc="dataset")

    def on_result(result: SceneResult) -> None:
        if result.row is None:
            retry[result.index] = result.retry
        bar.update()

    try:
        _run_jobs(job, [(i, seed) for i in todo], executor, workers, scheduler=scheduler,
                  is_done=is_done, on_result=on_result, max_rss_mb=max_rss_mb)
    finally:
        bar.close()
    return retry


def _run_jobs(job: Callable[..., SceneResult], jobs: list[tuple], executor: str,
              workers: int, *, scheduler: str | None, is_done: Callable[[int], bool],
              on_result: Callable[[SceneResult], None], max_rss_mb: float) -> None:
    """``job(*each)`` (:func:`process_one`, the run's settings bound) for each of
    ``jobs``: in warm local workers, or on a Dask cluster."""
    if executor == "dask":
        run_dask(job, jobs, scheduler, on_result=on_result)
    else:  # one worker too: a worker process retires, this process could not
        from mirrorsim.rendering.backend import set_render_threads

        # each worker renders on its share of the cores
        run_local(job, jobs, workers, is_done=is_done, on_result=on_result,
                  max_rss_mb=max_rss_mb,
                  setup=partial(set_render_threads, usable_cores() // workers))


