"""Taichi runtime selection: the one place that calls ``ti.init``."""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable

from roshan import allocator, taichi_patches

taichi_patches.import_taichi()  # first: Taichi defines its own kernels as it loads (see there)

import taichi as ti  # noqa: E402
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext  # noqa: E402

ARCHES = ("cpu", "cuda", "vulkan", "auto")
# Taichi's default fast math lets LLVM use approximate reciprocals and square roots (RCP14/RSQRT14 and the like)
# and fuse or reorder float operations freely. The approximations are vendor-specific: the FlyAgent kernels gave
# other trajectories on an Intel AVX-512 Xeon than on the AMD EPYC that recorded the behaviour pins. With exact
# (IEEE) math both CPUs give the same bits (the Xeon's fast_math=False hashes are the ones pinned now). What it
# costs: BENCHMARKS.md, "Same numbers on every CPU"; tests/test_runtime.py holds the setting.
FAST_MATH = False
# Taichi keeps compiled kernels on disk (~/.cache/taichi) and, past 100 MB, evicts the least recently used quarter.
# This package's kernel variants (maps, frame skips, layouts, network shapes) outgrow that: the test suite wrote
# more than 100 MB, so it recompiled kernels it had compiled minutes before (a file of env tests took 90 s
# recompiling and 29 s cached). 1 GiB holds them all; TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES still overrides it.
OFFLINE_CACHE_BYTES = 1 << 30
_current: dict[str, object] = {}
_per_runtime: dict[str, object] = {}  # objects that live as long as the Taichi runtime (for_this_runtime)
_per_process: dict[str, object] = {}  # objects that outlive a re-initialised runtime (for_this_process)
# Bumped whenever the runtime is reset or re-initialised: an object that holds fields compares the number it was
# built under (an int comparison, cheap enough for every step) to refuse use after its fields died.
_generation = [0]


# Arches whose kernels are known to give wrong results without any error, and why. init_taichi refuses them
# unless ROSHAN_UNVERIFIED_ARCH names the arch (for work on the kernels themselves);
# tests/test_runtime.py::test_vulkan_is_refused_because_its_fire_differs_from_the_cpu keeps the reason true.
UNVERIFIED_ENV = "ROSHAN_UNVERIFIED_ARCH"
WRONG_ARCHES = {
    "vulkan": "its fire kernels run silently wrong (Taichi 1.7.4's SPIR-V code on Mesa lavapipe: one launch of "
              "1,000 fire updates makes a single update, and ignition lights 2 of the 18 fires the CPU lights; "
              "benchmarks/scripts/vulkan_atomic_repro.py shows atomic adds in loops losing updates there)",
}


def init_taichi(arch: str = "cpu", threads: int | None = None, debug: bool = False) -> str:
    """Initialise Taichi once per process and return the arch actually used.

    Args:
        arch: ``cpu`` (default), ``cuda``, ``vulkan`` or ``auto`` (CUDA when present, else CPU); an arch of
            :data:`WRONG_ARCHES` is refused with its reason.
        threads: CPU worker threads; ``None`` lets Taichi use every core.
        debug: Taichi debug mode (bounds checks; slow).

    Calling it again with the same arguments is a no-op; with different ones it re-initialises Taichi, which
    invalidates every field allocated before (so do it before building simulators).
    """
    if arch not in ARCHES:
        raise ValueError(f"--arch: unknown arch {arch!r}; expected one of {', '.join(ARCHES)}")
    if arch in WRONG_ARCHES and os.environ.get(UNVERIFIED_ENV) != arch:
        raise ValueError(f"--arch {arch} is refused: {WRONG_ARCHES[arch]}. Use --arch cpu (or cuda where present). "
                         f"To run it anyway while working on the kernels, set {UNVERIFIED_ENV}={arch}.")
    if threads is not None and threads < 1:
        raise ValueError(f"--threads: expected a positive integer, got {threads}")
    key = {"arch": arch, "threads": threads, "debug": debug}
    if _current.get("key") == key:
        return str(_current["arch"])
    kwargs: dict[str, object] = {"debug": debug, "random_seed": 0, "log_level": ti.WARN, "fast_math": FAST_MATH}
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    if not os.environ.get("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"):
        kwargs["offline_cache_max_size_of_files"] = OFFLINE_CACHE_BYTES
    if _current:  # ti.init re-initialises: every field and kernel of the old runtime dies
        _forget_runtime()
    allocator.retain_freed_memory()  # the process that starts Taichi steps envs and their torch tensors
    _plain_source_positions(not debug)
    if arch == "cpu":
        kwargs["arch"] = ti.cpu
    elif arch == "cuda":
        kwargs["arch"] = ti.cuda
    elif arch == "vulkan":
        kwargs["arch"] = ti.vulkan
    else:
        kwargs["arch"] = ti.gpu if _has_gpu() else ti.cpu
    ti.init(**kwargs)
    used = _arch_name(ti.lang.impl.current_cfg().arch)
    if arch in ("cuda", "vulkan") and used != arch:
        warnings.warn(f"--arch {arch} requested but Taichi fell back to {used}", stacklevel=2)
    _current.update(key=key, arch=used)
    return used


