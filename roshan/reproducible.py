"""The reproducible mode: torch's CPU kernels pinned so that a seed gives the same weights on every x86-64 CPU.

The Taichi kernels already give the same bits on every CPU (exact math, :mod:`roshan.runtime`). Torch does not by
itself: it picks its CPU code by what the processor offers, and two of its choices round differently.

- **MKL's GEMMs**: MKL dispatches by vendor as well as instruction set. Its conditional numerical reproducibility
  (``MKL_CBWR``) pins a code branch, but a branch named by instruction set (``AVX2``, ``AVX512``) holds on Intel
  CPUs only; elsewhere MKL falls back to its ``AUTO`` branch (measured on an AMD EPYC: ``AVX2``, ``AVX512`` and
  ``AUTO`` all gave one fingerprint, and MKL itself reports branch ``AUTO`` there). ``COMPATIBLE`` (SSE2 without
  approximate reciprocals) is the one branch documented to give the same results on Intel and compatible
  processors, and it is slow: 27.6 against 54.7 GFLOP/s for a 6144x256x256 product on one AMD EPYC core.
- **The Linear layers' GEMMs**, most of a FlyAgent update, therefore run on a BLAS of our own choosing instead:
  the OpenBLAS of the pinned ``scipy-openblas32`` wheel, loaded privately with its Haswell (AVX2 + FMA) kernels
  forced (``OPENBLAS_CORETYPE``) and one thread. OpenBLAS picks kernels by that core type alone and takes its
  blocking from the core type's compiled-in table, so every AVX2 CPU, Intel or AMD, runs the same instructions in
  the same order: about 80 GFLOP/s on that core (:func:`gemm_library`, :mod:`roshan.algos.linear`). The other
  products (attention, einsum) stay on MKL's COMPATIBLE branch.
- **ATen's own kernels** (activations, reductions, the normal sampler, Adam) come in a build per instruction set
  (``DEFAULT``, ``AVX2``, ``AVX512``); vector widths decide the order of sums. ``ATEN_CPU_CAPABILITY=avx2`` picks the
  AVX2 build on every CPU that has AVX2 (every x86-64 server CPU since 2015), so an AVX-512 Xeon and an AVX2-only
  EPYC run the same code.
- **Thread counts** decide the order in which parallel reductions combine: in this mode ``train.torch_threads: 0``
  means one torch thread, not "all cores" (which differs by machine).

Both variables are read when torch first uses MKL and ATen's dispatch, so they must be set before any torch
operation runs: :func:`enable` does that (the CLI calls it before it imports torch), and :func:`check` tells, from
the loaded libraries themselves, whether the settings took effect. What the mode costs in training speed is in
BENCHMARKS.md ("Training that reproduces on any CPU").
"""

from __future__ import annotations

import ctypes
import functools
import os
import platform
import sys
from pathlib import Path

ENV_VAR = "ROSHAN_REPRODUCIBLE"  # "0" turns the mode off for the commands that enable it by default
SETTINGS = {"ATEN_CPU_CAPABILITY": "avx2", "MKL_CBWR": "COMPATIBLE"}
ISA = "AVX2"  # what torch.backends.cpu.get_cpu_capability() reports once ATEN_CPU_CAPABILITY=avx2 took effect
_MKL_CBWR_BRANCH = 1  # mkl_cbwr.h: mkl_cbwr_get(MKL_CBWR_BRANCH) returns the branch in force
_MKL_CBWR_COMPATIBLE = 3
MODES = ("reproducible", "vendor")
GEMM_PACKAGE = "scipy_openblas32"  # the pinned OpenBLAS build (pyproject.toml names its version)
GEMM_CORE = "Haswell"  # the kernels forced: AVX2 + FMA, on every x86-64 server CPU since 2015


class ReproducibleModeError(RuntimeError):
    """The reproducible mode was asked for but torch already runs with other kernels."""


