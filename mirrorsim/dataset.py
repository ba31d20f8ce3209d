"""Datasets for error modelling: many random scenes rendered, detected, solved and scored.

Layout of a dataset folder::

    DIR/scenes/<name>.yaml    each scene as a normal scene file (rerun one alone with
                              `mirrorsim evaluate`)
    DIR/frames/<name>/…       its frame, ground truth, ids and annotated frame
    DIR/rows/<name>.json      its finished row (written last, atomically: a row file
                              exists only for a complete scene)
    DIR/dataset.parquet       all rows, one per scene, in index order
    DIR/README.md             the dataset card
    DIR/dataset.json          how it was made (seed, n, spec, spp): --resume checks it

Scene i is drawn from ``SeedSequence(seed).spawn(n)[i]`` and rendered with seed i, so a
row depends on (seed, i) alone: the same seed gives the same rows whatever the number of
workers or interruptions.  Work runs in worker processes that are recycled every few
scenes (Mitsuba leaks when scenes are reloaded in one process), or on a Dask cluster.
"""

from __future__ import annotations

import json
import math
import sys
import time
import traceback
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from mirrorsim.errors import InputError, RunFailed
from mirrorsim.io import atomic_path, write_json, write_text
from mirrorsim.model import RenderSettings, Scene
from mirrorsim.report import ObjectTruth, Report
from solver.geometry import yaw_difference

ROW_SCHEMA_VERSION = 1
RECYCLE_EVERY = 8  # scenes per worker process before it is replaced


def scene_name(i: int) -> str:
    """File name of scene i."""
    return f"scene{i:06d}"


def process_one(i: int, seed: int, n: int, spec: dict, out: str, spp: int | None,
                variant: str) -> dict:
    """Draw, render, detect, solve and score scene i; write its files; return its row.

    A failure is recorded in the row (``error``), never raised.
    """
    from mirrorsim.evaluate import evaluate_scene
    from mirrorsim.sampler import sample_scene, to_yaml

    out_dir = Path(out)
    name = scene_name(i)
    t0 = time.perf_counter()
    row: dict = {"index": i, "scene": name, "seed": seed, "schema": ROW_SCHEMA_VERSION}
    try:
        ss = np.random.SeedSequence(seed).spawn(n)[i]
        scene = sample_scene(spec, np.random.default_rng(ss), name)
        scene = replace(scene, render=RenderSettings(spp=spp or scene.render.spp, seed=i))
        write_text(out_dir / "scenes" / f"{name}.yaml", to_yaml(scene))
        t1 = time.perf_counter()
        rep = evaluate_scene(scene, out_dir / "frames" / name, variant=variant, progress=False)
        row.update(_flatten(scene, rep))
        row["seconds_sample"] = t1 - t0
        row["error"] = ""
    except Exception as exc:  # recorded, not fatal: one bad scene must not stop a run
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=3)
    row["seconds_total"] = time.perf_counter() - t0
    write_json(out_dir / "rows" / f"{name}.json", row)
    return row


def _flatten(scene: Scene, rep: Report) -> dict:
    """The row's columns: scene parameters, truth, measurements, solution, errors."""
    cam, mir, t = scene.camera, scene.mirror, rep.truth
    meas, sol, err = rep.measurements, rep.solution, rep.errors
    row = {
        "camera_x": cam.position[0], "camera_y": cam.position[1], "camera_height": cam.height,
        "camera_pan_deg": cam.pan_deg, "hfov_deg": cam.hfov,
        "mirror_x": mir.center[0], "mirror_y": mir.center[1], "mirror_yaw_deg": mir.yaw % 180,
        "mirror_width": mir.size[0], "mirror_height": mir.size[1],
        "target_x": scene.target.position[0], "target_y": scene.target.position[1],
        "variant": rep.render.variant, "spp": rep.render.spp, "render_seed": rep.render.seed,
    }
    b, frame = meas.beacons[0], rep.frames[0]
    for kind, truth, (alpha, d), clipped in (
            ("target", t.target, meas.targets[0], frame.target_clipped),
            ("beacon", t.beacons[0], (b.alpha_deg, b.d_total), frame.beacon_clipped)):
        row.update({
            f"{kind}_pos_x": truth.position[0], f"{kind}_pos_y": truth.position[1],
            f"{kind}_alpha_true": truth.alpha_deg, f"{kind}_d_true": truth.d_total,
            f"{kind}_d1": truth.d1, f"{kind}_d2": truth.d2,
            f"{kind}_off_axis_deg": (truth.alpha_deg - cam.pan_deg + 180.0) % 360.0 - 180.0,
            f"{kind}_incidence_deg": _incidence_deg(scene, truth),
            f"{kind}_height_px_true": truth.image_px.height,
            f"{kind}_alpha_meas": alpha, f"{kind}_d_meas": d,
            f"{kind}_alpha_err": alpha - truth.alpha_deg,
            f"{kind}_d_rel_err": (d - truth.d_total) / truth.d_total,
            f"{kind}_clipped": bool(clipped),
        })
    row.update({
        "est_target_x": float(sol.target[0]), "est_target_y": float(sol.target[1]),
        "est_mirror_yaw_deg": sol.mirror.yaw_deg,
        "err_target_cm": err.target_cm, "err_mirror_yaw_deg": err.mirror_yaw_deg,
        "err_mirror_offset_cm": err.mirror_offset_cm,
        "err_reflection_point_cm": err.reflection_point_cm,
        "target_ellipse95_major_cm": (math.nan if err.target_ellipse95_major_cm is None
                                      else err.target_ellipse95_major_cm),
    })
    return row


