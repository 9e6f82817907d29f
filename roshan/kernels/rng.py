"""Counter-based random numbers: a hash of (seed, env, episode, step, id, draw), never a stateful stream.

A trajectory therefore depends on the seed alone, not on thread count or launch order. Normal deviates come
from a fixed table of 2**16 exact normal quantiles indexed by 16 hash bits (the original also reuses a
pre-generated ring buffer of normals, docs/model/fire.md §12); one 32-bit hash thus yields two independent normals.
"""


import statistics

import numpy as np
import taichi as ti

TABLE_BITS = 16
TABLE_SIZE = 1 << TABLE_BITS
TABLE_MASK = TABLE_SIZE - 1
TWO_PI = 6.283185307179586

# Stream domains: keep the draws of different processes apart even for equal (step, id).
DOMAIN_CONVECTION = 1
DOMAIN_RADIATION = 2
DOMAIN_EMISSION = 3
DOMAIN_CELLS = 4
DOMAIN_EPISODE = 5
DOMAIN_IGNITION = 6
DOMAIN_DRONES = 7


@ti.func
def mix32(x: ti.u32) -> ti.u32:
    """lowbias32 (Chris Wellons' hash prospector): a full-avalanche 32-bit integer hash."""
    x ^= x >> ti.u32(16)
    x *= ti.u32(0x7FEB352D)
    x ^= x >> ti.u32(15)
    x *= ti.u32(0x846CA68B)
    x ^= x >> ti.u32(16)
    return x


@ti.func
def key(base: ti.u32, a: ti.i32, b: ti.i32) -> ti.u32:
    """Derive a key from a base key and two integers (e.g. an id and a draw index)."""
    return mix32(mix32(base ^ ti.cast(a, ti.u32) * ti.u32(0x9E3779B9)) + ti.cast(b, ti.u32) * ti.u32(0x85EBCA6B))


@ti.func
def uniform(h: ti.u32) -> ti.f32:
    """A float in [0, 1) from the top 24 bits of a hash."""
    return ti.cast(h >> ti.u32(8), ti.f32) * (1.0 / 16777216.0)


@ti.func
def uniform_int(h: ti.u32, n: ti.i32) -> ti.i32:
    """An integer in [0, n) (n > 0); the bias is below 2**-24 for the map sizes we use."""
    return ti.min(ti.cast(uniform(h) * ti.cast(n, ti.f32), ti.i32), n - 1)


@ti.func
def low16(h: ti.u32) -> ti.i32:
    """Table index from the low 16 bits of a hash."""
    return ti.cast(h & ti.u32(TABLE_MASK), ti.i32)


@ti.func
def high16(h: ti.u32) -> ti.i32:
    """Table index from the high 16 bits of a hash (independent of :func:`low16`)."""
    return ti.cast(h >> ti.u32(16), ti.i32)


def normal_quantiles(*seeds: int) -> list[np.ndarray]:
    """The exact N(0, 1) quantiles at (k + 0.5) / TABLE_SIZE, one copy shuffled with each fixed seed (default
    0x5EED). The quantiles are computed once for all seeds: 65,536 pure-Python ``inv_cdf`` calls cost ~40 ms."""
    nd = statistics.NormalDist()
    q = np.array([nd.inv_cdf((k + 0.5) / TABLE_SIZE) for k in range(TABLE_SIZE)], dtype=np.float32)
    tables = []
    for seed in seeds or (0x5EED,):
        t = q.copy()
        np.random.default_rng(seed).shuffle(t)
        tables.append(t)
    return tables


def base_key(seed: int, *parts: int) -> int:
    """Host-side twin of :func:`key` chains, for per-env episode keys (pure Python, exact u32 arithmetic)."""
    h = _mix32_py(seed & 0xFFFFFFFF)
    for p in parts:
        h = _mix32_py((h ^ ((p * 0x9E3779B9) & 0xFFFFFFFF)) & 0xFFFFFFFF)
    return h


def _mix32_py(x: int) -> int:
    x &= 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    x ^= x >> 16
    return x
