"""What the camera does after the pinhole: lens distortion, sensor noise, 8-bit sRGB.

No Mitsuba here: the renderer (:mod:`mirrorsim.rendering.passes`) applies distortion and noise to
its pinhole render, and the detector (:mod:`mirrorsim.detection.detector`) undoes a known
distortion with the same model.  Distortion is OpenCV's Brown–Conrady radial model:
a point at normalized radius r (r = |(u − cx, v − cy)| / fx on the ideal pinhole image)
is imaged at r·(1 + k1 r² + k2 r⁴).
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import cv2
import numpy as np

from mirrorsim.scene.model import Camera, SensorNoise
from mirrorsim.scene.projection import hfov_of, radial_factor

# fixed-point steps inverting the radial model at most (tested to 1e-6 px); it stops
# earlier where a step changes nothing (13 steps for exp1's lens: the same result)
UNDISTORT_ITERATIONS = 40


def _grid(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Normalized coordinates of every pixel centre."""
    u = (np.arange(camera.width) - camera.cx) / camera.fx
    v = (np.arange(camera.height_px) - camera.cy) / camera.fx
    return np.meshgrid(u, v)


def undistort_points(x: np.ndarray, y: np.ndarray, k: tuple[float, float]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The ideal normalized coordinates of distorted ones (inverts the radial model by
    fixed-point iteration; converges for the lenses :mod:`mirrorsim.formats.scenefile`
    accepts, whose r·(1 + k1 r² + k2 r⁴) grows over the frame)."""
    xu, yu = x.copy(), y.copy()
    for _ in range(UNDISTORT_ITERATIONS):
        f = radial_factor(xu, yu, k)
        nx, ny = x / f, y / f
        if np.array_equal(nx, xu) and np.array_equal(ny, yu):
            break  # a fixed point: every further step gives the same bits
        xu, yu = nx, ny
    return xu, yu


@functools.lru_cache(maxsize=4)  # one lens per dataset worker: built once
def _distort_maps(camera: Camera, k: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, int]:
    """For each pixel of the distorted frame, where to sample the pinhole render of a
    canvas ``margin`` px wider on every side; returns (map_u, map_v, margin)."""
    xd, yd = _grid(camera)
    xu, yu = undistort_points(xd, yd, k)
    mu, mv = camera.cx + camera.fx * xu, camera.cy + camera.fx * yu
    reach = max(-mu.min(), mu.max() - (camera.width - 1), -mv.min(),
                mv.max() - (camera.height_px - 1), 0.0)
    margin = int(math.ceil(reach)) + 2  # +2: the bilinear footprint stays on the canvas
    return ((mu + margin).astype(np.float32), (mv + margin).astype(np.float32), margin)


def distortion_canvas(camera: Camera, k: tuple[float, float]) -> tuple[Camera, int]:
    """The pinhole camera to render for a distorted frame: the same focal length and
    principal point, ``margin`` px more on every side (so every pixel of the distorted
    frame has something to sample)."""
    margin = _distort_maps(camera, k)[2]
    w, h = camera.width + 2 * margin, camera.height_px + 2 * margin
    hfov = hfov_of(w, camera.fx)
    return replace(camera, resolution=(w, h), hfov=hfov), margin


def distort(canvas: np.ndarray, camera: Camera, k: tuple[float, float],
            *, nearest: bool = False) -> np.ndarray:
    """The distorted frame (camera's size) from a pinhole render of
    :func:`distortion_canvas`: bilinear in linear radiance, or ``nearest`` (labels)."""
    mu, mv, _ = _distort_maps(camera, k)
    return cv2.remap(canvas, mu, mv, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR)


@functools.lru_cache(maxsize=4)  # one lens per camera: built once, not per frame
def _undistort_maps(camera: Camera, k: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel of the ideal pinhole frame, where the lens imaged it (closed form)."""
    xu, yu = _grid(camera)
    f = radial_factor(xu, yu, k)
    return ((camera.cx + camera.fx * xu * f).astype(np.float32),
            (camera.cy + camera.fx * yu * f).astype(np.float32))


def undistort(image: np.ndarray, camera: Camera, k: tuple[float, float]) -> np.ndarray:
    """The ideal pinhole frame from a distorted 8-bit sRGB one (the detector's first
    step for a calibrated lens): resampled bilinearly in linear radiance, so that edges
    keep their place."""
    mu, mv = _undistort_maps(camera, k)
    linear = srgb8_to_linear(image)
    out = cv2.remap(linear, mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return to_srgb8(out)


def add_noise(linear: np.ndarray, noise: SensorNoise, seed: int) -> np.ndarray:
    """Linear radiance as a sensor records it: the exposure puts ``full_well`` electrons
    at radiance 1; each pixel and channel gets Poisson shot noise on its electrons and
    Gaussian read noise, then saturates at the full well (seeded: same seed, same noise)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x6E6F697365]))
    electrons = rng.poisson(np.clip(linear, 0.0, None).astype(np.float64) * noise.full_well)
    electrons = electrons + rng.normal(0.0, noise.read_noise, linear.shape)
    return (np.clip(electrons, 0.0, noise.full_well) / noise.full_well).astype(np.float32)


def srgb8_to_linear(image: np.ndarray) -> np.ndarray:
    """8-bit sRGB → linear float32 (IEC 61966-2-1)."""
    return lookup_codes(image, _LINEAR_OF_CODE)


def lookup_codes(image: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``table[image]`` for 8-bit codes (an image of other dtype is cast to uint8):
    OpenCV's table lookup where it takes the shape (grey or 3–4 channels), the same
    values 20× faster than numpy's gather."""
    codes = np.asarray(image)
    if codes.dtype != np.uint8:
        codes = codes.astype(np.uint8)
    if codes.size and (codes.ndim == 2 or (codes.ndim == 3 and codes.shape[2] in (3, 4))):
        return cv2.LUT(codes, table)
    return table[codes]


def to_srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear RGB → 8-bit sRGB (IEC 61966-2-1 transfer curve), rounded.

    By lookup of the linear value where each 8-bit step begins (the curve is
    monotonic), compared as float32 bit patterns (ordered like the values for x ≥ 0;
    negative values sort below all steps, so map to 0 as clipping would): a table by the
    upper 16 bits, and a comparison with the one step's edge a bucket may hold.  The same
    codes as evaluating the curve and rounding (tests/test_render.py checks random values
    and both sides of every step's edge).
    """
    x = np.ascontiguousarray(linear, np.float32)
    bits = x.view(np.int32).reshape(-1)
    out = np.empty(bits.shape, np.uint8)
    # in chunks that stay in the cache, into buffers made once: twice as fast on a
    # full-size frame as whole-frame temporaries (benchmarks/pieces.py, "linear → sRGB")
    step = max(1, min(bits.size, SRGB_CHUNK))
    clipped, bucket = np.empty(step, np.int32), np.empty(step, np.int32)
    edge, past = np.empty(step, np.int32), np.empty(step, bool)
    for start in range(0, bits.size, step):
        n = min(step, bits.size - start)
        c, b, e, p, o = clipped[:n], bucket[:n], edge[:n], past[:n], out[start:start + n]
        # a table by the upper 16 bits (values beyond [0, 1] clipped, as the steps do)
        np.clip(bits[start:start + n], 0, _ONE_BITS, out=c)
        np.right_shift(c, 16, out=b)
        np.take(_BUCKET_CODE, b, out=o)
        np.take(_BUCKET_EDGE, b, out=e)
        np.greater_equal(c, e, out=p)
        o += p
    return out.reshape(x.shape)


def _srgb_steps() -> np.ndarray:
    """Bit patterns of the smallest float32 at which the rounded sRGB code becomes k,
    k = 1..255."""
    s = (np.arange(1, 256) - 0.5) / 255.0
    t = np.where(s <= 0.04045, s / 12.92, ((s + 0.055) / 1.055) ** 2.4)
    f = t.astype(np.float32)
    f = np.where(f.astype(np.float64) < t, np.nextafter(f, np.float32(np.inf)), f)
    return f.view(np.int32)


_SRGB_STEP_BITS = _srgb_steps()
SRGB_CHUNK = 1 << 15  # values converted at a time: 416 KiB of buffers
_ONE_BITS = int(np.float32(1.0).view(np.int32))
_BUCKET_STARTS = np.arange((_ONE_BITS >> 16) + 1, dtype=np.int64) << 16
_BUCKET_CODE = np.searchsorted(_SRGB_STEP_BITS, _BUCKET_STARTS, side="right").astype(np.uint8)
# a bucket spans 2¹⁶ float32 values: at most one step's edge falls in it (the steps are
# wider than a bucket everywhere in [0, 1]; checked here), found at the bucket's code
_n_edges = np.searchsorted(_SRGB_STEP_BITS, _BUCKET_STARTS + 0xFFFF, side="right") - _BUCKET_CODE
assert _n_edges.max() <= 1, "two sRGB steps in one bucket"
_BUCKET_EDGE = np.where(_n_edges == 1, _SRGB_STEP_BITS[np.minimum(_BUCKET_CODE, 254)],
                        np.iinfo(np.int32).max).astype(np.int32)
_CODES = np.arange(256) / 255.0
# linear radiance of each 8-bit code, float64 (the detector scales it to 0–255)
LINEAR_OF_CODE = np.where(_CODES <= 0.04045, _CODES / 12.92, ((_CODES + 0.055) / 1.055) ** 2.4)
_LINEAR_OF_CODE = LINEAR_OF_CODE.astype(np.float32)