def wanted(flag: bool | None = None) -> bool:
    """Whether a command should run in the mode: ``flag`` (a command's ``--reproducible/--vendor-kernels``) when
    given, else not unless ``ROSHAN_REPRODUCIBLE=0`` says so."""
    if flag is not None:
        return flag
    return os.environ.get(ENV_VAR, "1") != "0"


def enable(on: bool = True) -> None:
    """Set the mode's variables in this process's environment (and so its subprocesses'), or, with ``on=False``,
    record that the mode is off (``ROSHAN_REPRODUCIBLE=0``, which workers started from here inherit).

    Must run before torch computes anything; when torch has already picked other kernels this raises
    :class:`ReproducibleModeError` instead of running a training that would not reproduce."""
    if not on:
        os.environ[ENV_VAR] = "0"
        for key, value in SETTINGS.items():  # inherited from a parent in the mode (a runner's workers, the tests)
            if os.environ.get(key) == value:
                del os.environ[key]
        return
    os.environ[ENV_VAR] = "1"
    os.environ.update(SETTINGS)
    if "torch" in sys.modules:
        problem = check()
        if problem:
            raise ReproducibleModeError(f"the reproducible mode could not be set: {problem}. Set "
                                        f"{' '.join(f'{k}={v}' for k, v in SETTINGS.items())} before torch "
                                        "is imported")


def environ(on: bool, base: dict | None = None) -> dict:
    """The environment of a new process (``base``, default this one's) with the mode on or off, whatever ``base``
    says: the way to start a process in a chosen mode, since the settings must be in place before its torch loads."""
    env = {k: v for k, v in (os.environ if base is None else base).items() if k not in SETTINGS}
    env[ENV_VAR] = "1" if on else "0"
    if on:
        env.update(SETTINGS)
    return env


def mkl_branch() -> int | None:
    """MKL's code branch in force (3 = COMPATIBLE), read from the MKL inside torch; None where it cannot be read
    (a torch without MKL, or MKL not loaded)."""
    if "torch" not in sys.modules:
        return None
    import torch

    if not torch.backends.mkl.is_available():
        return None
    try:
        lib = ctypes.CDLL(os.path.join(os.path.dirname(torch.__file__), "lib", "libtorch_cpu.so"))
        get = lib.mkl_serv_cbwr_get
    except (OSError, AttributeError):
        return None
    get.restype, get.argtypes = ctypes.c_int, [ctypes.c_int]
    return int(get(_MKL_CBWR_BRANCH))


def torch_isa() -> str:
    """The instruction set of ATen's kernels in this process (``AVX2``, ``AVX512``, ``DEFAULT``, ...)."""
    import torch

    return str(torch.backends.cpu.get_cpu_capability())


def check() -> str | None:
    """None when torch in this process runs the mode's kernels, else what differs (one line)."""
    isa = torch_isa()
    if isa != ISA:
        return f"torch's CPU kernels are {isa}, not {ISA} (ATEN_CPU_CAPABILITY)"
    branch = mkl_branch()
    if branch is not None and branch != _MKL_CBWR_COMPATIBLE:
        return f"MKL runs code branch {branch}, not COMPATIBLE ({_MKL_CBWR_COMPATIBLE}; MKL_CBWR)"
    try:
        gemm_library()
    except ReproducibleModeError as e:
        return str(e)
    return None


class GemmLibrary:
    """The pinned OpenBLAS, loaded for this process alone: ``sgemm`` is its row-major ``cblas_sgemm``."""

    ROW_MAJOR, NO_TRANS, TRANS = 101, 111, 112  # cblas.h

    def __init__(self, path: Path):
        self.path = path
        self._lib = ctypes.CDLL(str(path), mode=ctypes.RTLD_LOCAL)
        self._lib.scipy_openblas_get_corename.restype = ctypes.c_char_p
        self._lib.scipy_openblas_set_num_threads(1)
        self.core = self._lib.scipy_openblas_get_corename().decode()
        self.sgemm = self._lib.scipy_cblas_sgemm
        i, f, p = ctypes.c_int, ctypes.c_float, ctypes.c_void_p
        self.sgemm.argtypes = [i, i, i, i, i, i, f, p, i, p, i, f, p, i]
        self.sgemm.restype = None


