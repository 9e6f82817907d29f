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
    0x5EED). The quantiles are computed once for all seeds, by :func:`exact_quantiles`."""
    q = exact_quantiles(TABLE_SIZE).astype(np.float32)
    tables = []
    for seed in seeds or (0x5EED,):
        t = q.copy()
        np.random.default_rng(seed).shuffle(t)
        tables.append(t)
    return tables


# Wichura's AS241 central-region coefficients, highest power first, as Python's statistics.NormalDist uses them.
_AS241_NUM = (2.5090809287301226727e+3, 3.3430575583588128105e+4, 6.7265770927008700853e+4, 4.5921953931549871457e+4,
              1.3731693765509461125e+4, 1.9715909503065514427e+3, 1.3314166789178437745e+2, 3.3871328727963666080e+0)
_AS241_DEN = (5.2264952788528545610e+3, 2.8729085735721942674e+4, 3.9307895800092710610e+4, 2.1213794301586595867e+4,
              5.3941960214247511077e+3, 6.8718700749205790830e+2, 4.2313330701600911252e+1, 1.0)


def exact_quantiles(n: int) -> np.ndarray:
    """``statistics.NormalDist().inv_cdf((k + 0.5) / n)`` for k < n, bit for bit, as float64.

    The 85 % of points in AS241's central region (|p - 0.5| <= 0.425, a rational function) are evaluated with
    numpy in the same order of operations, which rounds exactly as the scalar code; the tails (a logarithm) still
    go through ``inv_cdf`` itself. 65,536 ``inv_cdf`` calls from Python cost ~40 ms of every start.
    """
    p = (np.arange(n, dtype=np.float64) + 0.5) / n
    q = p - 0.5
    central = np.abs(q) <= 0.425
    qc = q[central]
    r = 0.180625 - qc * qc
    num = np.full_like(r, _AS241_NUM[0])
    den = np.full_like(r, _AS241_DEN[0])
    for a, b in zip(_AS241_NUM[1:], _AS241_DEN[1:], strict=True):
        num = num * r + a
        den = den * r + b
    out = np.empty(n, dtype=np.float64)
    out[central] = num * qc / den
    nd = statistics.NormalDist()
    out[~central] = [nd.inv_cdf(x) for x in p[~central].tolist()]
    return out


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
