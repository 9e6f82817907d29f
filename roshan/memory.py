"""Memory the machine has left, and the one refusal of a build that would not fit in it.

Every simulator (FireSim alone, the simulator bundle of an env and its torch buffers) works out what its fields
will take from the map, the env count and the capacities before it allocates anything, and calls
:func:`check_fits`. Without it, a build too large for the machine either ended in a Taichi traceback
(``Virtual memory allocation (595754164224 B) failed`` for 100,000 envs of a 941k-cell map) or quietly pushed the
machine into swap (2,500 envs of that map took 8 GB in 20 s). The estimate counts field and buffer bytes only:
Taichi's runtime, torch and the compiled kernels are already resident when the check runs, so what the machine
reports as available is what the new fields can still take.

``ROSHAN_MEMORY_CHECK=0`` turns the refusal off (for a machine whose swap or overcommit is meant to be used).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

# A build may take this share of the available memory: the rest is for what the estimate leaves out (Taichi's
# runtime and kernels, numpy temporaries while building, torch's workspace) and for the other processes. A
# build estimated at 19.3 GiB with 19.6 GiB available was killed by the kernel's OOM killer at 19.4 GiB.
USABLE_SHARE = 0.9
# Above this share of the available memory a build goes ahead with a warning.
WARN_SHARE = 0.5
MEMINFO = Path("/proc/meminfo")
CGROUP = Path("/sys/fs/cgroup")  # cgroup v2: a container's own limit can be far below the host's memory
CHECK_ENV = "ROSHAN_MEMORY_CHECK"


class MemoryLimitError(ValueError):
    """A build would need more memory than the machine has available; the message gives the estimate, what is
    available and the settings that make it smaller."""


def available_memory() -> tuple[int, str] | None:
    """(bytes a new allocation can still take, where that number comes from), or None where nothing says.

    ``MemAvailable`` of /proc/meminfo (free memory plus what the kernel can reclaim without swapping), narrowed to
    the room left under this process's cgroup v2 limit where one is set; elsewhere the free physical pages
    (``sysconf``), which leave out the page cache and so understate it.
    """
    found: tuple[int, str] | None = None
    try:
        for line in MEMINFO.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found = int(line.split()[1]) * 1024, "MemAvailable in /proc/meminfo"
                break
    except (OSError, ValueError, IndexError):
        pass
    if found is None:
        try:
            found = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "free physical memory (sysconf)"
        except (ValueError, OSError, AttributeError):
            return None
    room = _cgroup_room()
    if room is not None and room < found[0]:
        return room, "the room under this process's cgroup memory limit"
    return found


def _cgroup_room() -> int | None:
    """memory.max - memory.current of this process's cgroup v2, or None without a limit (or cgroup v2)."""
    try:
        line = Path("/proc/self/cgroup").read_text().splitlines()[0]
        if not line.startswith("0::"):
            return None
        group = CGROUP / line[3:].lstrip("/")
        limit = (group / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return max(0, int(limit) - int((group / "memory.current").read_text()))
    except (OSError, ValueError, IndexError):
        return None


def format_bytes(n: float) -> str:
    """``n`` bytes with a binary unit: 512 B, 3.2 KiB, 146.8 MiB, 555.1 GiB."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def check_fits(what: str, need: int, ways_out: list[str], arch: str | None = "cpu") -> None:
    """Raise :class:`MemoryLimitError` when ``need`` bytes exceed :data:`USABLE_SHARE` of the memory available
    now; warn when they exceed :data:`WARN_SHARE` of it.

    Args:
        what: what would be built, with its size (``"FireSim: 100000 envs of map 'X' (941,192 cells, dense)"``).
        need: the estimate, in bytes.
        ways_out: the settings that make it smaller, each as the user would write it.
        arch: the Taichi arch the fields live on; only the CPU's are checked (host memory). A GPU's fields live
            in its own memory, which this does not measure.
    """
    if arch not in (None, "cpu") or os.environ.get(CHECK_ENV, "1") == "0":
        return
    available = available_memory()
    if available is None:
        return
    room, source = available
    if need > USABLE_SHARE * room:
        raise MemoryLimitError(
            f"{what} needs an estimated {format_bytes(need)} of memory, but {format_bytes(room)} is available "
            f"({source}) and a build may take {USABLE_SHARE:.0%} of it; use {', or '.join(ways_out)} (or set "
            f"{CHECK_ENV}=0 to build it anyway)")
    if need > WARN_SHARE * room:
        warnings.warn(f"{what} will take an estimated {format_bytes(need)} of the {format_bytes(room)} of memory "
                      f"available ({source})", stacklevel=3)
