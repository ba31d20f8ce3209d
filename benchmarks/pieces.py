"""Benchmark: what one dataset scene's pieces cost, in one warm process.

    python benchmarks/pieces.py [--scenes 8] [--rss 0] [--ratio 0] [--seed S]

Times (median over ``--scenes`` scenes of the default spec, after one warm-up scene):
drawing a valid scene, the board texture, the render at the spec's settings, the id
pass, linear → sRGB, PNG encoding, detection; then (``--rss N``) the process's resident
memory after each of N whole dataset scenes; then (``--ratio N``) for N scenes of a
fresh seed (or ``--seed``'s: two versions compared on the same scenes), a whole dataset
scene's wall time against the bare render of its passes (the scene loaded beforehand,
the same ``mi.render`` calls, warm kernels) in the same process.  Runs on older
checkouts too (it looks up what each has), so that before/after figures come from the
same script.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import clone  # noqa: F401  (the clone first on sys.path)
import numpy as np

from mirrorsim.detection.detector import detect_frame  # noqa: E402
from mirrorsim.pipelines.calibrate import calibrate  # noqa: E402
from mirrorsim.pipelines.random_scenes import load_spec, sample_scene  # noqa: E402
from mirrorsim.rendering import mitsuba_scene  # noqa: E402
from mirrorsim.rendering import passes as render  # noqa: E402
from mirrorsim.truth import optics  # noqa: E402


def _png_writer():
    from mirrorsim.formats.files import encode_png
    return lambda px, path: Path(path).write_bytes(encode_png(px))


def _timed(fn, *args):
    t = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=8)
    ap.add_argument("--rss", type=int, default=0)
    ap.add_argument("--ratio", type=int, default=0)
    ap.add_argument("--seed", type=int,
                    help="the ratio's scenes (default: a fresh seed, printed; give one to "
                         "compare two versions on the same scenes)")
    a = ap.parse_args()
    spec = load_spec(None)
    write_png = _png_writer()
    times: dict[str, list[float]] = {}
    tmp = Path(tempfile.mkdtemp())
    for i in range(a.scenes + 1):
        scene, t_draw = _timed(sample_scene, spec, np.random.SeedSequence(0, spawn_key=(i,)),
                               f"s{i}")
        board = replace(scene.board)  # a new object: a cache keyed by value still hits
        fn = getattr(mitsuba_scene._board_texture, "__wrapped__", mitsuba_scene._board_texture)
        _, t_tex = _timed(fn, board)
        frame = render.render_frame(scene.with_render(seed=i), progress=False)
        srgb, t_srgb = _timed(render.to_srgb8, frame.linear)
        _, t_png = _timed(write_png, srgb, tmp / "f.png")
        from mirrorsim.formats.capture import CaptureRecord
        cap = CaptureRecord.from_scene(scene, frame="f.png")
        cal = calibrate(cap.camera, cap.target_size, cap.beacons[0].height)
        _, t_det = _timed(detect_frame, srgb, cap, cal)
        box = optics.mirror_box(scene)
        share = 0.0 if box is None else (
            (box[2] - box[0]) * (box[3] - box[1]) / (scene.camera.width * scene.camera.height_px))
        if i == 0:
            continue  # warm-up: imports, kernels, calibration
        for k, v in (("draw a valid scene", t_draw), ("board texture (uncached)", t_tex),
                     ("render + id pass", frame.info.seconds_total),
                     ("render (path tracing)", frame.info.seconds_render),
                     ("linear → sRGB", t_srgb), ("PNG encode + write", t_png),
                     ("detection", t_det), ("mirror's box, share of the frame", share)):
            times.setdefault(k, []).append(v)
    settings = f"{scene.render.sampler if hasattr(scene.render, 'sampler') else 'independent'}"
    print(f"pieces of a dataset scene, default spec ({settings}, {scene.render.spp} spp), "
          f"1920×1088, median of {a.scenes}; {platform.machine()}, {os.cpu_count()} cores\n")
    print("| piece | seconds (share: fraction) |\n|---|---|")
    for k, v in times.items():
        print(f"| {k} | {statistics.median(v):.3f} |")
    if a.rss:
        from mirrorsim.pipelines.dataset import process_one
        for d in ("rows", "scenes", "frames"):
            (tmp / "ds" / d).mkdir(parents=True)
        print("\n| dataset scenes done in this process | resident memory (MiB) |\n|---|---|")
        rss = []
        for i in range(a.rss):
            process_one(i, 0, spec, out=str(tmp / "ds"), spp=None, variant="auto")
            with open("/proc/self/statm") as f:
                rss.append(int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20)
            if i in (0, 1, 4, 9) or i == a.rss - 1 or (i + 1) % 10 == 0:
                print(f"| {i + 1} | {rss[-1]:.0f} |")
        if a.rss > 2:  # the first scene loads Mitsuba's and the kernels' memory
            print(f"\ngrowth after the first scene: "
                  f"{(rss[-1] - rss[0]) / (a.rss - 1):.2f} MiB a scene")
    if a.ratio:
        _ratio(spec, a.ratio, tmp / "ratio", a.seed)


def _bare_render(scene) -> float:
    """Seconds of the ``mi.render`` calls of ``scene``'s passes alone: the whole film,
    then each tile (aimed as mirrorsim aims it), each evaluated; the scene is loaded
    before the clock starts."""
    import drjit as dr
    import mitsuba as mi

    spp = scene.render.spp
    box, background, _, _, passes = render._regions(scene, spp)  # what render_frame does
    tiles = tuple(sorted({t for *_, t in passes}))
    mi_scene = mi.load_dict(mitsuba_scene.build_scene_dict(scene, tiles), optimize=False)
    sensors = {s.id(): s for s in mi_scene.sensors()}
    t0 = time.perf_counter()
    dr.eval(mi.render(mi_scene, sensor=sensors["sensor"],
                      spp=spp if box is None else background, seed=1))
    dr.sync_thread()
    for (u0, v0, u1, v1), n, _, t in passes:
        sensor = sensors[f"sensor_tile{t}"]
        params = mi.traverse(sensor)
        for v in range(v0, v1, t):
            for u in range(u0, u1, t):
                mitsuba_scene.aim_tile(params, scene.camera, t, u0=u, v0=v)
                per = render._tile_pass(n, t)  # samples per call, as mirrorsim splits them
                for k, m in enumerate([per] * (n // per) + ([n % per] if n % per else [])):
                    dr.eval(mi.render(mi_scene, sensor=sensor, spp=m, seed=2 + k))
                    dr.sync_thread()
    return time.perf_counter() - t0


def _ratio(spec, n: int, tmp: Path, seed: int | None = None) -> None:
    from mirrorsim.pipelines.dataset import process_one
    from mirrorsim.pipelines.random_scenes import sample_scene as draw

    for d in ("rows", "scenes", "frames"):
        (tmp / d).mkdir(parents=True)
    seed = int.from_bytes(os.urandom(3), "big") if seed is None else seed
    print(f"\nseed {seed}: a whole dataset scene (draw, render, detect, solve, score, "
          "write) against the bare render of its passes\n")
    print("| scene | whole (s) | bare render (s) | ratio |\n|---|---|---|---|")
    ratios = []
    for i in range(n + 1):
        t0 = time.perf_counter()
        process_one(i, seed, spec, out=str(tmp), spp=None, variant="auto")
        whole = time.perf_counter() - t0
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(i,)))
        bare = _bare_render(draw(spec, rng, f"r{i}").with_render(seed=i))
        if i == 0:
            continue  # warm-up
        ratios.append(whole / bare)
        print(f"| {i} | {whole:.2f} | {bare:.2f} | {whole / bare:.2f} |")
    print(f"| median | | | {statistics.median(ratios):.2f} |")


if __name__ == "__main__":
    main()
