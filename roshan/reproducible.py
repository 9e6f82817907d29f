"""The reproducible mode: torch's CPU kernels pinned so that a seed gives the same weights on every x86-64 CPU.

The Taichi kernels already give the same bits on every CPU (exact math, :mod:`roshan.runtime`). Torch does not by
itself: it picks its CPU code by what the processor offers, and two of its choices round differently.

- **MKL's GEMMs** (every ``Linear``): MKL dispatches by vendor as well as instruction set. Its conditional numerical
  reproducibility (``MKL_CBWR``) pins a code branch, but a branch named by instruction set (``AVX2``, ``AVX512``)
  holds on Intel CPUs only; elsewhere MKL falls back to its ``AUTO`` branch (measured on an AMD EPYC: ``AVX2``,
  ``AVX512`` and ``AUTO`` all gave one fingerprint, and MKL itself reports branch ``AUTO`` there). ``COMPATIBLE``
  (SSE2 without approximate reciprocals) is the one branch documented to give the same results on Intel and
  compatible processors.
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
import os
import platform
import sys

ENV_VAR = "ROSHAN_REPRODUCIBLE"  # "0" turns the mode off for the commands that enable it by default
SETTINGS = {"ATEN_CPU_CAPABILITY": "avx2", "MKL_CBWR": "COMPATIBLE"}
ISA = "AVX2"  # what torch.backends.cpu.get_cpu_capability() reports once ATEN_CPU_CAPABILITY=avx2 took effect
_MKL_CBWR_BRANCH = 1  # mkl_cbwr.h: mkl_cbwr_get(MKL_CBWR_BRANCH) returns the branch in force
_MKL_CBWR_COMPATIBLE = 3
MODES = ("reproducible", "vendor")


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
    return None


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
    """What made a result: CPU model, torch's version, instruction set and threads, and the mode. Call it after
    torch computed something (ATen and MKL decide their kernels at their first use)."""
    import torch

    return {"cpu": cpu_model(), "torch": torch.__version__, "isa": torch_isa(),
            "torch_threads": torch.get_num_threads(), "mode": mode()}


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
