"""How the process keeps the memory it frees: set once by the command line and its workers.

Notes
-----
Describing a fragment allocates and frees grids of tens to hundreds of MB again and
again (one inverse FFT per kernel and radius). The GNU C library serves a request that
large with a fresh ``mmap`` and returns it to the system on ``free``, so every grid is
faulted in again page by page. On a virtual machine a page fault is expensive: on a
2-core Firecracker VM, three quarters of a run's page faults were in the inverse FFTs'
outputs, and its system time was up to as long as its user time. Served from the heap
and kept there, the pages are faulted in once: a 3- and a 4-piece run took 0.84-0.86 of
the wall time, with half the system time or less and 4-7 % more peak memory
(``python -m benchmarks.speed.allocator``). The setting changes no result.
"""

from __future__ import annotations

import sys

_M_TRIM_THRESHOLD = -1  # glibc <malloc.h>
_M_MMAP_MAX = -4
_TRIM_THRESHOLD = 2**31 - 1  # bytes free at the top of the heap before it is given back (an int)


def retain_freed_memory() -> bool:
    """Serve every allocation from the heap and keep what is freed for the next one (glibc).

    Returns
    -------
    bool
        Whether the C library took the setting (False off Linux, or on a C library
        without ``mallopt``, where nothing changes).
    """
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt  # the C library the interpreter runs on
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_MAX, 0)) and bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
