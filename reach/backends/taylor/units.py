"""The taylor back-end's work units: expanding one ADS box and sweeping one subdomain.

They are module-level functions of picklable arguments (the model, the bound property, plain
numbers), so a level of ADS boxes or the rigorous sweeps of all subdomains can run on local worker
processes or a Dask cluster (:mod:`reach.executors`). Each process compiles a problem once
and keeps it, keyed by a digest of the pickled model and property. The units run with one BLAS
thread: their matrix products are many and small, and BLAS threads competing for the cores of a
loaded machine made them tens of times slower.
"""

from __future__ import annotations

import ctypes
import logging
import time
from functools import lru_cache

from reach.backends.taylor.bound import truncate
from reach.backends.taylor.deadline import NONE, Deadline
from reach.backends.taylor.keys import fingerprint
from reach.backends.taylor.lockstep import within
from reach.backends.taylor.problem import Candidates, EventProblem
from reach.model.simulate import single_threaded

log = logging.getLogger(__name__)
_PROBLEMS: dict[str, tuple] = {}


def problem(model, prop) -> EventProblem:
    key = fingerprint(model, prop)
    if key not in _PROBLEMS:
        if len(_PROBLEMS) > 16:
            _PROBLEMS.clear()
        _PROBLEMS[key] = (EventProblem(model, prop), model, prop)   # keeps the objects alive
    return _PROBLEMS[key][0]


def expand_box(model, prop, order: int, expand_order: int, tol: float, center, half_width):
    """Candidate maps of one box: ``(maps truncated to order, maps as expanded)``."""
    maps = problem(model, prop).candidates(center, half_width, expand_order, tol)
    return _truncated(maps, order, expand_order), maps


def expand_boxes(model, prop, order: int, expand_order: int, tol: float, boxes: list,
                 deadline: Deadline = NONE) -> list:
    """:func:`expand_box` of each ``(center, half_width)`` in ``boxes``, expanded as one batch
    (OutOfTime past the ``deadline``)."""
    keep_freed_memory()
    with single_threaded(), within(deadline):
        batch = problem(model, prop).candidates_batch(boxes, expand_order, tol)
    return [(_truncated(maps, order, expand_order), maps) for maps in batch]


@lru_cache(maxsize=None)
def keep_freed_memory() -> None:
    """Let this process's C allocator (glibc) keep freed blocks of up to 64 MiB for reuse.

    By default glibc serves a block above its mmap threshold (128 KiB, raised to the size of a
    freed block, up to 32 MiB) by a fresh ``mmap``, and gives the top of its heap back to the
    system above the trim threshold (twice that), so the arrays of a batch's DA layers, a few
    hundred KiB each and allocated thousands of times, can cost a page fault per 4 KiB touched.
    A SIREN network on 96 runs (order 4 in 2 variables) took 5.4 ms per evaluation with the
    defaults and 2.5 ms with these thresholds (0.7 ms on 32 runs either way), so batches of more
    than about 64 runs pay only with them. Without glibc's ``mallopt``: no change."""
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3            # mallopt parameters (malloc.h)
    mallopt(m_mmap_threshold, 64 << 20)
    mallopt(m_trim_threshold, 256 << 20)


def _truncated(maps: Candidates, order: int, expand_order: int) -> Candidates:
    return maps.like({name: truncate(p, order) if expand_order > order else p for name, p in maps.items()})


def sweep_box(model, prop, order: int, rel_tol: float, tol: float, center, half_width,
              keep_sets: bool = False, deadline: Deadline = NONE) -> dict:
    """The rigorous sweep of one subdomain (:meth:`EventProblem.sweep`), its outcome logged
    (progress under ``-v``)."""
    started = time.perf_counter()
    with single_threaded():
        out = problem(model, prop).sweep(center, half_width, order, rel_tol, tol, keep_sets, deadline)
    lo, hi = out["bound"]
    log.info("subdomain swept in %.1f s: %s", time.perf_counter() - started,
             f"unbounded ({out['why']})" if "why" in out else
             f"bound [{lo:.6g}, {hi:.6g}] ({out['stretches']} stretches, {out['steps']} steps)")
    return out
