"""How much memory this process holds and the machine has (Linux ``/proc``; elsewhere the
peak resident set from ``resource`` and, failing ``sysconf``, no limit)."""

from __future__ import annotations

import os
import resource


def resident_bytes() -> int:
    """The process's resident set now (``/proc/self/statm``), or its peak where that is absent."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak * 1024 if os.uname().sysname == "Linux" else peak


def physical_bytes() -> float:
    """The machine's physical memory (infinite where it cannot be read)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (OSError, ValueError, AttributeError):
        return float("inf")
