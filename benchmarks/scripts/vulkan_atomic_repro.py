"""The smallest kernel we found that runs wrong on Vulkan (Mesa lavapipe, Taichi 1.7.4): why `--arch vulkan` is
refused (roshan.runtime.WRONG_ARCHES, issue 17).

A field `+=` that Taichi cannot prove private to the thread is an atomic add; inside a loop under a divergent
branch it loses updates. The same loop with a plain load and store, or with the thread's own index (which Taichi
demotes to a plain store), is right. The fire kernels update per-env counters with `+=` inside per-env loops
and branches, which is this shape; that it is the whole story is not shown yet (a FireSim on Vulkan, whose env
loops are not padded, still makes 2 updates in a launch of 100).

    python benchmarks/scripts/vulkan_atomic_repro.py      # needs a Vulkan driver (apt-get install mesa-vulkan-drivers)
"""

import taichi as ti

ti.init(arch=ti.vulkan, log_level=ti.WARN)
counts = ti.field(ti.i32, 32)


@ti.kernel
def atomic_add(n: ti.i32):
    for v in range(32):
        if v % 8 == 0:
            for _ in range(n):
                counts[v // 8] += 1  # atomic: wrong


@ti.kernel
def load_store(n: ti.i32):
    for v in range(32):
        if v % 8 == 0:
            for _ in range(n):
                counts[v // 8] = counts[v // 8] + 1  # plain: right


@ti.kernel
def own_index(n: ti.i32):
    for v in range(32):
        if v % 8 == 0:
            for _ in range(n):
                counts[v] += 1  # demoted to a plain store: right


for kernel, where in ((atomic_add, slice(0, 4)), (load_store, slice(0, 4)), (own_index, slice(0, 32, 8))):
    counts.fill(0)
    kernel(100)
    print(f"{kernel.__name__:>10}: {counts.to_numpy()[where]} (expected 100 each)")
