"""Benchmark: what replaying recorded kernels (Dr.Jit's freeze) saves, and the cached
code fingerprint of the calibration key.

    python benchmarks/freeze.py [--frames 6] [--fresh 3]

- A full-size default frame's render calls and the recordings they make (freezing on);
- ``--frames`` frames of the default scene (each its own seed) in one warm process,
  freezing on and off alternately (``MIRRORSIM_FREEZE``): each frame's render time;
- a process's first frame, freezing on and off, each in ``--fresh`` fresh processes
  (a process's first frame is traced either way: the two should agree);
- finding the modules a calibration's K depends on (parsing their imports) against
  reading the cached answer.
Stamped with commit, date and machine.
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import subprocess
import sys
import time

from clone import ROOT  # noqa: E402  (the clone first on sys.path)
from stamp import stamp  # noqa: E402

FIRST_FRAME = (
    "import sys, time, copy, yaml; sys.path.insert(0, {root!r})\n"
    "from mirrorsim.pipelines.scenes import scene_from_dict\n"
    "from mirrorsim.rendering.passes import render_frame\n"
    "d = yaml.safe_load(open({root!r} + '/scenes/default.yaml'))\n"
    "d['render'] = {{**d.get('render', {{}}), 'seed': {seed}}}\n"
    "s = scene_from_dict(d, 'default.yaml', 'default')\n"
    "t = time.perf_counter(); render_frame(s, progress=False)\n"
    "print(time.perf_counter() - t)\n")


def _scene(seed: int):
    import yaml

    from mirrorsim.pipelines.scenes import scene_from_dict

    d = copy.deepcopy(yaml.safe_load((ROOT / "scenes" / "default.yaml").read_text()))
    d["render"] = {**d.get("render", {}), "seed": seed}
    return scene_from_dict(d, "default.yaml", "default")


def _warm(frames: int) -> tuple[int, int, dict[str, float]]:
    """Calls and recordings of one frozen frame; median render time per mode."""
    from mirrorsim.rendering import frozen, passes

    calls, made = [0], []
    call, make = passes.render_call, frozen._frozen

    def counted(*a, **k):
        calls[0] += frozen._CURRENT.get() is not None
        return call(*a, **k)

    def kept():
        made.append(make())
        return made[-1]

    passes.render_call, frozen._frozen = counted, kept
    passes.render_frame(_scene(1), progress=False)  # the process's first frame: traced
    times: dict[str, list[float]] = {"1": [], "0": []}
    for k in range(2 * frames):
        mode = "10"[k % 2]
        os.environ["MIRRORSIM_FREEZE"] = mode
        calls[0], made[:] = 0, []
        t = time.perf_counter()
        passes.render_frame(_scene(100 + k), progress=False)
        times[mode].append(time.perf_counter() - t)
        if mode == "1":
            frozen_calls, recordings = calls[0], sum(f.n_recordings for f in made)
    os.environ.pop("MIRRORSIM_FREEZE")
    return frozen_calls, recordings, {m: statistics.median(v) for m, v in times.items()}


def _first_frames(fresh: int) -> dict[str, float]:
    out: dict[str, list[float]] = {"1": [], "0": []}
    for k in range(fresh):
        for mode in ("10" if k % 2 else "01"):  # either first in turn
            code = FIRST_FRAME.format(root=str(ROOT), seed=1000 + 2 * k + int(mode))
            done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                  env={**os.environ, "MIRRORSIM_FREEZE": mode}, check=True)
            out[mode].append(float(done.stdout.split()[-1]))
    return {m: statistics.median(v) for m, v in out.items()}


def _fingerprint() -> tuple[float, float]:
    from mirrorsim.pipelines import calibrate

    t = time.perf_counter()
    calibrate.code_modules()
    found = time.perf_counter() - t
    calibrate.code_fingerprint()  # cached now, if it was not
    calibrate.code_fingerprint.cache_clear()
    t = time.perf_counter()
    calibrate.code_fingerprint()
    return found, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--fresh", type=int, default=3)
    a = ap.parse_args()
    print(stamp(), "\n")
    calls, recordings, warm = _warm(a.frames)
    first = _first_frames(a.fresh)
    found, cached = _fingerprint()
    print("| measure | freezing on | freezing off |\n|---|---|---|")
    print(f"| a full-size default frame's frozen render calls / recordings | {calls} / "
          f"{recordings} | – |")
    print(f"| a frame in a warm process, median of {a.frames} (s) | {warm['1']:.3f} | "
          f"{warm['0']:.3f} |")
    print(f"| a process's first frame, median of {a.fresh} fresh processes (s) | "
          f"{first['1']:.3f} | {first['0']:.3f} |")
    print(f"\nThe calibration key's code fingerprint: finding its modules {found:.3f} s, "
          f"reading the cached answer {cached * 1000:.1f} ms.")


if __name__ == "__main__":
    main()
