"""A dataset's frames as learning pipelines take them: ``DIR/coco.json`` (COCO's
instances and keypoints), ``DIR/metadata.jsonl`` with the card's Hugging Face front
matter (``datasets.load_dataset(DIR, split="train")``), and ``DIR/croissant.json``.

Each is made from the frames' truth files (their annotations, verified on reading) and
the dataset's rows; ``mirrorsim dataset`` writes them when it finishes, and
``mirrorsim export`` for a folder made earlier.
"""

from __future__ import annotations

import datetime
import hashlib
from dataclasses import dataclass
from pathlib import Path

from mirrorsim.errors import BadParameter
from mirrorsim.formats import dataset_table as table
from mirrorsim.formats import frame_table
from mirrorsim.formats.dataset_folder import read_verified
from mirrorsim.formats.dataset_rows import DatasetError, read_description
from mirrorsim.formats.files import FRAME_SUFFIXES, dumps, write_json, write_text
from mirrorsim.scene.model import frame_beacon
from mirrorsim.truth.annotations import CATEGORIES, Annotations, Instance, frame_annotations
from mirrorsim.truth.groundtruth import GroundTruth, load_truth

EXPORTS = ("coco", "hf", "croissant")


@dataclass(frozen=True)
class FrameEntry:
    """One frame of a dataset: its scene's row, its name, and its files' paths relative
    to the folder (the measurements' '' where the scene wrote none)."""

    row: table.DatasetRow
    frame: str
    image: str
    truth_file: str
    measurements_file: str


def dataset_frames(rows: list[table.DatasetRow]) -> list[FrameEntry]:
    """Every frame the rows record (a frame is a file of ``frames/<scene>/`` beside its
    capture record), in the rows' order."""
    out = []
    for row in rows:
        name = row["scene"]
        for stem in sorted(f.removesuffix(".capture.json") for f in row.files
                           if f.endswith(".capture.json")):
            image = next((stem + s for s in FRAME_SUFFIXES if stem + s in row.files), None)
            if image is None or f"{stem}.json" not in row.files:
                continue
            meas = f"{name}.measurements.json"
            out.append(FrameEntry(row, stem, f"frames/{name}/{image}",
                                  f"frames/{name}/{stem}.json",
                                  f"frames/{name}/{meas}" if meas in row.files else ""))
    return out


def annotations_of(folder: Path, entry: FrameEntry) -> tuple[GroundTruth, Annotations]:
    """A frame's truth and its annotations, read and verified; for a frame made before
    truth files held them, made now from its scene file and its id pass (rendered again:
    ray casts at pixel centres, no path tracing), once the scene is shown to be the
    frame's (its render fingerprint).

    Raises
    ------
    DatasetError
        For a truth file that cannot be read, or an older frame whose scene file is not
        the one it was rendered from.
    """
    path = folder / entry.truth_file
    try:
        truth = load_truth(path)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DatasetError(path, f"not a readable truth file ({exc})") from None
    if truth.annotations is not None:
        return truth, truth.annotations
    # (Mitsuba only here: reading a dataset's frames and exporting them need none)
    from mirrorsim.errors import InputError
    from mirrorsim.pipelines.measured import frames_of
    from mirrorsim.pipelines.scenes import load_scene
    from mirrorsim.rendering.frames import object_labels
    from mirrorsim.rendering.passes import render_ids, scene_fingerprint

    scene_file = folder / "scenes" / f"{entry.row['scene']}.yaml"
    try:
        scenes = frames_of(load_scene(scene_file))
    except InputError as exc:
        raise DatasetError(path, f"holds no annotations, and its scene file cannot make "
                           f"them ({exc})") from None
    frame = next((f for f in scenes if f.name == entry.frame), None)
    if frame is None or truth.render is None or \
            truth.render.fingerprint != scene_fingerprint(frame):
        raise DatasetError(path, f"holds no annotations, and {scene_file.name} is not the "
                           "scene it was rendered from: make the dataset again")
    first, in_mirror = render_ids(frame)
    return truth, frame_annotations(frame, first, in_mirror, labels=object_labels(frame))


def scene_object(entry: FrameEntry, name: str) -> str:
    """An instance's object as its scene names it: a frame per beacon
    (``<scene>_b<k>``) holds that beacon alone, its truth's ``beacons[0]``, which is
    the scene's ``beacons[k]``."""
    k = frame_beacon(entry.row["scene"], entry.frame)
    return f"beacons[{k}]" if k is not None and name == "beacons[0]" else name


def _number(row: table.DatasetRow, name: str) -> float | None:
    """A row's value, or None where the scene failed (its row has no such column)."""
    v = row.columns.get(name)
    return None if v is None else float(v)


def frame_line(entry: FrameEntry, truth: GroundTruth, ann: Annotations) -> dict:
    """The frame's line of ``metadata.jsonl`` (:data:`~mirrorsim.formats.frame_table.FIELDS`)."""
    row = entry.row
    objects = [{"object": scene_object(entry, i.object), "view": i.view, "category": i.category,
                "bbox": list(i.bbox), "area": i.area, "mask_counts": i.mask["counts"],
                "keypoints": flat_keypoints(i)} for i in ann.instances]
    return {"file_name": entry.image, "scene": row["scene"], "index": row.index,
            "frame": entry.frame, "truth_file": entry.truth_file,
            "measurements_file": entry.measurements_file, "width": ann.width,
            "height": ann.height, "error": row.error,
            # the table's exact readings (in 3-D what an exact detector reads, which a
            # leaning glass moves off the base's image); a failed scene's, its truth's
            "target_alpha_true": float(row.columns.get("target_alpha_true",
                                                       truth.target.alpha_deg)),
            "target_d_true": float(row.columns.get("target_d_true", truth.target.d_total)),
            "target_alpha_meas": _number(row, "target_alpha_meas"),
            "target_d_meas": _number(row, "target_d_meas"),
            "err_target_cm": _number(row, "err_target_cm"),
            "camera_intrinsics": [c for r in ann.virtual_camera.intrinsics for c in r],
            "virtual_camera": [c for r in ann.virtual_camera.world_to_camera for c in r],
            "lens_distortion": list(ann.virtual_camera.distortion),
            "objects": objects}


