"""Where a cold test suite's time goes: with this folder on PYTHONPATH and COMPILE_PROFILE_LOG set, every Python
process (pytest and the commands its tests start) logs Taichi's AST transform of each kernel instance it builds and
the first launch of each compiled kernel (the compile, or the offline cache's load, plus one run), one
tab-separated line each: pid, event (ast / launch1), kernel, seconds, the test running (PYTEST_CURRENT_TEST).

    rm -rf /tmp/ticold
    COMPILE_PROFILE_LOG=/tmp/compile.tsv TI_OFFLINE_CACHE_FILE_PATH=/tmp/ticold \\
        PYTHONPATH=benchmarks/compile_profile python -m pytest -q
    python benchmarks/scripts/compile_profile_summary.py /tmp/compile.tsv

Taichi is patched as it loads (a meta path finder), so a process that never imports it pays nothing.
"""

import importlib.abc
import importlib.util
import os
import sys
import time

LOG = os.environ.get("COMPILE_PROFILE_LOG")


def _write(event: str, name: str, seconds: float) -> None:
    test = os.environ.get("PYTEST_CURRENT_TEST", "-").split(" ")[0]
    with open(LOG, "a") as f:
        f.write(f"{os.getpid()}\t{event}\t{name}\t{seconds:.4f}\t{test}\n")


def _patch(kernel_impl) -> None:
    kernel = kernel_impl.Kernel
    materialize, launch_kernel = kernel.materialize, kernel.launch_kernel
    launched: set[int] = set()

    def timed_materialize(self, key=None, args=None, arg_features=None):
        new = key is None or key not in self.compiled_kernels
        start = time.perf_counter()
        out = materialize(self, key, args, arg_features)
        if new:
            _write("ast", self.func.__qualname__, time.perf_counter() - start)
        return out

    def timed_launch(self, t_kernel, *args):
        first = id(t_kernel) not in launched
        start = time.perf_counter()
        out = launch_kernel(self, t_kernel, *args)
        if first:
            launched.add(id(t_kernel))
            _write("launch1", self.func.__qualname__, time.perf_counter() - start)
        return out

    kernel.materialize, kernel.launch_kernel = timed_materialize, timed_launch


class _PatchTaichiOnLoad(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name != "taichi.lang.kernel_impl":
            return None
        sys.meta_path.remove(self)
        try:
            spec = importlib.util.find_spec(name)
        finally:
            sys.meta_path.insert(0, self)
        exec_module = spec.loader.exec_module

        def exec_and_patch(module):
            exec_module(module)
            _patch(module)

        spec.loader.exec_module = exec_and_patch
        return spec


if LOG:
    sys.meta_path.insert(0, _PatchTaichiOnLoad())
