"""Choosing a Mitsuba variant that works on this machine, without ever crashing.

``llvm_ad_rgb`` aborts the whole process (SIGABRT inside LLVM's instruction
selection) when drjit finds libLLVM 15 or 16; ``mi.set_variant`` succeeds and the
crash comes at the first kernel.  So each JIT variant is tried in a child process
that renders a tiny mirror scene, and the answer is cached per machine and software
(so the probe runs once, not on every command).  A crash of the probe (an abort, a
segmentation fault, an error) is a verdict; a probe killed from outside (the OOM
killer's SIGKILL, a SIGTERM) says nothing about the variant and is not cached.
"""

from __future__ import annotations

import hashlib
import os
import platform
import signal
import subprocess
import sys
import warnings
from importlib import metadata
from pathlib import Path

from mirrorsim.errors import BackendError, BadParameter
from mirrorsim.formats.cache import read_entry, write_entry

VARIANTS = {"cuda": "cuda_ad_rgb", "llvm": "llvm_ad_rgb", "scalar": "scalar_rgb"}
PROBE_TIMEOUT_S = 180
# signals that end a process from outside: its death is no verdict on the variant
NOT_A_VERDICT = frozenset({signal.SIGKILL, signal.SIGTERM, signal.SIGINT, signal.SIGHUP,
                           signal.SIGQUIT})
FAST_PATH_HINT = (
    "the fast LLVM backend is unavailable, rendering with scalar_rgb (about 5-10x slower); "
    "to get it, install libLLVM 19 (Debian/Ubuntu: `apt-get install libllvm19`) or point "
    "DRJIT_LIBLLVM_PATH at a working libLLVM"
)

# A tiny scene with the features our renders use: a conductor mirror, a mesh-free
# cube, an area light and a box filter.  Rendering it compiles the kernels that crash.
_PROBE_CODE = r"""
import sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "path", "max_depth": 4},
    "sensor": {"type": "perspective", "fov": 45,
               "to_world": mi.ScalarTransform4f().look_at(origin=[0, -4, 1], target=[0, 0, 0],
                                                           up=[0, 0, 1]),
               "film": {"type": "hdrfilm", "width": 8, "height": 6,
                        "rfilter": {"type": "box"}}},
    "mirror": {"type": "rectangle", "bsdf": {"type": "conductor"}},
    "cube": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0, -1, 0.5])
                                            .scale(0.3)},
    "light": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 4]),
              "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 5.0}}},
})
image = mi.render(scene, spp=4)
import numpy as np
assert np.isfinite(np.asarray(image)).all()
print("mirrorsim-probe-ok")
"""


def _machine_key(variant: str) -> str:
    """What a probe's answer depends on: machine, Python, package versions, LLVM choice."""
    parts = [
        variant,
        platform.node(),
        platform.machine(),
        sys.executable,
        _version("mitsuba"),
        _version("drjit"),
        os.environ.get("DRJIT_LIBLLVM_PATH", ""),
        os.environ.get("CUDA_VISIBLE_DEVICES", ""),
        # a newly installed libLLVM changes what drjit finds
        ",".join(sorted(p.name for p in _llvm_dirs())),
    ]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]


def _llvm_dirs() -> list[Path]:
    found = []
    for d in ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib",
              "/usr/local/lib"):
        try:
            found += [p for p in Path(d).glob("libLLVM*.so*")]
        except OSError:
            pass
    return found


def _version(pkg: str) -> str:
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return "?"


def probe(variant: str, *, use_cache: bool = True) -> tuple[bool, str]:
    """Whether ``variant`` renders here, tried in a child process.

    Returns
    -------
    ok : bool
    detail : str
        Why not, when it does not (the child's last line of output or its signal).
    """
    key = f"{variant}|{_machine_key(variant)}"
    found = read_entry("backend", key, _check_answer) if use_cache else None
    if found is not None:
        return found["ok"], found["detail"]
    ok, detail, verdict = _run_probe(variant)
    if verdict:
        write_entry("backend", key, {"variant": variant, "ok": ok, "detail": detail})
    return ok, detail


