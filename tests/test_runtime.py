"""The Taichi runtime: a clear error before Taichi's unchecked 512-tree limit, reset_taichi, and the arches refused."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest
import taichi as ti

from roshan import runtime
from roshan.kernels.fire import FireSim
from tests.conftest import make_map


def test_simulators_refuse_to_start_near_the_field_tree_limit(monkeypatch):
    FireSim(make_map(np.full((4, 4), 2)), num_envs=1)  # at least one tree exists now
    used = runtime.field_trees()
    assert used >= 1
    monkeypatch.setattr(runtime, "MAX_FIELD_TREES", used + runtime.TREE_HEADROOM - 1)
    with pytest.raises(RuntimeError, match=rf"FireSim: this process already holds {used} Taichi field trees"):
        FireSim(make_map(np.full((4, 4), 2)), num_envs=1)


@pytest.mark.slow
def test_reset_taichi_frees_every_field_tree():
    for _ in range(3):
        FireSim(make_map(np.full((4, 4), 2)), num_envs=2).reset()
    before = runtime.field_trees()
    assert before >= 3
    runtime.reset_taichi()
    assert runtime.current_arch() is None
    sim = FireSim(make_map(np.full((4, 4), 2)), num_envs=2)  # initialises Taichi again
    sim.reset()
    assert runtime.current_arch() == "cpu" and 1 <= runtime.field_trees() < before


def simulate_summary(arch: str) -> tuple[str, str]:
    """``roshan simulate`` of one seed on an arch with the refusal lifted: (Taichi's start line, summary)."""
    cmd = [sys.executable, "-m", "roshan", "simulate", "--map", "35x36_Woods", "--envs", "4", "--steps", "200",
           "--every", "100", "--seed", "1", "--arch", arch]
    env = {**os.environ, runtime.UNVERIFIED_ENV: arch}
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600, check=True)
    text = out.stdout + out.stderr
    started = re.search(r"Starting on arch=(\w+)", text)
    # Signed: Vulkan's counters come back as garbage (negative counts), which is part of why it is refused.
    summary = re.search(r"\((-?[\d.]+) s of fire\).*?all envs: burning (-?[\d.]+)", text, re.S)
    assert summary, text
    return (started.group(1) if started else "?"), summary.groups()


@pytest.mark.slow
def test_vulkan_is_refused_because_its_fire_differs_from_the_cpu():
    with pytest.raises(ValueError, match=r"--arch vulkan is refused: .*ROSHAN_UNVERIFIED_ARCH=vulkan"):
        runtime.init_taichi("vulkan")
    # The reason, kept true: the same seed on Vulkan (Mesa lavapipe, which CI installs) against the CPU.
    cpu = simulate_summary("cpu")
    assert cpu == ("x64", ("20.0", "18"))  # 200 updates of 0.1 s; 18 fires burning
    vulkan = simulate_summary("vulkan")
    if vulkan[0] != "vulkan":
        pytest.skip("no Vulkan driver here (apt-get install mesa-vulkan-drivers)")
    assert vulkan[1] != cpu[1], "Vulkan now matches the CPU on this seed: check 20 seeds and lift the refusal"


def test_taichi_runs_with_exact_math():
    """Fast math lets LLVM use vendor-specific approximate reciprocals and square roots; the FlyAgent's
    trajectories then differ between an Intel and an AMD CPU (issue 35). The runtime turns it off."""
    runtime.ensure_taichi()
    assert ti.lang.impl.current_cfg().fast_math is False


def test_the_suite_compiles_fast_here_and_in_its_subprocesses():
    """tests/conftest.py turns Taichi's advanced optimisation off for the suite (a cold suite is mostly compiling),
    in the environment, so the commands tests start compile fast too."""
    runtime.ensure_taichi()
    assert ti.lang.impl.current_cfg().advanced_optimization is False
    code = "from roshan.runtime import ensure_taichi; import taichi as ti; ensure_taichi(); " \
           "print(ti.lang.impl.current_cfg().advanced_optimization)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "False"


def test_the_kernel_cache_holds_all_of_this_packages_kernels(monkeypatch):
    """Taichi's default 100 MB disk cache evicts a quarter of itself when full; the suite's kernels outgrow it and
    were recompiled minutes after they were compiled (issue 31). The runtime raises the limit unless the user sets
    TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES, which Taichi then reads itself."""
    monkeypatch.delenv("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", raising=False)
    runtime.init_taichi("cpu")
    assert ti.lang.impl.current_cfg().offline_cache_max_size_of_files == runtime.OFFLINE_CACHE_BYTES >= 1 << 30