def _incidence_deg(scene: Scene, truth: ObjectTruth) -> float:
    """Angle between the camera's ray to the mirror and the mirror's normal."""
    ray = np.asarray(truth.reflection_point) - np.asarray(scene.camera.position, float)
    ray_bearing = math.degrees(math.atan2(ray[1], ray[0]))
    return 90.0 - float(yaw_difference(ray_bearing, scene.mirror.yaw))


# ------------------------------------------------------------------- the run


class DatasetError(InputError):
    """A run that cannot start (e.g. a folder holding another dataset): bad input."""

    def __init__(self, folder: str | Path, message: str):
        super().__init__(folder, "", message)


def run_dataset(n: int, seed: int, out: str | Path, *, workers: int = 1,
                spec_path: str | Path | None = None, spp: int | None = None,
                variant: str = "auto", resume: bool = False, executor: str = "local",
                scheduler: str | None = None, progress: bool = True,
                recycle_every: int = RECYCLE_EVERY) -> dict:
    """Make (or finish) a dataset of ``n`` scenes; return a summary.

    Raises
    ------
    DatasetError
        If ``out`` holds a dataset made with other settings, or holds one and
        ``resume`` is false.
    """
    from mirrorsim.backend import choose_variant
    from mirrorsim.sampler import load_spec

    out = Path(out)
    spec = load_spec(spec_path)
    meta = {"n": n, "seed": seed, "spp": spp, "spec": spec}
    meta_path = out / "dataset.json"
    if meta_path.exists():
        old = json.loads(meta_path.read_text())
        same = {k: old.get(k) for k in ("n", "seed", "spp", "spec")} == meta
        if not resume:
            raise DatasetError(out, "already holds a dataset: pass --resume to finish it, "
                               "or choose another --out")
        if not same:
            raise DatasetError(out, f"holds a dataset made with other settings "
                               f"(n={old.get('n')}, seed={old.get('seed')}, spp={old.get('spp')})")
    for sub in ("scenes", "frames", "rows"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    if not meta_path.exists():
        write_json(meta_path, meta)
    # the probe runs once here rather than in every worker
    chosen = choose_variant(variant)
    todo = [i for i in range(n) if not (out / "rows" / f"{scene_name(i)}.json").exists()]
    t_start = time.perf_counter()
    done_before = n - len(todo)
    bar = tqdm(total=len(todo), unit="scene", disable=not progress, desc="dataset")
    args = [(i, seed, n, spec, str(out), spp, chosen) for i in todo]
    if executor == "dask":
        for _ in _run_dask(args, scheduler):
            bar.update()
    elif workers <= 1:
        for a in args:
            process_one(*a)
            bar.update()
    else:
        _run_local(args, workers, out, bar, recycle_every)
    bar.close()
    wall = time.perf_counter() - t_start
    rows = collect_rows(out, n)
    write_table(out, rows)
    write_card(out, meta, rows, chosen)
    failed = [r for r in rows if r.get("error")]
    return {"rows": len(rows), "computed": len(todo), "already_done": done_before,
            "failed": len(failed), "parquet": str(out / "dataset.parquet"),
            "seconds": wall, "per_minute": len(todo) / wall * 60 if todo and wall else 0.0}


def _run_local(args: list[tuple], workers: int, out: Path, bar,
               recycle_every: int = RECYCLE_EVERY) -> None:
    """Worker processes, replaced every ``recycle_every`` scenes: each chunk of
    workers × recycle_every scenes gets a fresh pool (ProcessPoolExecutor's own
    max_tasks_per_child hangs on Python 3.11 once its first workers retire).  A worker
    that dies (killed, out of memory) breaks the pool: a new one takes the scenes that
    have no row yet."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")  # a fresh interpreter: no inherited Mitsuba state
    deaths = 0
    while True:
        remaining = [a for a in args
                     if not (out / "rows" / f"{scene_name(a[0])}.json").exists()]
        if not remaining:
            return
        chunk = remaining[:workers * recycle_every]
        try:
            with ProcessPoolExecutor(workers, mp_context=ctx) as ex:
                for f in as_completed([ex.submit(process_one, *a) for a in chunk]):
                    f.result()
                    bar.update()
        except BrokenProcessPool:
            deaths += 1
            if deaths > 3:
                raise RunFailed("worker processes keep dying; the rows done so far are "
                                "kept (rerun with --resume)") from None
            print("\nwarning: a worker process died; a new pool takes the unfinished "
                  "scenes", file=sys.stderr)


def _run_dask(args, scheduler: str | None):
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futures = [client.submit(process_one, *a, pure=False) for a in args]
        for f in as_completed(futures):
            yield f.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def collect_rows(out: Path, n: int) -> list[dict]:
    """The finished rows of scenes 0..n-1, in index order."""
    rows = []
    for i in range(n):
        p = Path(out) / "rows" / f"{scene_name(i)}.json"
        if p.exists():
            rows.append(json.loads(p.read_text()))
    return rows


def write_table(out: Path, rows: list[dict]) -> Path:
    """All rows as one Parquet table (pyarrow), written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols: dict[str, list] = {}
    keys = sorted({k for r in rows for k in r if k != "traceback"},
                  key=lambda k: (k not in ("index", "scene", "error"), k))
    for k in keys:
        cols[k] = [r.get(k) for r in rows]
    table = pa.table(cols) if rows else pa.table({"index": pa.array([], pa.int64())})
    path = Path(out) / "dataset.parquet"
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return path


def write_card(out: Path, meta: dict, rows: list[dict], variant: str) -> None:
    """Write the dataset card DIR/README.md."""
    ok = [r for r in rows if not r.get("error")]
    med = lambda k: float(np.nanmedian([abs(r[k]) for r in ok])) if ok else math.nan  # noqa: E731
    text = f"""# mirrorsim dataset

Made with `mirrorsim dataset --n {meta['n']} --seed {meta['seed']}`
({'scene spp' if meta['spp'] is None else f"--spp {meta['spp']}"}; backend {variant}).
{len(rows)} rows, {len(rows) - len(ok)} failed (their `error` column says why).

Each row is one random scene (`scenes/<scene>.yaml`, a normal scene file: rerun it with
`mirrorsim evaluate`), its frame (`frames/<scene>/`), and these columns of
`dataset.parquet`:

- `index`, `scene`, `seed`, `render_seed`, `variant`, `spp`, `error` (empty if fine);
- scene parameters: `camera_x`, `camera_y`, `camera_height`, `camera_pan_deg`,
  `hfov_deg`, `mirror_x`, `mirror_y`, `mirror_yaw_deg`, `mirror_width`,
  `mirror_height`, `target_x`, `target_y` (cm, degrees);
- for `target_*` and `beacon_*`: position `pos_x`, `pos_y`; ground truth `alpha_true`,
  `d_true`, `d1`, `d2`; geometry `off_axis_deg` (bearing of the image off the optical
  axis), `incidence_deg` (camera ray against the mirror's normal), `height_px_true`
  (exact image height of the upright axis); measurements `alpha_meas`, `d_meas`; errors
  `alpha_err` (deg, measured − true) and `d_rel_err` (relative); `clipped`;
- solution: `est_target_x`, `est_target_y`, `est_mirror_yaw_deg`; errors
  `err_target_cm`, `err_mirror_yaw_deg`, `err_mirror_offset_cm`,
  `err_reflection_point_cm`; the solver's own bound `target_ellipse95_major_cm`
  (semi-major axis of its 95 % error ellipse);
- timings: `seconds_sample`, `seconds_total`.

Median |errors| here: target α {med('target_alpha_err'):.4f}°, target d
{100 * med('target_d_rel_err'):.3f} %, beacon α {med('beacon_alpha_err'):.4f}°, beacon d
{100 * med('beacon_d_rel_err'):.3f} %, target {med('err_target_cm'):.3f} cm.

Scene i is drawn from `SeedSequence({meta['seed']}).spawn({meta['n']})[i]` with the spec in
`dataset.json` and rendered with seed i.  `mirrorsim errormodel DIR` fits the error
model.
"""
    write_text(Path(out) / "README.md", text)
