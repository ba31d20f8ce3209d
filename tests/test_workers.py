"""Warm worker processes: a worker renders scene after scene exactly as a fresh process
would, retires past its memory limit, and is replaced when it dies."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

from mirrorsim.pipelines.workers import rss_mb, run_local
from tests.conftest import small_scene

_HELD: list[bytearray] = []


def _grow(i: int, mb: int) -> tuple[int, int]:
    """Hold ``mb`` MiB more for the worker's life; say which process did job i."""
    _HELD.append(bytearray(os.urandom(1) * (mb << 20)))
    return i, os.getpid()


def _rss(i: int) -> tuple[int, float]:
    return i, rss_mb()


def _die_once(i: int, marker: str) -> tuple[int, int]:
    """The first worker to take job 1 dies without an answer (as kill -9 would)."""
    if i == 1 and not Path(marker).exists():
        Path(marker).touch()
        os._exit(9)
    return i, os.getpid()


def _fail(i: int) -> int:
    if i == 2:
        raise ValueError("job 2 is bad")
    return i


def _run(fn, jobs, workers=1, max_rss_mb=0.0):
    got = []
    run_local(fn, jobs, workers, is_done=lambda i: any(g[0] == i for g in got),
              on_result=got.append,
              max_rss_mb=max_rss_mb)
    return got


def test_a_warm_worker_takes_every_job_without_a_limit():
    got = _run(_grow, [(i, 1) for i in range(5)])
    assert sorted(i for i, _ in got) == list(range(5))
    assert len({pid for _, pid in got}) == 1  # one process did them all


def _mark_setup() -> None:
    os.environ["MIRRORSIM_TEST_SETUP"] = str(os.getpid())


def _setup_seen(i: int) -> tuple[int, str, int]:
    return i, os.environ.get("MIRRORSIM_TEST_SETUP", ""), os.getpid()


def test_each_worker_runs_its_setup_before_its_first_job():
    """Two workers, each with its own setup: every job sees its own process's mark, and
    the parent's environment is untouched."""
    got = []
    run_local(_setup_seen, [(i,) for i in range(4)], 2,
              is_done=lambda i: any(g[0] == i for g in got),
              on_result=got.append, setup=_mark_setup)
    assert sorted(i for i, *_ in got) == list(range(4))
    assert all(mark == str(pid) for _, mark, pid in got)
    assert "MIRRORSIM_TEST_SETUP" not in os.environ


def test_renders_run_on_the_threads_they_are_given():
    """set_render_threads sets Dr.Jit's thread pool, one thread at least."""
    import drjit as dr

    from mirrorsim.rendering.backend import set_render_threads

    before = dr.thread_count()
    try:
        set_render_threads(3)
        assert dr.thread_count() == 3
        set_render_threads(0)  # more workers than cores
        assert dr.thread_count() == 1
    finally:
        dr.set_thread_count(before)


def test_a_worker_retires_after_its_bounded_number_of_jobs():
    """Memory or not, a worker retires after max_jobs (Dr.Jit's kernels of new scenes
    pile up): 7 jobs at 3 a worker take 3 processes, in order, none lost."""
    got = []
    run_local(_grow, [(i, 0) for i in range(7)], 1, is_done=lambda i: any(g[0] == i for g in got),
              on_result=got.append, max_rss_mb=0.0, max_jobs=3)
    assert [i for i, _ in got] == list(range(7))
    pids = [pid for _, pid in got]
    assert [len(set(pids[k:k + 3])) for k in (0, 3, 6)] == [1, 1, 1]
    assert len(set(pids)) == 3


def test_a_worker_past_its_memory_limit_is_replaced():
    # each job holds 64 MiB more; a limit 100 MiB above a fresh worker's footprint lets
    # a worker finish one or two jobs before it retires
    limit = _run(_rss, [(0,)])[0][1] + 100
    got = _run(_grow, [(i, 64) for i in range(6)], workers=2, max_rss_mb=limit)
    assert sorted(i for i, _ in got) == list(range(6))  # each once, none lost
    assert len({pid for _, pid in got}) >= 3


def test_a_dead_workers_job_is_redone_once(tmp_path, capsys):
    got = _run(_die_once, [(i, str(tmp_path / "died")) for i in range(4)], workers=2)
    assert sorted(i for i, _ in got) == [0, 1, 2, 3]
    assert "a worker process died" in capsys.readouterr().err


def test_an_exception_in_a_job_reaches_the_caller():
    with pytest.raises(ValueError, match="job 2 is bad"):
        _run(_fail, [(i,) for i in range(4)])


def _render_digest(i: int, name: str, variant: str) -> tuple[int, str, int]:
    from mirrorsim.rendering.passes import render_frame

    scene = small_scene(name, 160, 91, spp=4, sampler="multijitter")
    f = render_frame(scene.with_render(spp=4, seed=i), variant=variant, progress=False)
    data = b"".join(np.ascontiguousarray(a).tobytes() for a in (f.linear, f.first,
                                                                f.in_mirror))
    return i, hashlib.sha256(data).hexdigest(), os.getpid()


def test_a_warm_worker_renders_like_fresh_processes(fast_variant):
    jobs = [(i, name, fast_variant) for i, name in enumerate(("exp1", "default", "exp3",
                                                              "exp1"))]
    warm = _run(_render_digest, jobs)
    fresh = _run(_render_digest, jobs, max_rss_mb=1)  # every worker retires after a job
    assert len({pid for *_, pid in warm}) == 1
    assert len({pid for *_, pid in fresh}) == len(jobs)
    assert sorted(d[:2] for d in warm) == sorted(d[:2] for d in fresh)
