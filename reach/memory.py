"""How much memory this process holds and may hold (Linux ``/proc``, ``/sys/fs/cgroup``;
elsewhere the peak resident set from ``resource`` and, failing ``sysconf``, no limit)."""

from __future__ import annotations

import os
import resource

CGROUP_LIMITS = ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes")


def resident_bytes() -> int:
    """The process's resident set now (``/proc/self/statm``), or its peak where that is absent."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak * 1024 if os.uname().sysname == "Linux" else peak


def physical_bytes() -> float:
    """The memory this process may hold: the machine's physical memory, or less where a
    control group (cgroup v2 ``memory.max``, v1 ``memory.limit_in_bytes``) or the address-space
    limit (``RLIMIT_AS``) sets less; infinite where none can be read."""
    limits = []
    try:
        limits.append(float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")))
    except (OSError, ValueError, AttributeError):
        pass
    for path in CGROUP_LIMITS:
        try:
            with open(path) as f:
                text = f.read().strip()
            if text.isdigit():
                limits.append(float(text))
        except OSError:
            pass
    try:
        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            limits.append(float(soft))
    except (OSError, ValueError, AttributeError):
        pass
    return min(limits, default=float("inf"))
