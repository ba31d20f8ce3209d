"""Renders that replay recorded kernels: Dr.Jit's ``freeze`` around ``mi.render``.

A render call traces Mitsuba's Python and C++ into kernels, then launches them (compiled
once: Dr.Jit caches kernels by their code).  A frozen call records its kernel launches
the first time it meets a configuration (the sensor's film size, the sample count) and
afterwards launches them straight away: a frame's tiles of one size share a recording
(``benchmarks/freeze.py`` measures what it saves).

The recordings live for one scene (:func:`frozen_renders`), never longer: a frozen
function matches a Mitsuba scene by its Python identity, and a process-wide one, given
a new scene at a freed scene's address, replayed kernels that pointed into the freed
scene (a segmentation fault, measured).  ``MIRRORSIM_FREEZE=0`` turns freezing off
(tests/test_render.py holds frames bit for bit the same either way); the scalar
variant, which has no kernels, never freezes.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
from collections.abc import Callable, Iterator

import drjit as dr
import mitsuba as mi

_SCOPES = 0  # frozen_renders scopes this process has opened
# the frozen render of the scene being rendered (None: outside frozen_renders); a new
# thread starts without one (it traces as usual), so one scope's recordings serve only
# the thread that opened it
_CURRENT: contextvars.ContextVar[Callable | None] = contextvars.ContextVar(
    "frozen_render", default=None)


def freezing() -> bool:
    """Whether renders replay recorded kernels: on a JIT variant, unless
    ``MIRRORSIM_FREEZE=0``."""
    return (os.environ.get("MIRRORSIM_FREEZE", "1") != "0"
            and mi.variant().startswith(("llvm", "cuda")))


def _frozen() -> Callable:
    """``mi.render`` frozen: the film's size and the sample count are static arguments
    (each records once); the seed is opaque (a new seed replays)."""
    @dr.freeze(warn_after=1 << 30)
    def render(mi_scene, sensor, spp: int, size: tuple[int, int], seed):  # noqa: ARG001
        return mi.render(mi_scene, sensor=sensor, spp=spp, seed=seed)
    return render


@contextlib.contextmanager
def frozen_renders() -> Iterator[None]:
    """Within this scope (one scene's renders), :func:`render_call` records and replays;
    the recordings are dropped at its end.  A process's first scope traces as usual:
    a process's first recordings cost more than one frame's replays save (measured on
    a full frame, each in a fresh process), so a one-frame command would only lose."""
    global _SCOPES
    _SCOPES += 1
    token = _CURRENT.set(_frozen() if freezing() and _SCOPES > 1 else None)
    try:
        yield
    finally:
        _CURRENT.reset(token)


def render_call(mi_scene: mi.Scene, sensor: mi.Sensor, *, spp: int, seed: int) -> mi.TensorXf:
    """One ``mi.render`` of ``sensor``'s film: replayed inside :func:`frozen_renders`
    where :func:`freezing` says so, else traced as usual."""
    frozen = _CURRENT.get()
    if frozen is None or not freezing():
        return mi.render(mi_scene, sensor=sensor, spp=spp, seed=seed)
    size = tuple(int(c) for c in sensor.film().crop_size())
    return frozen(mi_scene, sensor, spp, size, dr.opaque(mi.UInt32, seed))