@functools.cache
def gemm_library() -> GemmLibrary:
    """The mode's BLAS: the pinned OpenBLAS with its :data:`GEMM_CORE` kernels and one thread, loaded on first use.

    OpenBLAS reads ``OPENBLAS_CORETYPE`` and ``OPENBLAS_NUM_THREADS`` when it loads, so they are set for that
    moment only and this process's other BLAS (numpy's) keeps its own choice. Raises
    :class:`ReproducibleModeError` where the build is missing or the CPU cannot run those kernels."""
    flags = cpu_flags()
    if flags and not {"avx2", "fma"} <= flags:
        raise ReproducibleModeError(f"this CPU lacks AVX2 or FMA, which the pinned {GEMM_CORE} GEMM kernels need")
    try:
        import importlib.util

        found = importlib.util.find_spec(GEMM_PACKAGE)
    except (ImportError, ValueError):
        found = None
    path = Path(found.submodule_search_locations[0]) / "lib" / "libscipy_openblas.so" if found else None
    if path is None or not path.is_file():
        raise ReproducibleModeError(f"the pinned OpenBLAS ({GEMM_PACKAGE}, pyproject.toml) is not installed; "
                                    "`make install` installs it")
    wanted_env = {"OPENBLAS_CORETYPE": GEMM_CORE, "OPENBLAS_NUM_THREADS": "1"}
    before = {k: os.environ.get(k) for k in wanted_env}
    os.environ.update(wanted_env)
    try:
        lib = GemmLibrary(path)
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    if lib.core != GEMM_CORE:
        raise ReproducibleModeError(f"{path} runs its {lib.core} kernels, not {GEMM_CORE} (OPENBLAS_CORETYPE)")
    return lib


def cpu_flags() -> set[str]:
    """The CPU's feature flags (``/proc/cpuinfo``); empty where they cannot be read."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def mode() -> str:
    """``reproducible`` when this process's torch runs the mode's kernels, else ``vendor`` (what the CPU offers)."""
    return MODES[0] if check() is None else MODES[1]


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), e.g. ``AMD EPYC`` or ``Intel(R) Xeon(R) Platinum 8375C``."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine() -> dict:
    """What made a result: CPU model, torch's version, instruction set and threads, the mode, and in the mode its
    BLAS. Call it after torch computed something (ATen and MKL decide their kernels at their first use)."""
    import torch

    out = {"cpu": cpu_model(), "torch": torch.__version__, "isa": torch_isa(),
           "torch_threads": torch.get_num_threads(), "mode": mode()}
    if out["mode"] == MODES[0]:
        out["gemm"] = gemm_label()
    return out


def gemm_label() -> str:
    """The mode's BLAS in a few words: package, version and kernels, e.g. ``scipy-openblas32 0.3.34.481.3 Haswell``."""
    from importlib.metadata import version

    name = GEMM_PACKAGE.replace("_", "-")
    return f"{name} {version(name)} {gemm_library().core}"


def label(m: dict) -> str:
    """A :func:`machine` record in a few words: its CPU model, and the kernels' instruction set where torch ran
    outside the reproducible mode (its results then hold on that CPU kind only)."""
    return m.get("cpu", "?") + ("" if m.get("mode") == MODES[0] else f" ({m.get('isa', '?')}, vendor kernels)")


def torch_threads(configured: int) -> int:
    """Torch's intra-op threads for training: ``configured`` (``train.torch_threads``) when set; else one in the
    mode (a fixed order of sums whatever the machine) and torch's default (all cores) outside it."""
    if configured:
        return configured
    if mode() == MODES[0]:
        return 1
    import torch

    return torch.get_num_threads()
