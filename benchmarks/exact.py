"""Where an object's front face lies in a frame, exactly: the benchmarks that hold a
measured edge to the geometry share it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mirrorsim.detection.image_geometry import FRONT_OFFSET
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene
from mirrorsim.scene.model import Scene
from mirrorsim.truth import optics

SPEC = Path(__file__).resolve().parents[1] / "scenes" / "dataset_spec.yaml"


def spec_scenes(n: int) -> Iterator[Scene]:
    """Scenes 0..n−1 of the ideal bench's dataset spec (``spec000``…), the same in every
    benchmark that holds edges to the geometry."""
    spec = load_spec(SPEC)
    for i in range(n):
        yield sample_scene(spec, np.random.SeedSequence(0, spawn_key=(i,)), f"spec{i:03d}")


def front_face(scene, obj, height: float, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows (u, v) of the foot and the top (in that order) of ``obj``'s
    front face in its mirror image: the virtual image's axis moved towards the camera
    by FRONT_OFFSET[kind], ``height`` cm high."""
    img = optics.mirror_image(scene.camera.position, scene.mirror, obj.position)
    ray = (img.virtual - np.asarray(scene.camera.position)) / img.d_total
    front = img.virtual - ray * FRONT_OFFSET[kind]
    u, v, _ = optics.project(scene.camera, np.array([[*front, 0.0], [*front, height]]))
    return u, v
