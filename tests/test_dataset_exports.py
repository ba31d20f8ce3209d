"""A dataset as learning pipelines take it, each in one line: Hugging Face's
``load_dataset``, mlcroissant, pycocotools, and :class:`FrameDataset` (in PyTorch's
``DataLoader`` where torch is installed); and ``mirrorsim export`` for a folder made
earlier.  The loaders are the optional extra ``ml``'s: each test skips without its own."""

import glob
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mirrorsim.formats import rle
from mirrorsim.pipelines.dataset import run_dataset
from mirrorsim.pipelines.frame_dataset import FrameDataset
from tests.test_dataset import SPEC


@pytest.fixture(scope="module")
def four(tmp_path_factory):
    """A 4-scene dataset of two beacons a scene (a frame a beacon: 8 frames)."""
    out = tmp_path_factory.mktemp("exports") / "ds"
    run_dataset(4, 11, out, workers=1, spec_path=SPEC, beacons=2, progress=False)
    frames = sorted(p for p in out.glob("frames/*/*.png") if p.stem[-1].isdigit())
    assert len(frames) == 8
    return out, frames


def test_the_frame_globs_match_the_frames_alone(four):
    out, frames = four
    card = (out / "README.md").read_text()
    assert card.startswith("---\n") and "# mirrorsim dataset" in card
    croissant = json.loads((out / "croissant.json").read_text())
    globs = croissant["distribution"][1]["includes"]
    found = {Path(p) for g in globs for p in glob.glob(str(out / g))}
    assert found == set(frames)


def test_hugging_face_loads_it_in_one_line(four, tmp_path):
    datasets = pytest.importorskip("datasets")
    out, frames = four
    ds = datasets.load_dataset(str(out), split="train", cache_dir=str(tmp_path))
    assert ds.num_rows == len(frames)
    row = ds[0]
    assert row["image"].size == (row["width"], row["height"]) == (960, 544)
    assert row["image"].getpixel((10, 10)) is not None  # decoded
    cats = {o["category"] for r in ds for o in r["objects"]}
    assert {"target_in_mirror", "beacon_in_mirror", "mirror"} <= cats


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # rdflib's own, under mlcroissant
def test_croissant_validates_and_iterates(four):
    mlc = pytest.importorskip("mlcroissant")
    out, frames = four
    ds = mlc.Dataset(str(out / "croissant.json"))  # validates on loading
    records = list(ds.records("frames"))
    images = list(ds.records("images"))
    assert len(records) == len(images) == len(frames)
    names = {r["frames/file_name"].decode() for r in records}
    assert names == {r["images/file_name"].decode() for r in images}
    assert images[0]["images/image"].size == (960, 544)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pycocotools' own, NumPy 2
def test_coco_opens_and_every_mask_holds_its_area(four):
    coco_mod = pytest.importorskip("pycocotools.coco")
    out, frames = four
    coco = coco_mod.COCO(str(out / "coco.json"))
    assert len(coco.getImgIds()) == len(frames)
    anns = coco.loadAnns(coco.getAnnIds())
    assert anns
    for a in anns:
        mask = coco.annToMask(a)
        assert mask.sum() == a["area"] > 0
        cat = coco.loadCats(a["category_id"])[0]
        assert len(a["keypoints"]) == 3 * len(cat["keypoints"])


def test_frame_dataset_gives_images_masks_and_truth(four):
    out, frames = four
    ds = FrameDataset(out)
    assert len(ds) == len(frames)
    item = ds[len(ds) - 1]
    assert item["image"].shape == (544, 960, 3) and item["image"].dtype == np.uint8
    n = len(item["categories"])
    assert item["masks"].shape == (n, 544, 960) and item["boxes"].shape == (n, 4)
    for mask, box in zip(item["masks"], item["boxes"], strict=True):
        vs, us = np.nonzero(mask)
        assert (us.min(), vs.min(), us.max() - us.min() + 1, vs.max() - vs.min() + 1) == \
            tuple(box)
    assert item["truth"].annotations is not None and item["measurements"] is not None
    assert [len(k) for k in item["keypoints"]] == [
        4 if c.startswith(("target", "mirror")) else 2 for c in item["categories"]]
    assert sum(1 for _ in ds) == len(ds)  # iterates to its end
    with pytest.raises(TypeError):
        ds["0"]