def flat_keypoints(instance: Instance) -> list[float]:
    """An instance's keypoints as COCO lists them: u, v, visibility each (0, 0, 0 for
    one off the frame)."""
    out: list[float] = []
    for k in instance.keypoints:
        out += [k.u, k.v, k.visible] if k.visible else [0.0, 0.0, 0]
    return out


def coco_document(frames: list[tuple[FrameEntry, GroundTruth, Annotations]],
                  description: str) -> dict:
    """COCO's instances and keypoints document of the frames (each with its truth and
    annotations: :func:`annotations_of`): masks as compressed RLE, keypoints per
    category (:data:`~mirrorsim.truth.annotations.CATEGORIES`)."""
    cats = {c.name: k + 1 for k, c in enumerate(CATEGORIES)}
    images, annotations = [], []
    for n, (entry, _, ann) in enumerate(frames, start=1):
        images.append({"id": n, "file_name": entry.image, "width": ann.width,
                       "height": ann.height})
        for inst in ann.instances:
            kp = flat_keypoints(inst)
            annotations.append({
                "id": len(annotations) + 1, "image_id": n, "category_id": cats[inst.category],
                "segmentation": dict(inst.mask), "area": inst.area, "bbox": list(inst.bbox),
                "iscrowd": 0, "keypoints": kp, "num_keypoints": sum(v > 0 for v in kp[2::3]),
                "object": scene_object(entry, inst.object)})
    return {"info": {"description": description, "version": "1.0",
                     "date_created": datetime.date.today().isoformat()},
            "licenses": [], "images": images, "annotations": annotations,
            "categories": [{"id": cats[c.name], "name": c.name,
                            "supercategory": c.name.split("_")[0],
                            "keypoints": list(c.keypoints),
                            "skeleton": [list(p) for p in c.skeleton]} for c in CATEGORIES]}


def image_globs(entries: list[FrameEntry]) -> tuple[str, ...]:
    """Patterns that match the frames and nothing else of the folder: a frame's name
    ends in a digit (``scene000012``, or ``scene000012_b1`` for a frame per beacon),
    the id labels' and the annotated images' do not."""
    return tuple(f"frames/*/scene*[0-9]{s}" for s in sorted({Path(e.image).suffix
                                                              for e in entries}))


def write_exports(folder: str | Path, what: tuple[str, ...] = EXPORTS) -> dict[str, Path]:
    """Write ``what`` (of :data:`EXPORTS`) for the dataset in ``folder``, its table, rows
    and files verified first (``mirrorsim export``); the files written, by export.

    Raises
    ------
    DatasetError
        For a folder whose table, rows or files fail verification, or whose frames hold
        no annotations.
    BadParameter
        For an export not in :data:`EXPORTS`.
    """
    bad = [w for w in what if w not in EXPORTS]
    if bad:
        raise BadParameter("what", f"{bad[0]!r}: choose from {', '.join(EXPORTS)}")
    folder = Path(folder)
    _, rows = read_verified(folder)  # the table, its rows and every file they record
    return export_rows(folder, rows, read_description(folder), what=what)


def export_rows(folder: Path, rows: list[table.DatasetRow], meta: dict, *,
                what: tuple[str, ...] = EXPORTS) -> dict[str, Path]:
    """Write ``what`` for ``rows``, the dataset's rows as its run holds them (``meta``:
    its description); the files written, by export."""
    entries = dataset_frames(rows)
    if not entries:
        raise DatasetError(folder, "has no frames to export (its rows record no files: "
                           "made by a mirrorsim before rows recorded them, or every scene "
                           "failed before its render)")
    desc = f"mirrorsim dataset of {meta['n']} scenes (seed {meta['seed']}), {len(entries)} frames"
    frames = [(e, *annotations_of(folder, e)) for e in entries]
    written: dict[str, Path] = {}
    if "coco" in what:
        written["coco"] = write_json(folder / "coco.json", coco_document(frames, desc))
    if "hf" in what and (folder / "croissant.json").exists():
        what = (*what, "croissant")  # it names the metadata's SHA-256: made again with it
    if "hf" in what or "croissant" in what:
        lines = [frame_line(*f) for f in frames]
        text = "".join(dumps(line, indent=None) for line in lines)
        written["metadata"] = write_text(folder / "metadata.jsonl", text)
        digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    if "hf" in what:
        written["hf"] = _write_front_matter(folder, len(entries), image_globs(entries))
    if "croissant" in what:
        name = f"mirrorsim-seed{meta['seed']}-n{meta['n']}"  # not the folder's: it moves
        doc = frame_table.croissant(name, description=desc, image_globs=image_globs(entries),
                                    metadata_sha256=digest,
                                    date=datetime.date.today().isoformat())
        written["croissant"] = write_json(folder / "croissant.json", doc)
    return written


def _write_front_matter(folder: Path, frames: int, globs: tuple[str, ...]) -> Path:
    """The card (``README.md``) with the Hub's front matter at its top (replacing any)."""
    card = folder / "README.md"
    text = card.read_text(encoding="utf-8") if card.exists() else "# mirrorsim dataset\n"
    if text.startswith("---\n"):
        end = text.find("\n---\n", 4)
        text = text[end + 5:] if end >= 0 else text
    return write_text(card, frame_table.front_matter(frames, globs) + text)
