"""Running many scenes in long-lived worker processes (or on a Dask cluster), safe to
interrupt.

* Warm workers: each worker process imports Mitsuba once, then takes scene after
  scene.  A worker retires when its resident memory passes ``max_rss_mb`` or after
  MAX_JOBS_PER_WORKER scenes, and a fresh one takes its place (Dr.Jit keeps every new
  scene's kernels in memory).
* Only the parent process handles Ctrl-C: workers start with SIGINT blocked (the
  signal mask survives ``spawn``'s exec) and then ignore it, so an interrupt can never
  land inside a worker and be mistaken for the scene's failure.  On Ctrl-C the parent
  kills its workers at once and stops; nothing they were doing is recorded.
* A worker that dies (killed, out of memory) is replaced; its job goes to another
  worker unless ``is_done`` says it finished.  A parent that dies (SIGKILL; SIGTERM is
  handled as Ctrl-C is) takes its workers with it (Linux: PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import contextlib
import ctypes
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
# a worker retires after this many scenes whatever its memory: Dr.Jit keeps each new
# scene's kernels (~2 MiB a scene measured), so a long-lived worker grows without bound
MAX_JOBS_PER_WORKER = 100
# the memory a worker needs: ~500 MiB measured warm after a full-size scene
# (docs/performance.md), doubled for the passes of larger frames
WORKER_MEMORY_MB = 1024
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


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


def _die_with(parent: int) -> None:
    """Have the kernel kill this process when its parent dies (Linux's
    PR_SET_PDEATHSIG): a parent killed by SIGKILL leaves no worker finishing a scene
    that nobody will collect."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the parent died before the request was made
        os._exit(1)


def available_mb() -> float | None:
    """The memory available to new processes (Linux's MemAvailable, MiB), or None."""
    try:
        with open("/proc/meminfo") as f:
            return next(int(line.split()[1]) for line in f
                        if line.startswith("MemAvailable:")) / 1024
    except (OSError, StopIteration, ValueError, IndexError):
        return None


def usable_cores() -> int:
    """The cores this process may use (affinity, cpusets)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)


def max_workers() -> tuple[int, str]:
    """How many local workers this machine runs usefully: one per core, and no more
    than its available memory holds (WORKER_MEMORY_MB each); and why."""
    cores = usable_cores()
    free_mb = available_mb()
    if free_mb is None:
        return cores, f"{cores} cores"
    by_memory = max(1, int(free_mb // WORKER_MEMORY_MB))
    return min(cores, by_memory), (f"{cores} cores; {free_mb / 1024:.1f} GiB available "
                                   f"holds {by_memory} workers of ~{WORKER_MEMORY_MB} MiB")


def _worker(conn: Connection, fn: Callable, max_rss_mb: float, parent: int,
            max_jobs: int, setup: Callable[[], None] | None) -> None:
    """A worker's life: ``setup()``, then jobs in, (ok, value, retiring) out, until told to
    stop (None), its memory passes the limit or it has done ``max_jobs`` jobs."""
    _die_with(parent)
    _ignore_sigint()
    if setup is not None:
        setup()
    warnings.showwarning = one_line_warning  # as the parent shows them
    done = 0
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
        done += 1
        retiring = (max_rss_mb > 0 and rss_mb() > max_rss_mb) or done >= max_jobs
        conn.send((ok, value, retiring))
        if retiring:
            return


class _Slot:
    """One worker process, its pipe and the job it holds."""

    def __init__(self, ctx, fn: Callable, max_rss_mb: float, max_jobs: int,
                 setup: Callable[[], None] | None):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, fn, max_rss_mb, os.getpid(), max_jobs,
                                                      setup), daemon=True)
        self.proc.start()
        child.close()
        self.job: tuple | None = None


def run_local(fn: Callable, jobs: list[tuple], workers: int, *, is_done: Callable[[int], bool],
              on_result: Callable[[object], None], max_rss_mb: float = 0.0,
              max_jobs: int = MAX_JOBS_PER_WORKER,
              setup: Callable[[], None] | None = None) -> None:
    """Call ``fn(*job)`` for each job in ``workers`` warm processes, each of which first
    calls ``setup()`` (picklable); ``on_result`` gets each return value.  A worker past
    ``max_rss_mb`` MiB (0: no limit) or ``max_jobs`` jobs retires after its job; one that
    dies is replaced and its job, unless ``is_done(index)`` (the index is a job's first
    element), given to the next free worker."""
    ctx = mp.get_context("spawn")  # a fresh interpreter: no inherited Mitsuba state
    pending = deque(jobs)
    slots: list[_Slot] = []
    deaths = 0

    def start() -> None:
        with _sigint_held():
            slots.append(_Slot(ctx, fn, max_rss_mb, max_jobs, setup))

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
             *, on_result: Callable[[object], None]) -> None:
    """The same on a Dask cluster (a local one when no scheduler is given)."""
    from dask.distributed import Client, LocalCluster
    from dask.distributed import as_completed as dask_completed

    cluster = None
    with _sigint_held():
        if scheduler is None:
            # its dashboard on a free port: the default 8787, taken by another cluster or
            # run on the machine, made the cluster's start warn (an error under pytest)
            cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                   dashboard_address=":0")
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
