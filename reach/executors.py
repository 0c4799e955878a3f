"""Where work units run: local processes (default) or a Dask cluster.

Both take a picklable function and a list of argument tuples and yield ``(index, result)``
as units finish, so the runner can print progress. A unit that exceeds the time limit is
stopped inside its worker (SIGALRM) and reported as timed out; a worker's address space is
capped so one runaway case cannot take the machine down, and a local worker ends with the
process that started it (Linux: the parent-death signal), so a ``reach bench -j 2`` stopped by
SIGTERM or SIGKILL leaves no worker computing on.
"""

from __future__ import annotations

import os
import re
import signal
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

MEMORY_LIMIT_BYTES = 16 * 2 ** 30
PR_SET_PDEATHSIG = 1               # prctl option (linux/prctl.h)
CONNECT_SECONDS = 10


class UnitTimeout(BaseException):
    """A unit's time limit ran out (a BaseException, so that no ``except Exception`` in a
    back-end takes it for a failure of its own)."""


def _alarm(signum, frame):
    raise UnitTimeout()


def guarded(fn, args, time_limit):
    """Run ``fn(*args)`` under a time limit; return ``("ok", value)`` or ``("timeout", None)``.
    The timer is armed and disarmed inside the guarded region: a limit so short that the alarm
    comes before ``setitimer`` returns (``--time-limit 1e-6``), or one that runs out while the
    timer is being disarmed, is a timeout like any other. The previous SIGALRM handler is put
    back."""
    if not time_limit:
        return "ok", fn(*args)
    previous = signal.signal(signal.SIGALRM, _alarm)
    try:
        try:
            signal.setitimer(signal.ITIMER_REAL, time_limit)
            return "ok", fn(*args)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
    except UnitTimeout:
        return "timeout", None
    finally:
        signal.signal(signal.SIGALRM, previous)


def _worker_start():
    """In each local worker: the address-space cap, and SIGTERM when the parent dies
    (``prctl(PR_SET_PDEATHSIG)``; nothing where the call does not exist)."""
    try:
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, MEMORY_LIMIT_BYTES))
    except (ImportError, ValueError, OSError):
        pass
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass
    if os.getppid() == 1:           # the parent died before the signal was armed
        os._exit(1)


class LocalExecutor:
    """A pool of local worker processes (``jobs`` of them; all cores by default)."""

    name = "local"

    def __init__(self, jobs: int | None = None):
        self.jobs = jobs or os.cpu_count() or 1

    def map_unordered(self, fn, arg_list, time_limit=None):
        if self.jobs == 1:
            for i, args in enumerate(arg_list):
                yield i, guarded(fn, args, time_limit)
            return
        pool = ProcessPoolExecutor(max_workers=self.jobs, initializer=_worker_start)
        try:
            futures = {pool.submit(guarded, fn, args, time_limit): i for i, args in enumerate(arg_list)}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    yield futures[f], f.result()
        except BaseException:                   # Ctrl-C, an error, the caller stopping early
            stop_workers(pool)
            raise
        pool.shutdown(wait=True)


def stop_workers(pool: ProcessPoolExecutor) -> None:
    """End ``pool`` now: its queued units cancelled and its worker processes terminated (a
    plain shutdown waits for the units under way, minutes of a Monte Carlo batch after a
    Ctrl-C)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=5)


def check_address(scheduler, field: str) -> None:
    """A Dask scheduler address (``tcp://host:8786``; no path, so no ``file://``), else InputError."""
    from reach.errors import InputError
    if not isinstance(scheduler, str) or not re.fullmatch(r"(tcp|tls|inproc|ws|wss)://[^\s/]+", scheduler):
        raise InputError(f"expected an address such as tcp://host:8786, got {scheduler!r}", field=field)


class DaskExecutor:
    """Units as tasks on a Dask cluster (``--scheduler tcp://host:8786``; the ``dist`` extra)."""

    name = "dask"

    def __init__(self, scheduler):
        try:
            from distributed import Client
        except ImportError:
            from reach.errors import InputError
            raise InputError("Dask is not installed: pip install 'reach[dist]'", field="--scheduler") from None
        if hasattr(scheduler, "submit"):
            self.client = scheduler
            return
        check_address(scheduler, "--scheduler")
        from reach.errors import InputError
        try:
            self.client = Client(scheduler, timeout=CONNECT_SECONDS)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler {scheduler} within {CONNECT_SECONDS} s "
                             f"({exc.__class__.__name__})", field="--scheduler") from None

    def map_unordered(self, fn, arg_list, time_limit=None):
        from distributed import as_completed

        futures = {self.client.submit(guarded, fn, args, None, pure=False): i for i, args in enumerate(arg_list)}
        for f in as_completed(list(futures)):
            yield futures[f], f.result()


def make_executor(jobs=None, scheduler=None):
    return DaskExecutor(scheduler) if scheduler else LocalExecutor(jobs)
