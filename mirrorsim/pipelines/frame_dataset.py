"""A dataset's frames as a sequence for training: :class:`FrameDataset`.

It is a plain Python sequence (``len``, indexing), so PyTorch's ``DataLoader`` takes it
as a map-style dataset without mirrorsim importing torch; its items are dicts of numpy
arrays and typed values (``batch_size=None``, or a ``collate_fn`` of your own: frames
differ in their number of instances).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from mirrorsim.arguments import checked
from mirrorsim.formats import rle
from mirrorsim.formats.dataset_folder import read_verified
from mirrorsim.formats.dataset_rows import DatasetError
from mirrorsim.formats.measurements import load_measurements
from mirrorsim.pipelines.dataset_exports import (
    FrameEntry,
    annotations_of,
    dataset_frames,
    flat_keypoints,
    scene_object,
)
from mirrorsim.scene.render_settings import AOVS


class FrameDataset:
    """The frames of the dataset in ``folder``, verified when it is opened (its table,
    rows and every file they record).

    Item ``i`` is a dict:

    - ``image``: the frame, RGB, uint8 (H, W, 3);
    - ``masks``: bool (N, H, W), one per instance (``masks=False``: absent);
    - ``boxes``: float (N, 4), x, y, width, height (px);
    - ``categories``, ``objects``, ``views``: per instance, its COCO category, object
      (``target``, ``beacons[i]``, ``mirror``) and view (``direct``, ``mirror``);
    - ``keypoints``: per instance a float (K, 3) array of u, v, visibility;
    - ``virtual_camera``: the mirror's virtual camera (its world-to-camera 4×4 matrix);
    - ``truth``: the frame's :class:`~mirrorsim.truth.groundtruth.GroundTruth`;
    - ``measurements``: what the solver was given (None: the scene failed first);
    - ``depth``, ``normals``: the frame's float arrays where the dataset was made with
      ``--aov`` (docs/annotations.md);
    - ``scene``, ``frame``: their names.

    ``transform``, where given, is applied to each item before it is returned.

    Raises
    ------
    DatasetError
        For a folder whose table, rows or files fail verification, or without frames.
    """

    @checked  # each argument held to its hint, as every public entry point's
    def __init__(self, folder: str | Path, *, masks: bool = True,
                 transform: Callable[[dict], Any] | None = None):
        self.folder = Path(folder)
        self.entries: list[FrameEntry] = dataset_frames(read_verified(self.folder)[1])
        if not self.entries:
            raise DatasetError(self.folder, "has no frames")
        self.masks, self.transform = masks, transform

    def __len__(self) -> int:
        return len(self.entries)

    def __getitem__(self, i: int) -> Any:
        if not isinstance(i, int | np.integer):
            raise TypeError(f"FrameDataset indices are whole numbers, not {type(i).__name__}")
        entry = self.entries[i]  # (an IndexError past the end ends iteration)
        item = self._item(entry)
        return self.transform(item) if self.transform is not None else item

    def _item(self, entry: FrameEntry) -> dict:
        truth, ann = annotations_of(self.folder, entry)
        bgr = cv2.imread(str(self.folder / entry.image), cv2.IMREAD_COLOR)
        if bgr is None:
            raise DatasetError(self.folder / entry.image, "cannot be decoded as an image")
        inst = ann.instances
        item = {"image": cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB),
                "boxes": np.array([i.bbox for i in inst], float).reshape(-1, 4),
                "categories": [i.category for i in inst],
                "objects": [scene_object(entry, i.object) for i in inst],
                "views": [i.view for i in inst],
                # (u, v, visibility) as COCO lists them: 0, 0, 0 off the frame
                "keypoints": [np.array(flat_keypoints(i), float).reshape(-1, 3) for i in inst],
                "virtual_camera": np.array(ann.virtual_camera.world_to_camera),
                "truth": truth,
                "measurements": load_measurements(self.folder / entry.measurements_file)
                if entry.measurements_file else None,
                "scene": entry.row["scene"], "frame": entry.frame}
        if self.masks:
            item["masks"] = np.stack([rle.decode(i.mask) for i in inst]) if inst else \
                np.zeros((0, ann.height, ann.width), bool)
        for name in AOVS:
            path = self.folder / Path(entry.image).with_name(f"{entry.frame}.{name}.npy")
            if path.exists():
                item[name] = np.load(path, allow_pickle=False)
        return item
