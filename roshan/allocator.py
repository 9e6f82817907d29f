"""Keep freed heap memory for reuse instead of handing it back to the kernel after every large tensor.

glibc serves blocks above its mmap threshold (at most 32 MB after its dynamic adjustment) with fresh
``mmap`` pages and unmaps them on free, so every large torch temporary (a batch of 16,384 drone
observations through a 256-wide layer is 16-64 MB) is page-faulted in again on every step. On this
project's 2-core machine that cost more than the arithmetic: policy inference for 4,096 envs spent 60 %
of its time in ``cat``/``relu``/``copy`` page faults. Raising the mmap and trim thresholds to 1 GiB lets
the heap keep and reuse those blocks (PyTorch's CPU tuning guide suggests jemalloc or tcmalloc for the
same reason; this needs no extra package). Set ``ROSHAN_MALLOC_TUNING=0`` to leave glibc's defaults.
"""

from __future__ import annotations

import ctypes
import os
import sys

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameter numbers (malloc.h)
M_MMAP_THRESHOLD = -3
THRESHOLD_BYTES = 1 << 30


def retain_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds; True if both took effect (False off glibc or when disabled)."""
    if os.environ.get("ROSHAN_MALLOC_TUNING", "1") == "0" or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None)  # the process's own symbols, libc's among them (find_library runs ldconfig)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and other libcs without mallopt
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(M_MMAP_THRESHOLD, THRESHOLD_BYTES)) and bool(mallopt(M_TRIM_THRESHOLD, THRESHOLD_BYTES))
