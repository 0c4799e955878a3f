"""A deeply recursive search run in a thread of its own with a large stack.

star follows every path of jumps by recursion (a chain, its cells, their jumps, the successors'
chains), four or five frames per jump: Python's default limit of 1000 frames stops a path near
240 jumps, which a bouncing ball or a sawtooth of a few hundred periods exceeds. The search
runs instead in a thread whose stack is :data:`STACK_BYTES` (reserved, not resident: only the
pages it touches count) under a recursion limit of :data:`FRAMES` frames, about 9000 jumps;
beyond that the RecursionError still ends it cleanly. Python-to-Python calls take no C stack
(CPython 3.11), so the limit is what binds, far below the stack's size.

If the caller is interrupted while it waits (the bench's per-unit time limit arrives as an
exception in the main thread, Ctrl-C), ``cancel`` is set and the search, which checks it
regularly, stops before the exception goes on: no search is left running behind a unit
that has ended.
"""

from __future__ import annotations

import sys
import threading

FRAMES = 40_000
STACK_BYTES = 256 * 2 ** 20

_LOCK = threading.Lock()
_NAME = "deep-search"


def call_deep(fn, cancel: threading.Event):
    """``fn()`` in a thread with a deep stack; its value, or its exception raised here. Called
    from such a thread (a search inside a search), ``fn()`` runs where it is."""
    if threading.current_thread().name == _NAME:
        return fn()
    outcome: dict = {}
    done = threading.Event()        # waited on, not the thread: an interrupted join() may mark
                                    # a running thread as ended

    def target():
        try:
            outcome["value"] = fn()
        except BaseException as exc:           # handed to the caller, whatever it is
            outcome["error"] = exc
        finally:
            done.set()

    with _LOCK:
        limit = sys.getrecursionlimit()
        try:
            previous = threading.stack_size(STACK_BYTES)
        except (ValueError, RuntimeError):      # no settable stack here: run as it is
            return fn()
        sys.setrecursionlimit(max(limit, FRAMES))
        try:
            worker = threading.Thread(target=target, name=_NAME, daemon=True)
            worker.start()
        except RuntimeError:                    # no thread to be had (address-space limit)
            sys.setrecursionlimit(limit)
            return fn()
        finally:
            threading.stack_size(previous)
        try:
            done.wait()
        except BaseException:
            cancel.set()
            done.wait()
            raise
        finally:
            sys.setrecursionlimit(limit)
    error = outcome.pop("error", None)
    if error is not None:
        try:
            raise error
        finally:        # neither the dict nor this frame keeps the exception: its traceback holds
            error = None    # the search's frames, which would otherwise wait for the collector
    return outcome.get("value")