# Building a kernel costs Taichi 1.7.4 (its last release) a Python AST transform at every start, which its
# offline cache does not skip (the cache key is computed from the transformed IR). Part of it is pure waste:
# it formats a caret diagram of the source (textwrap over the line) for every AST node, only to attach it as
# debug info: ~40 % of the transform. Outside debug mode each node gets "File, line, function" and its source
# line instead, which is what a compile error then shows (tests/test_runtime.py checks it). The source lookups
# it repeats are patched by roshan.taichi_patches, as this module imported Taichi.
_FULL_POSITIONS = ASTTransformerContext.get_pos_info


def _plain_position(ctx, node) -> str:
    return (f'File "{ctx.file}", line {node.lineno + ctx.lineno_offset}, in {ctx.func.func.__name__}:\n'
            f"{ctx.src[node.lineno - 1]}\n")


def _plain_source_positions(plain: bool) -> None:
    ASTTransformerContext.get_pos_info = _plain_position if plain else _FULL_POSITIONS



def cpu_cores() -> int:
    """CPU cores this process may run on (its affinity mask, which containers and ``taskset`` narrow, else
    ``os.cpu_count()``)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity masks (macOS)
        return os.cpu_count() or 1


def share_cores(workers: int | None, threads: int | None) -> tuple[int, int | None]:
    """(worker processes, CPU threads of each) for runs that share this machine: what is given, the rest split from
    the cores; given neither, one single-threaded run per core. A training run's update is one thread in the
    reproducible mode, so a second run on a core gains more than a second thread in one run would (BENCHMARKS,
    "Training at the machine's speed"). ``None`` threads: all cores (one worker)."""
    cores = cpu_cores()
    if workers is None:
        return (cores, 1) if threads is None else (max(1, cores // threads), threads)
    if threads is None and workers > 1:
        threads = max(1, cores // workers)
    return workers, threads


def threads_warning(threads: int | None) -> str | None:
    """A warning line when ``threads`` asks for more CPU threads than this machine has cores (they would only
    take turns: ``--threads 999`` on 2 cores ran 2.5x slower than ``--threads 2``), else None."""
    cores = cpu_cores()
    if threads is None or threads <= cores:
        return None
    return (f"warning: --threads {threads} is more than the {cores} CPU core{'s' * (cores != 1)} this machine has; "
            f"the extra threads only take turns on them and make the kernels slower, not faster (use --threads "
            f"{cores} or less)")


def current_arch() -> str | None:
    """The arch Taichi was initialised with by :func:`init_taichi`, or ``None``."""
    return _current.get("arch")  # type: ignore[return-value]


def ensure_taichi() -> str:
    """Initialise Taichi on the CPU unless :func:`init_taichi` already ran."""
    return current_arch() or init_taichi()


# Taichi's LLVM backends (CPU, CUDA) hold at most 512 field trees per process and write past that limit
# without a check (a segfault in a later kernel). Fields declared before a kernel launch become one tree when
# it launches; one FlyVectorEnv makes 6 (a planner env more), and they stay until ti.reset(). Closed envs give
# their simulators to roshan.kernels.pool, so only envs alive at the same time (per build) hold trees.
MAX_FIELD_TREES = 512
TREE_HEADROOM = 32


def field_trees() -> int:
    """Field trees Taichi has allocated in this process (0 before initialisation)."""
    if current_arch() is None:
        return 0
    return int(ti.lang.impl.get_runtime().prog.get_snode_tree_size())


def check_field_room(what: str) -> None:
    """Raise a clear error instead of Taichi's out-of-bounds write when the tree limit is close."""
    used = field_trees()
    if used + TREE_HEADROOM > MAX_FIELD_TREES:
        raise RuntimeError(
            f"{what}: this process already holds {used} Taichi field trees (the CPU/CUDA backends allow "
            f"{MAX_FIELD_TREES}, and live envs keep theirs until closed); close() envs you no longer use (closed "
            "envs' simulators are reused by the next env of the same build), reuse envs with reset(), or call "
            "roshan.runtime.reset_taichi() once the old ones are no longer used")


