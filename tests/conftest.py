"""Shared helpers: scene files, small-resolution variants of them, a private cache dir."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from mirrorsim.scene import Scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


def scene_dict(name: str) -> dict:
    return yaml.safe_load((SCENES / f"{name}.yaml").read_text())


def small_scene(name: str, width: int = 320, height: int = 182, **render) -> Scene:
    """A bundled scene at a small resolution (same field of view, so same geometry)."""
    d = copy.deepcopy(scene_dict(name))
    d["camera"]["resolution"] = [width, height]
    if render:
        d["render"] = {**d.get("render", {}), **render}
    return scene_from_dict(d, source=f"{name}.yaml", default_name=name)


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    """Backend probe answers go to a per-session folder, never the user's cache."""
    cache = tmp_path_factory.getbasetemp() / "mirrorsim-cache"
    monkeypatch.setenv("MIRRORSIM_CACHE_DIR", str(cache))
