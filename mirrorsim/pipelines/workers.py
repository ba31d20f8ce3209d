"""Running many scenes in long-lived worker processes (or on a Dask cluster), safe to
interrupt.

* Warm workers: each worker process imports Mitsuba and compiles its kernels once, then
  takes scene after scene (Dr.Jit's kernel cache serves every later scene of the same
  structure).  A worker retires when its resident memory passes ``max_rss_mb`` and a
  fresh one takes its place (Mitsuba leaked when scenes were reloaded, mitsuba3 #1890;
  measured here, no growth over 30 scenes: README "Throughput").
* Only the parent process handles Ctrl-C: workers start with SIGINT blocked (the
  signal mask survives ``spawn``'s exec) and then ignore it, so an interrupt can never
  land inside a worker and be mistaken for the scene's failure.  On Ctrl-C the parent
  kills its workers at once and stops; nothing they were doing is recorded.
* A worker that dies (killed, out of memory) is replaced; its job goes to another
  worker unless ``is_done`` says it finished.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from multiprocessing.connection import Connection, wait

from mirrorsim.errors import RunFailed, one_line_warning

MAX_WORKER_DEATHS = 3


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


def rss_mb() -> float:
    """Resident memory of the calling process now (MiB; Linux), or 0 if unreadable."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return 0.0
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def _worker(conn: Connection, fn: Callable, max_rss_mb: float) -> None:
    """A worker's life: jobs in, (ok, value, retiring) out, until told to stop (None) or
    its memory passes the limit."""
    _ignore_sigint()
    warnings.showwarning = one_line_warning  # as the parent shows them
    while True:
        try:
            job = conn.recv()
        except EOFError:  # the parent is gone
            return
        if job is None:
            return
        try:
            value, ok = fn(*job), True
        except Exception as exc:  # the parent re-raises it, as a pool's future would
            value, ok = exc, False
        retiring = max_rss_mb > 0 and rss_mb() > max_rss_mb
        conn.send((ok, value, retiring))
        if retiring:
            return


class _Slot:
    """One worker process, its pipe and the job it holds."""

    def __init__(self, ctx, fn: Callable, max_rss_mb: float):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, fn, max_rss_mb), daemon=True)
        self.proc.start()
        child.close()
        self.job: tuple | None = None


def run_local(fn: Callable, jobs: list[tuple], workers: int, is_done: Callable[[int], bool],
              on_result: Callable[[object], None], max_rss_mb: float = 0.0) -> None:
    """Call ``fn(*job)`` for each job in ``workers`` warm processes; ``on_result`` gets
    each return value.  A worker past ``max_rss_mb`` MiB (0: no limit) retires after its
    job; one that dies is replaced and its job, unless ``is_done(index)`` (the index is
    a job's first element), given to the next free worker."""
    ctx = mp.get_context("spawn")  # a fresh interpreter: no inherited Mitsuba state
    pending = deque(jobs)
    slots: list[_Slot] = []
    deaths = 0

    def start() -> None:
        with _sigint_held():
            slots.append(_Slot(ctx, fn, max_rss_mb))

    try:
        for _ in range(min(workers, len(pending))):
            start()
        while pending or any(s.job is not None for s in slots):
            for s in [s for s in slots if s.job is None]:
                if pending:
                    s.job = pending.popleft()
                    with contextlib.suppress(OSError):  # a dead worker: found below
                        s.conn.send(s.job)
            busy = [s for s in slots if s.job is not None]
            ready = set(wait([s.conn for s in busy] + [s.proc.sentinel for s in busy]))
            for s in busy:
                if s.conn in ready or s.proc.sentinel in ready:
                    deaths += _collect(s, slots, pending, is_done, on_result)
                    if deaths > MAX_WORKER_DEATHS:
                        raise RunFailed("worker processes keep dying; the rows done so far "
                                        "are kept")
            # replace retired and dead workers while there is work for them
            while len(slots) < workers and len(pending) > sum(s.job is None for s in slots):
                start()
        for s in slots:
            s.conn.send(None)
        for s in slots:
            s.proc.join(timeout=30)
    except BaseException:  # Ctrl-C above all: the workers stop now, not after their scene
        for s in slots:
            with contextlib.suppress(Exception):
                s.proc.kill()
        raise


def _collect(s: _Slot, slots: list[_Slot], pending: deque, is_done: Callable[[int], bool],
             on_result: Callable[[object], None]) -> int:
    """Take a ready worker's result, or bury it; returns 1 for a death, else 0."""
    try:
        ok, value, retiring = s.conn.recv()
    except (EOFError, OSError):  # died without an answer
        slots.remove(s)
        s.proc.join(timeout=5)
        if not is_done(s.job[0]):
            pending.appendleft(s.job)
        print("\nwarning: a worker process died; a new one takes the unfinished scenes",
              file=sys.stderr)
        return 1
    s.job = None
    if retiring:
        slots.remove(s)
        s.proc.join(timeout=30)
    if not ok:
        raise value
    on_result(value)
    return 0


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
