"""How the fire's fields are laid out and how big they are, decided from the map, the env count and the config
before anything is allocated: dense or sparse cell records, list and particle pool capacities, the loop shape
(env-serial or chunked, the env loops' padding) and the bytes all of it takes.

:class:`roshan.kernels.fire.FireSim` allocates exactly :func:`fire_sizes`; the memory estimate of a build
(:mod:`roshan.kernels.pool`) reads the same sizes without building anything.
"""

from dataclasses import dataclass

import taichi as ti
import taichi.lang.impl as impl
from taichi.lang.field import ScalarField

from roshan.config import FireConfig, IgnitionConfig
from roshan.kernels import particles as pt
from roshan.kernels import rng
from roshan.kernels.fire_parallel import scratch_bytes
from roshan.kernels.fire_records import (
    BLOCK_CELLS,
    BLOCK_SIDE,
    CELL_FIELDS,
    N_COUNTS,
    T_BURN_LEFT,
    T_BURN_TIME,
    T_EXPOSURE,
    T_FLOOD,
    T_IGN,
    TIMER_FIELDS,
)
from roshan.maps import CLASSES, initial_fire_count
from roshan.runtime import current_arch


def default_capacities(num_cells: int, sparse_cells: int | None = None, num_fires: int = 0) -> tuple[int, int]:
    """Particle pool sizes per env.

    Dense layout: one convection and two radiation slots per cell, at least 1024 / 2048; the reference peaks
    (shared/reference) stay below 0.4 convection and 0.8 radiation particles per cell of a map that burns
    whole. Sparse layout (a fire that stays small next to its map): 1.5 slots of each kind per initial fire,
    at least a sixteenth of the block pool's cells. Measured over 50,000 updates of a 1.5 % fire (2 clusters,
    seeds 0 and 1): peaks of 0.58-0.77 convection and 0.6-0.66 radiation particles per initial fire on
    Borkenberge and the 941k-cell map.
    """
    if sparse_cells is not None:
        conv = rad = max(3 * num_fires // 2, sparse_cells // 16)
        return max(1024, conv), max(2048, rad)
    return max(1024, num_cells), max(2048, 2 * num_cells)


def block_grid(rows: int, cols: int) -> tuple[int, int]:
    """Blocks along the rows and the columns of a map (edge blocks are partly outside it)."""
    return -(-rows // BLOCK_SIDE), -(-cols // BLOCK_SIDE)


def default_block_capacity(num_blocks: int, num_fires: int) -> int:
    """Blocks per env the sparse pool holds: six per 64 initial fires plus 200, at most the map's.

    The footprint grows with the fires lit at the reset, not with the map: over 50,000 updates of a 1.5 %
    fire (2 clusters) the fire, its particles and the generator touched 412-517 blocks of Borkenberge (5,468
    fires) and 664-879 of the 941k-cell map (14,112 fires), 3-6 blocks per 64 fires (`roshan bench memory`
    and seeds 0 and 1). This gives those maps 1.4x and 1.7x the largest peak, within the memory targets of
    4 and 8 MiB per env.
    """
    return min(num_blocks, 6 * -(-num_fires // BLOCK_CELLS) + 200)


DENSE_BUDGET_BYTES = 1 << 30  # auto: every env stays dense while the dense records of all envs fit in 1 GiB
RECORD_BYTES = 4 * (CELL_FIELDS + 1) + 8 * TIMER_FIELDS + 1  # ints, mark, f64 timers, lit flag
# The timers each pass reads together sit together: the burning pass touches only the 16 bytes of its two
# timers per cell instead of a 40-byte record, so on a big map its working set fits the cache far better.
TIMER_GROUPS = ((T_BURN_TIME, T_BURN_LEFT), (T_IGN, T_EXPOSURE), (T_FLOOD,))
LIST_BYTES = 3 * 4  # burning, exposed and flooded lists, one i32 each per record


def grouped_vector_field(dtype, shape, groups) -> ti.MatrixField:
    """A vector field whose components are stored in groups, each group as its own array of small records
    (Taichi's AOS and SOA layouts are the two extremes of this). Accessed like any vector field."""
    n = sum(len(g) for g in groups)
    assert sorted(k for g in groups for k in g) == list(range(n))
    field = ti.Vector.field(n, dtype)
    members = field._get_field_members()  # Taichi 1.7's SOA layout places these one by one, as done here
    for group in groups:
        ti.root.dense(ti.ij, shape).place(*[ScalarField(members[k]) for k in group])
    return field


def dense_bytes_per_env(num_cells: int) -> int:
    """Field memory of one env in the dense layout (records, lists and the default particle pools)."""
    conv, rad = default_capacities(num_cells)
    return num_cells * (RECORD_BYTES + LIST_BYTES) + 4 * (pt.CONV_FIELDS * conv + pt.RAD_FIELDS * rad)


def choose_layout(layout: str, num_cells: int, block_capacity: int, num_envs: int = 1) -> str:
    """``auto`` is sparse where the block pool holds under half the map's cells (elsewhere the indirection
    costs more than it saves) and the dense layout of all ``num_envs`` envs would take over 1 GiB.

    The memory bound, not the map alone, decides, because the sparse layout is slower per update on a big map:
    every record access first reads the cell's block slot, a dependent load the dense layout does not have
    (one env on Borkenberge or the 941k-cell map: 0.66-0.68x the dense updates per second, BENCHMARKS "Fire
    memory"). A few envs of a big map fit dense and run faster; many do not fit any other way.
    """
    if layout != "auto":
        return layout
    if block_capacity * BLOCK_CELLS * 2 > num_cells:
        return "dense"
    return "sparse" if num_envs * dense_bytes_per_env(num_cells) > DENSE_BUDGET_BYTES else "dense"


# auto: the chunked update only where an env lights this many fires at its reset. Measured on this 2-core VM
# (BENCHMARKS "A parallel path inside one env"): 2 threads give 1.49x the env-serial update with 329k fires
# (941k-cell map, 35 %), tie with it at 128k (Borkenberge, 35 %) and are 2.6-4x slower at 1.5 %, where Taichi's
# ~30 us per parallel task and ~100 us per kernel launch outweigh a 90-190 us update.
CHUNKS_MIN_FIRES = 250_000


def cpu_threads() -> int:
    """Threads Taichi's CPU backend runs a parallel loop on."""
    return max(1, impl.current_cfg().cpu_max_num_threads)


def choose_parallel(parallel: str, num_envs: int, num_fires: int, threads: int | None = None) -> str:
    """``auto`` is ``chunks`` on the CPU where the envs leave threads idle and the fire is huge, else ``envs``."""
    if parallel != "auto":
        return parallel
    if current_arch() not in (None, "cpu"):
        return "envs"  # not measured on a GPU
    threads = cpu_threads() if threads is None else threads
    return "chunks" if 1 < threads and num_envs < threads and num_fires >= CHUNKS_MIN_FIRES else "envs"


def env_loop_padding(num_envs: int) -> int:
    """How far apart env indices sit in the index space of the heavy per-env loops.

    Taichi 1.7's CPU backend gives every task of a parallel range-for at least 512 iterations (adaptive block
    size), so a loop over fewer than ~1024 envs runs on one thread. The env loops iterate over
    ``num_envs * pad`` indices instead, and only every ``pad``-th does an env's work, so that even 2 envs
    land in different tasks. Measured: two threads busy at every E instead of one below E = 1024.
    """
    if current_arch() not in (None, "cpu") or num_envs == 1:
        return 1  # GPUs schedule one thread per iteration anyway; one env is one task whatever the padding
    return max(1, -(-1024 * cpu_threads() // num_envs))


def env_loop_serial(num_envs: int) -> bool:
    """True where the per-env loops run on the launching thread: one env on the CPU.

    Taichi's CPU backend hands each parallel loop to its thread pool, and waking the pool costs 30-60 us per loop
    here (a kernel of one parallel range-for over one index: 34 us on 2 threads, 66 us on 1; the same loop
    serialised: 1-2 us). One env is one task anyway, so it loses nothing by running serially.
    """
    return num_envs == 1 and current_arch() in (None, "cpu")


# Bytes per env beyond the records, lists and pools (wind, episode, env key, generator counter), per class of the
# class table (ignitable, n_conv, n_rad, tau_ign, tau_burn: 4 B; lr, sf: 8 B) and per entry of the random tables.
ENV_SCALAR_BYTES = 8 + 4 + 4 + 4
CLASS_BYTES = 5 * 4 + 2 * 8
TABLE_BYTES = 4 + 8


@dataclass(frozen=True)
class FireSizes:
    """The field sizes of a :class:`FireSim`, decided from the map, the env count and the config before anything
    is allocated: FireSim allocates exactly these, and the memory estimate reads them (:func:`fire_sizes`)."""

    rows: int
    cols: int
    num_envs: int
    layout: str  # "dense" or "sparse"
    num_blocks: int  # 8x8 blocks covering the map
    block_capacity: int  # blocks per env in the sparse pool; 0 when dense
    record_capacity: int  # cell records per env
    list_capacity: int  # entries of each cell list per env
    conv_capacity: int
    rad_capacity: int
    num_fires: int  # fires the generator lights at a reset

    @property
    def num_cells(self) -> int:
        return self.rows * self.cols

    @property
    def sparse(self) -> bool:
        return self.layout == "sparse"

    def bytes_per_env(self) -> int:
        """Field bytes one env holds: cell records, lists, block tables, particle pools and counters."""
        tables = 4 * (self.num_blocks + self.block_capacity) if self.sparse else 0
        return (self.record_capacity * RECORD_BYTES + LIST_BYTES * self.list_capacity + tables
                + 4 * (pt.CONV_FIELDS * self.conv_capacity + pt.RAD_FIELDS * self.rad_capacity)
                + 4 * (N_COUNTS + 8))

    def shared_bytes(self) -> int:
        """Field bytes the envs share: the map, the sparse layout's cell-to-block table, the class and random
        tables."""
        cells = 4 * self.num_cells * (2 if self.sparse else 1)
        return cells + CLASS_BYTES * len(CLASSES) + TABLE_BYTES * rng.TABLE_SIZE

    def estimate_bytes(self, chunked: bool = False) -> int:
        """Every byte a FireSim of these sizes allocates: its fields, the chunked update's scratch (``chunked``)
        and the host arrays of its counters."""
        scratch = scratch_bytes(self.conv_capacity, self.rad_capacity, self.list_capacity) if chunked else 0
        host = self.num_envs * 4 * (N_COUNTS + 1)
        return (self.num_envs * (self.bytes_per_env() + ENV_SCALAR_BYTES) + self.shared_bytes() + scratch
                + host)

    def pristine_bytes(self) -> int:
        """Bytes of the fields that hold other values than zero once built (map, block tables, episode numbers,
        class and random tables): :mod:`roshan.kernels.pool` keeps a copy of those to restore a reused bundle."""
        per_env = 4 + (4 * self.num_blocks if self.sparse else 0)
        return self.num_envs * per_env + self.shared_bytes()

    def ways_out(self) -> list[str]:
        """The settings that make these fields smaller, as a memory refusal suggests them."""
        ways = ["fewer envs (--envs / sim.envs)"]
        if self.sparse:
            ways.append(f"a smaller fire.block_capacity (now {self.block_capacity:,} blocks per env)")
        else:
            ways.append("the sparse layout (fire.layout=sparse: 8x8 blocks only where the fire goes)")
        ways.append(f"smaller fire.conv_capacity / fire.rad_capacity (now {self.conv_capacity:,} / "
                    f"{self.rad_capacity:,} particles per env)")
        return ways

    def describe(self, name: str) -> str:
        """``N env(s) of map 'name' (R x C cells, layout)`` for messages."""
        return (f"{self.num_envs:,} env{'s' * (self.num_envs != 1)} of map {name!r} ({self.rows:,} x {self.cols:,} "
                f"cells, {self.layout} layout)")


def fire_sizes(rows: int, cols: int, fire: FireConfig, ignition: IgnitionConfig, num_envs: int) -> FireSizes:
    """Layout, record and list capacities and particle pool sizes of ``num_envs`` envs of a rows x cols map (see
    :mod:`roshan.kernels.fire`, :func:`choose_layout` and :func:`default_capacities`)."""
    num_cells = rows * cols
    block_rows, block_cols = block_grid(rows, cols)
    num_blocks = block_rows * block_cols
    num_fires = initial_fire_count(num_cells, ignition.fire_percentage)
    block_capacity = min(num_blocks, fire.block_capacity or default_block_capacity(num_blocks, num_fires))
    layout = choose_layout(fire.layout, num_cells, block_capacity, num_envs)
    if layout == "sparse":
        record_capacity = block_capacity * BLOCK_CELLS
        list_capacity = min(num_cells, record_capacity)  # a listed cell has a record
        auto_conv, auto_rad = default_capacities(num_cells, list_capacity, num_fires)
    else:
        block_capacity = 0
        record_capacity = list_capacity = num_cells
        auto_conv, auto_rad = default_capacities(num_cells)
    return FireSizes(rows, cols, num_envs, layout, num_blocks, block_capacity, record_capacity, list_capacity,
                     fire.conv_capacity or auto_conv, fire.rad_capacity or auto_rad, num_fires)