def reset_taichi() -> None:
    """Free every field and compiled kernel (``ti.reset``); the next simulator initialises Taichi again.
    Objects built before (envs, simulators) must not be used afterwards."""
    if current_arch() is not None:
        ti.reset()
    _current.clear()
    _forget_runtime()


def taichi_generation() -> int:
    """How many times the Taichi runtime has been reset or re-initialised in this process."""
    return _generation[0]


def check_built_in_this_runtime(generation: int, what: str) -> None:
    """Raise instead of segfaulting when ``what`` was built (at ``generation``) before Taichi was reset: its
    fields and kernels belong to a dead runtime."""
    if generation != _generation[0]:
        raise RuntimeError(f"{what} was built before Taichi was reset (roshan.runtime.reset_taichi() or "
                           "init_taichi with other arguments), so its fields are gone; build a new one")


def for_this_runtime(name: str, make: Callable[[], object]):
    """The object ``name`` of the current Taichi runtime, made by ``make()`` at its first use; a reset or a new
    ``ti.init`` forgets it (such as the simulator pool of :mod:`roshan.kernels.pool`, whose fields die then)."""
    if name not in _per_runtime:
        _per_runtime[name] = make()
    return _per_runtime[name]


def for_this_process(name: str, make: Callable[[], object]):
    """The object ``name`` of this process, made by ``make()`` at its first use and kept across re-initialised
    runtimes: the one GGUI window (:mod:`roshan.ggui`, which must see the old runtime's window to destroy it),
    the warnings given once."""
    if name not in _per_process:
        _per_process[name] = make()
    return _per_process[name]


def warn_once(what: str) -> bool:
    """True the first time this process asks to warn about ``what``."""
    warned = for_this_process("warned", set)
    first = what not in warned
    warned.add(what)
    return first


def _forget_runtime() -> None:
    _generation[0] += 1
    _per_runtime.clear()


def torch_device() -> str:
    """The torch device whose memory Taichi kernels share: ``cuda`` on CUDA, else ``cpu``."""
    return "cuda" if current_arch() == "cuda" else "cpu"


def use_acting_threads(configured: int) -> None:
    """Torch intra-op threads for a process that acts in envs (evaluation, watching): ``configured``
    (``train.torch_threads``) when set, else one. Acting runs small batches between Taichi kernels, and torch's
    OpenMP threads spin after each op on the cores those kernels need: an evaluation of the endurance planner on
    three 100 x 110 maps took over 20 min per map with torch's default two threads beside one other process, and
    under 4 min for all three with one. Alone on the 2-core machine two threads are ~15 % faster (51 s against 60 s
    for 32 episodes of planner and greedy): ``train.torch_threads=2`` takes them."""
    import torch

    torch.set_num_threads(configured or 1)


def _has_gpu() -> bool:
    try:
        import torch

        return torch.cuda.is_available()
    except Exception:  # torch missing or broken CUDA install: treat as no GPU
        return False


def _arch_name(arch) -> str:
    name = str(arch).split(".")[-1]
    return {"x64": "cpu", "arm64": "cpu"}.get(name, name)
