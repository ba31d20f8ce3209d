"""The scenes the benchmarks that hold a measured edge to the geometry share (they hold
it to :func:`mirrorsim.truth.optics.front_face`)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mirrorsim.pipelines.random_scenes import load_spec, sample_scene
from mirrorsim.scene.model import Scene

SPEC = Path(__file__).resolve().parents[1] / "scenes" / "dataset_spec.yaml"


def spec_scenes(n: int) -> Iterator[Scene]:
    """Scenes 0..n−1 of the ideal bench's dataset spec (``spec000``…), the same in every
    benchmark that holds edges to the geometry."""
    spec = load_spec(SPEC)
    for i in range(n):
        yield sample_scene(spec, np.random.SeedSequence(0, spawn_key=(i,)), f"spec{i:03d}")