def _check_answer(value: dict) -> None:
    if not isinstance(value["ok"], bool) or not isinstance(value["detail"], str):
        raise TypeError("ok must be true or false and detail a text")


def _run_probe(variant: str) -> tuple[bool, str, bool]:
    """(works, why not, whether that is a verdict worth caching)."""
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBE_CODE, variant],
            capture_output=True, text=True, timeout=PROBE_TIMEOUT_S,
        )
    except subprocess.TimeoutExpired:
        return False, f"probe timed out after {PROBE_TIMEOUT_S} s", True
    if proc.returncode == 0 and "mirrorsim-probe-ok" in proc.stdout:
        return True, "", True
    lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
    # LLVM's crash dump is long: its first line says what happened
    first_error = next((ln for ln in lines if "ERROR" in ln or "Error" in ln), None)
    why = first_error or (lines[-1] if lines else "")
    code = proc.returncode
    if code < 0 and -code in NOT_A_VERDICT:
        return False, (f"the probe was killed by signal {-code} (not a verdict: tried again "
                       "next run)"), False
    status = f"killed by signal {-code}" if code < 0 else f"exit status {code}"
    return False, f"{status}: {why.strip()[:200]}", True


def check_variant(requested: str) -> None:
    """Refuse (:class:`BadParameter`, bad input) a variant name that is none of
    ``auto``, ``cuda``, ``llvm``, ``scalar`` or a full Mitsuba name of one: before a run
    claims its folder."""
    if requested != "auto" and requested not in VARIANTS and requested not in VARIANTS.values():
        raise BadParameter("variant", f"{requested!r}: use auto, cuda, llvm or scalar")


def choose_variant(requested: str = "auto") -> str:
    """The Mitsuba variant to render with.

    ``auto``: ``cuda_ad_rgb`` where a GPU works, else ``llvm_ad_rgb`` where the probe
    renders, else ``scalar_rgb`` with one warning on how to get the fast path.
    ``cuda`` / ``llvm``: that one, or :class:`BackendError` if its probe fails.
    ``scalar``: always works.
    """
    if requested in VARIANTS.values():
        requested = next(k for k, v in VARIANTS.items() if v == requested)
    if requested == "scalar":
        return VARIANTS["scalar"]
    if requested in ("cuda", "llvm"):
        ok, detail = probe(VARIANTS[requested])
        if not ok:
            hint = f"; {FAST_PATH_HINT.split('; ', 1)[1]}" if requested == "llvm" else ""
            raise BackendError(f"variant {VARIANTS[requested]} does not work here "
                               f"({detail}){hint}")
        return VARIANTS[requested]
    check_variant(requested)
    if _maybe_gpu() and probe(VARIANTS["cuda"])[0]:
        return VARIANTS["cuda"]
    if probe(VARIANTS["llvm"])[0]:
        return VARIANTS["llvm"]
    warnings.warn(FAST_PATH_HINT, RuntimeWarning, stacklevel=2)
    return VARIANTS["scalar"]


def set_render_threads(threads: int) -> None:
    """Have this process's renders run on ``threads`` threads (at least one).

    Dr.Jit's LLVM backend runs one thread per core in every process: two dataset
    workers on two cores ran four render threads, which contend (a new dataset of 24
    scenes, 2 workers: about 6 % faster with one thread each, benchmarks/dataset.py).
    """
    import drjit as dr  # a worker's first scene imports it anyway

    dr.set_thread_count(max(1, threads))


def _maybe_gpu() -> bool:
    """Cheap pre-check so machines without NVIDIA drivers skip the CUDA probe."""
    if os.environ.get("CUDA_VISIBLE_DEVICES", None) in ("", "-1"):
        return False
    return any(Path(p).exists() for p in ("/dev/nvidiactl", "/proc/driver/nvidia/version"))
