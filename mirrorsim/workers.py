"""Running many scenes in worker processes (or on a Dask cluster), safe to interrupt.

* Only the parent process handles Ctrl-C: workers start with SIGINT blocked (the
  signal mask survives ``spawn``'s exec) and then ignore it, so an interrupt can never
  land inside a worker and be mistaken for the scene's failure.  On Ctrl-C the parent
  kills its workers at once and stops; nothing they were doing is recorded.
* A worker that dies (killed, out of memory) breaks its pool; a new pool takes the
  scenes that have no row yet.
* Pools are replaced every ``recycle_every`` scenes per worker (Mitsuba leaks when
  scenes are reloaded in one process; ProcessPoolExecutor's own max_tasks_per_child
  hangs on Python 3.11 once its first workers retire).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import signal
import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from mirrorsim.errors import RunFailed

MAX_POOL_DEATHS = 3


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@contextlib.contextmanager
def _sigint_held() -> Iterator[None]:
    """Hold Ctrl-C back while workers are started (they inherit the mask); an interrupt
    meanwhile is delivered to the parent when the block ends."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def run_local(fn: Callable, jobs: list[tuple], workers: int, is_done: Callable[[int], bool],
              on_result: Callable[[object], None], recycle_every: int) -> None:
    """Call ``fn(*job)`` for each job in ``workers`` processes; ``on_result`` gets each
    return value.  After a worker's death the jobs of its pool for which ``is_done(index)``
    is false (the index is a job's first element) go to a new pool."""
    ctx = mp.get_context("spawn")  # a fresh interpreter: no inherited Mitsuba state
    deaths = 0
    remaining = list(jobs)
    while remaining:
        chunk, rest = remaining[:workers * recycle_every], remaining[workers * recycle_every:]
        ex = None
        try:
            with _sigint_held():
                ex = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_ignore_sigint)
                futures = [ex.submit(fn, *j) for j in chunk]
            for f in as_completed(futures):
                on_result(f.result())
            ex.shutdown(wait=True)
            remaining = rest
        except BrokenProcessPool:
            _stop(ex)
            deaths += 1
            if deaths > MAX_POOL_DEATHS:
                raise RunFailed("worker processes keep dying; the rows done so far are "
                                "kept (rerun with --resume)") from None
            print("\nwarning: a worker process died; a new pool takes the unfinished "
                  "scenes", file=sys.stderr)
            remaining = [j for j in chunk if not is_done(j[0])] + rest
        except BaseException:  # Ctrl-C above all: the workers stop now, not after their scene
            _stop(ex)
            raise


def _stop(ex: ProcessPoolExecutor | None) -> None:
    """Kill the pool's workers and let its manager thread finish (no join on them)."""
    if ex is None:
        return
    for p in list(getattr(ex, "_processes", {}).values()):
        with contextlib.suppress(Exception):
            p.kill()
    ex.shutdown(wait=False, cancel_futures=True)


def run_dask(fn: Callable, jobs: Iterable[tuple], scheduler: str | None,
             on_result: Callable[[object], None]) -> None:
    """The same on a Dask cluster (a local one when no scheduler is given)."""
    from dask.distributed import Client, LocalCluster
    from dask.distributed import as_completed as dask_completed

    cluster = None
    with _sigint_held():
        if scheduler is None:
            cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True)
            client = Client(cluster)
        else:
            client = Client(scheduler)
    try:
        futures = [client.submit(fn, *j, pure=False) for j in jobs]
        for f in dask_completed(futures):
            on_result(f.result())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