def test_float_arithmetic_is_evaluated_as_written():
    """What exact math buys: a kernel's f32 arithmetic rounds as written (numpy's bits), so no CPU's code generator
    may fuse a multiply-add, reassociate a sum or approximate a division. Under fast math LLVM folds
    ``(x + y) - x`` to ``y`` (this test then fails) and may fuse or approximate the rest, choices that vary with
    the target CPU (issue 35)."""
    runtime.ensure_taichi()
    rng = np.random.default_rng(0)
    x, y, z = (rng.uniform(-1e3, 1e3, 4096).astype(np.float32) for _ in range(3))
    out = np.zeros((4, 4096), np.float32)

    @ti.kernel
    def as_written(x: ti.types.ndarray(), y: ti.types.ndarray(), z: ti.types.ndarray(), out: ti.types.ndarray()):
        for i in range(x.shape[0]):
            out[0, i] = x[i] * y[i] + z[i]
            out[1, i] = (x[i] * 1e4 + y[i]) - x[i] * 1e4
            out[2, i] = x[i] / y[i]
            out[3, i] = 1.0 / ti.sqrt(ti.abs(z[i]))

    as_written(x, y, z, out)
    big = x * np.float32(1e4)
    np.testing.assert_array_equal(out[0], x * y + z)
    np.testing.assert_array_equal(out[1], (big + y) - big)
    np.testing.assert_array_equal(out[2], x / y)
    np.testing.assert_array_equal(out[3], np.float32(1.0) / np.sqrt(np.abs(z)))


def test_a_kernel_compile_error_still_names_its_file_and_line():
    """The start-up patch replaces Taichi's per-node caret diagrams with "File, line, function" and the source line:
    an error in a kernel must still say where."""
    runtime.ensure_taichi()
    assert ti.lang.ast.ast_transformer_utils.ASTTransformerContext.get_pos_info is runtime._plain_position

    @ti.kernel
    def broken() -> ti.i32:
        return undefined_name  # noqa: F821

    with pytest.raises(Exception) as err:
        broken()
    text = str(err.value)
    assert f'File "{__file__}"' in text and "in broken" in text and "return undefined_name" in text


def test_kernel_sources_are_looked_up_once_and_class_kernels_still_recognised():
    from taichi.lang import kernel_impl

    runtime.ensure_taichi()
    assert kernel_impl._inside_class.__module__ == "roshan.taichi_patches"
    assert hasattr(kernel_impl.getsourcelines, "uncached")

    @ti.data_oriented
    class Counter:
        def __init__(self):
            self.n = ti.field(ti.i32, ())

        @ti.kernel
        def bump(self, k: ti.i32):
            self.n[None] += k

    c = Counter()
    c.bump(2)
    c.bump(3)  # a class kernel taken for a free function would raise instead
    assert c.n[None] == 5


def test_taichi_is_patched_before_it_defines_its_own_kernels():
    """roshan.runtime imports Taichi through a one-shot hook that patches kernel_impl as it loads, so even the ~90
    kernels and functions that ``import taichi`` defines itself never call inspect.getframeinfo (each call scans
    sys.modules); no hook is left behind."""
    code = (
        "import inspect\n"
        "calls = []\n"
        "real = inspect.getframeinfo\n"
        "inspect.getframeinfo = lambda *a, **k: calls.append(1) or real(*a, **k)\n"
        "import sys\n"
        "hooks = list(sys.meta_path)\n"
        "import roshan.runtime\n"
        "from taichi.lang import kernel_impl\n"
        "assert kernel_impl._inside_class.__module__ == 'roshan.taichi_patches'\n"
        "assert sys.meta_path == hooks, sys.meta_path\n"
        "print(len(calls))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.split()[-1] == "0", out.stdout + out.stderr


def test_taichi_imported_before_roshan_is_patched_as_its_runtime_loads():
    code = ("import taichi\nfrom taichi.lang import kernel_impl\nimport roshan.runtime\n"
            "print(kernel_impl._inside_class.__module__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.split()[-1] == "roshan.taichi_patches", out.stdout + out.stderr


@pytest.mark.parametrize("cores,given,shared", [
    (2, (None, None), (2, 1)),   # neither given: one single-threaded run per core
    (2, (None, 2), (1, 2)),      # threads given: the workers that fit
    (16, (None, 4), (4, 4)),
    (2, (1, None), (1, None)),   # one worker: all cores
    (16, (4, None), (4, 4)),     # workers given: the cores split between them
    (2, (3, 1), (3, 1)),         # both given: as given
])
def test_runs_share_the_cores(monkeypatch, cores, given, shared):
    monkeypatch.setattr(runtime, "cpu_cores", lambda: cores)
    assert runtime.share_cores(*given) == shared
