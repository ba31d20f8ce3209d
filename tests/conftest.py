"""Shared helpers: scene files, small-resolution variants of them, a private cache dir."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from mirrorsim.formats.scenefile import scene_from_dict
from mirrorsim.scene.model import Scene

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


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Probe answers and calibrations go to a per-session folder, never the user's cache
    (session-wide, so that module-scoped fixtures use it too)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MIRRORSIM_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "mirrorsim-cache"))
        yield


@pytest.fixture(scope="session")
def fast_variant() -> str:
    """The Mitsuba variant the renderer's tests run on: the fastest that works here
    (``cuda_ad_rgb``, else ``llvm_ad_rgb``, else ``scalar_rgb``), named in their output."""
    from mirrorsim.rendering.backend import choose_variant

    return choose_variant("auto")


@pytest.fixture(scope="session")
def jit_variant(fast_variant) -> str:
    """A JIT variant (LLVM or CUDA); skips where only scalar_rgb works."""
    if fast_variant == "scalar_rgb":
        pytest.skip("no JIT backend here")
    return fast_variant


def pytest_report_header(config) -> str:  # noqa: ARG001
    """Say which Mitsuba backend the rendering tests run on."""
    from mirrorsim.rendering.backend import choose_variant

    return f"mirrorsim rendering tests run on: {choose_variant('auto')} (fast_variant fixture)"
