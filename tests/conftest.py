"""Shared helpers: scene files, small-resolution variants of them, a private cache dir."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from mirrorsim.pipelines.scenes import scene_from_dict
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


def synthetic_columns(n: int, seed: int, sigma_alpha=(0.003, 0.003), sigma_d=(0.002, 0.005),
                      **extra) -> dict:
    """Dataset columns as an error model reads them, for n rows of one camera pan (0°):
    each object's errors drawn N(0, σ) with (target, beacon) ``sigma_alpha`` (deg) and
    ``sigma_d`` (relative), plus ``extra`` columns."""
    import numpy as np

    rng = np.random.default_rng(seed)
    cols = {"index": list(range(n)), "error": [""] * n, "observer_pan_deg": np.zeros(n)}
    for k, kind in enumerate(("target", "beacon")):
        d = rng.uniform(40, 140, n)
        alpha = rng.uniform(-25, 25, n)
        a_err = rng.normal(0, sigma_alpha[k], n)
        d_err = rng.normal(0, sigma_d[k], n)
        cols.update({f"{kind}_d_true": d, f"{kind}_off_axis_deg": alpha,
                     f"{kind}_incidence_deg": rng.uniform(0, 60, n),
                     f"{kind}_height_px_true": 15000 / d,
                     f"{kind}_alpha_err": a_err, f"{kind}_d_rel_err": d_err,
                     f"{kind}_alpha_meas": alpha + a_err, f"{kind}_d_meas": d * (1 + d_err)})
    with_frame_columns(cols, rng)
    cols.update(extra)
    return cols


def with_frame_columns(cols: dict, rng) -> dict:
    """``cols`` with what the frames showed of each image and the scenes' facts, as a
    dataset records them (the error model's features and domain): each image's measured
    height (its true one), a contrast, the frame's noise, a lossless frame; a 6 cm camera
    of fx 1500 px, 4.2 cm pencils, one beacon."""
    import numpy as np

    n = len(cols["index"])
    for kind in ("target", "beacon"):
        cols[f"{kind}_height_px_meas"] = np.asarray(cols[f"{kind}_height_px_true"], float)
        cols[f"{kind}_contrast"] = rng.uniform(0.3, 0.8, n)
        cols[f"{kind}_noise"] = rng.uniform(0.005, 0.02, n)
        cols[f"{kind}_jpeg_quality"] = np.zeros(n)
    cols.setdefault("fx_px", np.full(n, 1500.0))
    cols.update(camera_height=np.full(n, 6.0), pencil_height_cm=np.full(n, 4.2),
                beacons=np.ones(n))
    return cols