def test_frame_dataset_in_a_torch_data_loader(four):
    torch = pytest.importorskip("torch")
    out, frames = four
    loader = torch.utils.data.DataLoader(FrameDataset(out), batch_size=None, shuffle=True,
                                         num_workers=2)
    seen = [item["frame"] for item in loader]
    assert sorted(seen) == sorted(p.stem for p in frames)


def test_export_writes_them_again_and_refuses_a_damaged_frame(four, tmp_path):
    out, frames = four
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    for name in ("coco.json", "croissant.json", "metadata.jsonl"):
        (copy / name).unlink()
    run = [sys.executable, "-m", "mirrorsim", "export", str(copy)]
    done = subprocess.run(run, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    for name in ("coco.json", "croissant.json", "metadata.jsonl"):
        assert (copy / name).read_bytes() == (out / name).read_bytes()
    frame = copy / frames[0].relative_to(out)
    frame.write_bytes(frame.read_bytes()[:-10])
    done = subprocess.run([*run, "--to", "coco"], capture_output=True, text=True)
    assert done.returncode == 2 and frame.name in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_metadata_lines_match_the_truth_files(four):
    out, _ = four
    for line in (out / "metadata.jsonl").read_text().splitlines():
        d = json.loads(line)
        truth = json.loads((out / d["truth_file"]).read_text())
        inst = truth["annotations"]["instances"]
        assert [o["mask_counts"] for o in d["objects"]] == [i["mask"]["counts"] for i in inst]
        h, w = d["height"], d["width"]
        for o in d["objects"]:
            assert rle.decode({"size": [h, w], "counts": o["mask_counts"]}).sum() == o["area"]


def _frame_name(args):
    ds, i = args
    return ds[i]["frame"]


def test_frame_dataset_travels_to_worker_processes(four):
    # what a DataLoader's workers do with it (torch or not): pickled to fresh processes,
    # indexed there
    import multiprocessing
    import pickle

    out, frames = four
    ds = FrameDataset(out)
    assert pickle.loads(pickle.dumps(ds))[0]["frame"] == ds[0]["frame"]
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        names = pool.map(_frame_name, [(ds, i) for i in range(len(ds))])
    assert sorted(names) == sorted(p.stem for p in frames)


def test_a_frame_made_before_annotations_gets_them_from_its_scene(four, tmp_path):
    # a truth file as an older mirrorsim wrote it (no annotations, sealed): the same
    # annotations come from its scene file and its id pass, rendered again; in a frame
    # per beacon the exports name the scene's beacon (its truth holds it alone)
    from dataclasses import replace

    from mirrorsim.formats.cache import seal
    from mirrorsim.formats.dataset_folder import collect_rows
    from mirrorsim.formats.files import write_json
    from mirrorsim.pipelines.dataset_exports import annotations_of, dataset_frames, scene_object
    from mirrorsim.truth.groundtruth import load_truth

    out, _ = four
    copy = tmp_path / "old"
    shutil.copytree(out, copy)
    entries = dataset_frames(collect_rows(copy, 4))
    entry = next(e for e in entries if e.frame.endswith("_b1"))
    path = copy / entry.truth_file
    truth = load_truth(path)
    write_json(path, seal(replace(truth, annotations=None).to_json()))
    again, ann = annotations_of(copy, entry)
    assert load_truth(path).annotations is None and ann == truth.annotations
    assert scene_object(entry, "beacons[0]") == "beacons[1]"
    assert scene_object(entry, "target") == "target"
    # another scene's file in its place is refused, naming the truth file
    other = next(e for e in entries if e.row["scene"] != entry.row["scene"])
    (copy / "scenes" / f"{entry.row['scene']}.yaml").write_bytes(
        (copy / "scenes" / f"{other.row['scene']}.yaml").read_bytes())
    from mirrorsim.formats.dataset_rows import DatasetError

    with pytest.raises(DatasetError, match=path.name):
        annotations_of(copy, entry)


def test_each_metadata_line_holds_the_declared_fields(four):
    from mirrorsim.formats.frame_table import FIELDS, OBJECT_FIELDS

    out, _ = four
    names = {"file_name"} | {f.name for f in FIELDS} - {"image"}
    for line in (out / "metadata.jsonl").read_text().splitlines():
        d = json.loads(line)
        assert set(d) == names
        assert all(set(o) == {f.name for f in OBJECT_FIELDS} for o in d["objects"])
