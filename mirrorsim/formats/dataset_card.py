"""A dataset's card (``DIR/README.md``): the command that made it, its columns with
their units, and its median errors."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np

from mirrorsim.formats import dataset_table as table
from mirrorsim.formats.files import write_text
from solver.selfcal import priors_text


def card_columns() -> str:
    """The table's columns as the card lists them, from their declaration."""
    groups = (("the run", table.RUN, ""), ("scene parameters", table.SCENE, ""),
              ("what the solver was given besides the images", table.KNOWN, ""),
              ("for `target_*` and `beacon_*` (and, in a scene of several beacons, "
               "`beacon2_*`, `beacon3_*`… with `known_x` and `known_y` besides)",
               table.PER_OBJECT, "<object>_"),
              ("solution", table.SOLUTION, ""),
              ("bench imperfections (the spec's `bench:` block; ideal values when absent)",
               table.BENCH, ""), ("timings", table.TIMING, ""))
    return "\n".join(textwrap.fill(f"- {title}: {table.card_section(cols, prefix)}.", 88,
                                    subsequent_indent="  ", break_on_hyphens=False)
                      for title, cols, prefix in groups)


def _calibrated(meta: dict) -> str:
    """The self-calibration options a dataset was made with, as its command had them."""
    cal = meta.get("calibrate")
    if not cal:
        return ""
    return ((f" --calibrate {','.join(cal['nuisances'])}" if cal["nuisances"] else "")
            + (f" --beacon-sigma {cal['position_sigma']:g}" if cal["position_sigma"] else "")
            + (f" --prior {priors_text(cal['priors'])}" if cal.get("priors") else ""))


def made_with(meta: dict, out: Path) -> str:
    """The command that makes the dataset ``meta`` describes again (the spec's file as
    it was named; the error model, where not the shipped one, by its file as it was named
    or, made in memory, by its hash: see
    :func:`_model_words`)."""
    spec = meta.get("spec") or {}
    sampler = (spec.get("render") or {}).get("sampler")
    count = (spec.get("beacon") or {}).get("count")
    return (f"mirrorsim dataset --n {meta['n']} --seed {meta['seed']} --out {out}"
            + (f" --spec {meta['spec_file']}" if meta.get("spec_file") else "")
            + (f" --spp {meta['spp']}" if meta.get("spp") is not None else "")
            + (f" --sampler {sampler}" if sampler else "")
            # (a count drawn from a range is the spec file's own: no option gives it)
            + (f" --beacons {count}" if count and not isinstance(count, list) else "")
            + (f" --error-model {meta.get('error_model_file') or 'MODEL'}"
               if meta.get("error_model_shipped") is False else "")
            + _calibrated(meta))


def _beacon_words(meta: dict) -> str:
    """How many beacons each scene has: ``2 beacon(s)``, or ``1–3 beacon(s)`` drawn."""
    count = (meta['spec'].get('beacon') or {}).get('count', 1)
    return (f"{count[0]}–{count[1]} beacon(s), drawn" if isinstance(count, list)
            else f"{count} beacon(s)")


def _model_words(meta: dict) -> str:
    """The error model a dataset was made with, where it is not the shipped one."""
    if meta.get("error_model_shipped") is not False:
        return ""
    if meta.get("error_model_file"):  # the file as it was named, and what it held then
        return (f"; the error model {meta['error_model_file']} was the one of SHA-256 "
                f"{meta['error_model_sha256'][:12]}… (dataset.json)")
    return (f"; MODEL: the error model of SHA-256 {meta['error_model_sha256'][:12]}… "
            "(dataset.json)")


def write_card(out: Path, meta: dict, rows: list[table.DatasetRow], *, variant: str) -> None:
    """Write the dataset card DIR/README.md."""
    ok = [r for r in rows if not r.error]
    med = lambda k: float(np.nanmedian([abs(r[k]) for r in ok])) if ok else math.nan  # noqa: E731
    columns = card_columns()
    fits = ("Its scenes were solved in 3-D (`geometry`): `mirrorsim errormodel DIR` fits "
            "a 3-D error model (each image's elevation σ besides)."
            if any(r.columns.get("geometry") == "3d" for r in ok)
            else "`mirrorsim errormodel DIR` fits the error model.")
    text = f"""# mirrorsim dataset

Made with `{made_with(meta, out)}`
({'the scenes’ spp' if meta['spp'] is None else f"{meta['spp']} spp"}; backend {variant};
{_beacon_words(meta)} a scene{_model_words(meta)}).
{len(rows)} rows, {len(rows) - len(ok)} failed (their `error` column says why).

Each row is one random scene (`scenes/<scene>.yaml`, a normal scene file: rerun it with
`mirrorsim evaluate`), its frame (`frames/<scene>/`), and these columns of
`dataset.parquet`:

{columns}

Median |errors| here: target α {med('target_alpha_err'):.4f}°, target d
{100 * med('target_d_rel_err'):.3f} %, beacon α {med('beacon_alpha_err'):.4f}°, beacon d
{100 * med('beacon_d_rel_err'):.3f} %, target {med('err_target_cm'):.3f} cm.

Scene i is drawn from `SeedSequence({meta['seed']}).spawn({meta['n']})[i]` with the spec in
`dataset.json` and rendered with seed i.  {fits}

## Loading it

Each frame's truth file (`frames/<scene>/<frame>.json`) holds its annotations: per
object and view a mask (COCO RLE), box and keypoints, and the mirror's virtual camera.
The same frames, one line each (`pip install 'mirrorsim[ml]'` brings the loaders):

```python
import mirrorsim as ms
table = ms.load_dataset("{out}")                  # this table, verified (pandas)
frames = ms.FrameDataset("{out}")                 # images, masks, keypoints, truth

import datasets                                   # Hugging Face: metadata.jsonl + frames
ds = datasets.load_dataset("{out}", split="train")

import mlcroissant as mlc                         # Croissant: record sets frames, images
records = mlc.Dataset("{out}/croissant.json").records("frames")

from pycocotools.coco import COCO                 # COCO instances and keypoints
coco = COCO("{out}/coco.json")
```
"""
    write_text(Path(out) / "README.md", text)
