"""FireSPIN on E independent copies of one land-cover map: cells, particles and their exchange (docs/model/fire.md).

One parallel loop runs over environments; each env's sparse work (its burning, exposed and flooded cell lists
and its particle pools) is done serially inside it. That keeps a step's cost proportional to the fire, not the
map, makes the order of every update fixed (so a seed fixes the trajectory whatever the thread count) and costs
one kernel launch per call however many envs or steps it advances.

Cell records live in one of two layouts behind the same accessors (``_rec`` / ``_touch``): dense, a record per
cell, or sparse, a per-env pool of 8 x 8 blocks that a block joins when fire, particles, water or the generator
first write to one of its cells and leaves at the reset, so memory and reset cost follow the fire's footprint.
The pool is plain fields (not Taichi ``pointer`` SNodes: those keep their memory when a field tree is destroyed,
Taichi issue 5777, and do not exist on Vulkan), handed out in the fixed order of the env's serial updates, so
a trajectory is the same in either layout. A full pool is counted (``dropped_blocks``), never silent.

Cell timers are f64 sums of ``dt`` exactly as the reference accumulates them: with dt = 0.1 the sums run
slightly below whole numbers, so most whole-second emissions and the burn-out of unrandomised cells happen one
update after the integer count would say. Those events are synchronised across every cell lit at t = 0, so the
difference shows at the reference's checkpoints (e.g. a third of the forest burns out at update 36,001, not
36,000); integer step counters would not match it.
"""


import math
from dataclasses import dataclass

import numpy as np
import taichi as ti
import taichi.lang.impl as impl
from taichi.lang.field import ScalarField

from roshan.config import FireConfig, IgnitionConfig, WindConfig
from roshan.kernels import particles as pt
from roshan.kernels import rng
from roshan.kernels.fire_parallel import ChunkedStep, scratch_bytes
from roshan.kernels.fire_records import (
    BLOCK_CELLS,
    BLOCK_SHIFT,
    BLOCK_SIDE,
    BURNED_OUT,
    C_FLAGS,
    C_PERIODS,
    C_STATE,
    C_VISIT,
    CELL_FIELDS,
    EMIT_CONV,
    EMIT_RAD,
    FLAG_BURNED_DOWN,
    FLAG_DRAWN,
    FLAG_EXPOSED,
    FLAG_EXTINGUISHED,
    N_BLOCKS,
    N_BURNED,
    N_BURNING,
    N_CONV,
    N_COUNTS,
    N_DROP_BLOCK,
    N_DROP_CONV,
    N_DROP_RAD,
    N_EXPOSED,
    N_EXTINGUISHED,
    N_FLOODED,
    N_IGNITED_INIT,
    N_IGNITION_SHORT,
    N_LIT,
    N_RAD,
    N_STEP,
    NEVER,
    STAT_NAMES,
    T_BURN_LEFT,
    T_BURN_TIME,
    T_EXPOSURE,
    T_FLOOD,
    T_IGN,
    TIMER_FIELDS,
)
from roshan.kernels.ignition import PATTERNS, light_initial_fires
from roshan.maps import BURNED, BURNING, CLASSES, FLOODED, GENERIC_UNBURNED, LandCoverMap, initial_fire_count
from roshan.memory import check_fits
from roshan.runtime import check_built_in_this_runtime, check_field_room, current_arch, ensure_taichi, taichi_generation


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


def _grouped_vector_field(dtype, shape, groups) -> ti.MatrixField:
    """A vector field whose components are stored in groups, each group as its own array of small records
    (Taichi's AOS and SOA layouts are the two extremes of this). Accessed like any vector field."""
    n = sum(len(g) for g in groups)
    assert sorted(k for g in groups for k in g) == list(range(n))
    field = ti.Vector.field(n, dtype)
    members = field._get_field_members()  # Taichi 1.7's SOA layout places these one by one, as done here
    for group in groups:
        ti.root.dense(ti.ij, shape).place(*[ScalarField(members[k]) for k in group])
    return field


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
    the module docstring, :func:`choose_layout` and :func:`default_capacities`)."""
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


@ti.data_oriented
class FireSim:
    """E FireSPIN environments on the same map, each with its own fire, wind and random stream.

    Args:
        land: the land-cover map every env simulates.
        fire, wind, ignition: model sections (``roshan.config``).
        num_envs: E.
        seed: seed of all random streams; env ``e`` of episode ``k`` draws from hash(seed, e, k, ...).
        check_memory: refuse (:class:`roshan.memory.MemoryLimitError`) before allocating what would not fit in the
            memory available; False where the caller has checked a larger build that holds this one
            (:mod:`roshan.kernels.pool`).
    """

    def __init__(self, land: LandCoverMap, fire: FireConfig | None = None, wind: WindConfig | None = None,
                 ignition: IgnitionConfig | None = None, num_envs: int = 1, seed: int = 0, check_memory: bool = True):
        ensure_taichi()
        check_field_room("FireSim")
        self._taichi_generation = taichi_generation()  # reset/step refuse to run on a reset runtime
        self.land_map = land
        self.fire_cfg = fire = fire or FireConfig()
        self.wind_cfg = wind = wind or WindConfig()
        self.ignition_cfg = ignition = ignition or IgnitionConfig()
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.num_envs = num_envs
        self.seed = int(seed)
        self.rows, self.cols = land.shape
        self.num_cells = self.rows * self.cols
        self.cell_size = float(land.cell_size)
        self._choose_layout(fire, ignition, check_memory)
        self._bake_constants()
        self.env_pad = env_loop_padding(num_envs)
        self.serial_envs = env_loop_serial(num_envs)  # kernels: ti.loop_config(serialize=...) on their env loops

        E, N, R = num_envs, self.num_cells, self.record_capacity
        self.land = ti.field(ti.i32, N)
        class_ints, class_floats = self._alloc_class_table(land)
        # Cell records, (E, R): record r of env e is cell r (dense) or cell (r & 63) of its block slot r >> 6.
        self.cells = ti.Vector.field(CELL_FIELDS, ti.i32, (E, R))
        self.timers = _grouped_vector_field(ti.f64, (E, R), TIMER_GROUPS)
        self.mark = ti.field(ti.i32, (E, R))  # generator scratch: used / visited-by-cluster
        # 1 once the cell has burned this episode. The cell state cannot say it: an extinguished cell is FLOODED
        # (as is a flooded unburned one) and returns to its class when the flood drains. Counted in N_LIT.
        self.lit = ti.field(ti.u8, (E, R))
        if self.sparse:
            self._alloc_block_pool(land)
        L = self.list_capacity
        self.burning = ti.field(ti.i32, (E, L))  # flat cell indices; also the generator's list of lit cells
        self.exposed = ti.field(ti.i32, (E, L))  # also the generator's BFS queue
        self.flooded = ti.field(ti.i32, (E, L))
        self.cand = ti.field(ti.i32, (E, 8))  # generator scratch: Moore neighbour candidates
        self.counts = ti.field(ti.i32, (E, N_COUNTS))
        self.conv = ti.Vector.field(pt.CONV_FIELDS, ti.f32, (E, self.conv_capacity))
        self.rad = ti.Vector.field(pt.RAD_FIELDS, ti.f32, (E, self.rad_capacity))
        self.wind = ti.Vector.field(2, ti.f32, E)
        self.episode = ti.field(ti.i32, E)  # resets so far
        self.env_key = ti.field(ti.u32, E)  # hash(seed, env, episode): the root of the env's streams
        self.gen_ctr = ti.field(ti.i32, E)  # draw counter of the serial initial-fire generator
        self.normals = ti.field(ti.f32, rng.TABLE_SIZE)
        self.unit = ti.Vector.field(2, ti.f32, rng.TABLE_SIZE)
        q, q_angles = rng.normal_quantiles(0x5EED, 0xA11CE)
        angles = 2.0 * np.pi * q_angles.astype(np.float64)
        self._load_tables(np.ascontiguousarray(land.classes.reshape(-1), dtype=np.int32), class_ints, class_floats,
                          q, np.stack([np.cos(angles), np.sin(angles)], axis=1).astype(np.float32))
        self._all = np.ones(E, dtype=np.int32)
        self._counts_host = np.zeros((E, N_COUNTS), dtype=np.int32)  # what step() and counters() read into
        self.chunked = ChunkedStep(self) if self.parallel == "chunks" else None

    # ------------------------------------------------------------------------------------------ setup

    def _choose_layout(self, fire: FireConfig, ignition: IgnitionConfig, check_memory: bool) -> None:
        """Layout, record and list capacities, and particle pool sizes (see the module docstring); refuses, before
        anything is allocated, a simulator that would not fit in the memory available (``check_memory``)."""
        self.sizes = z = fire_sizes(self.rows, self.cols, fire, ignition, self.num_envs)
        self.block_rows, self.block_cols = block_grid(self.rows, self.cols)
        self.num_blocks, self.block_capacity, self.layout = z.num_blocks, z.block_capacity, z.layout
        self.sparse = z.sparse
        self.record_capacity, self.list_capacity = z.record_capacity, z.list_capacity
        self.conv_capacity, self.rad_capacity = z.conv_capacity, z.rad_capacity
        self.parallel = choose_parallel(fire.parallel, self.num_envs, z.num_fires)
        if check_memory:
            check_fits(f"FireSim: {z.describe(self.land_map.name)}", z.estimate_bytes(self.parallel == "chunks"),
                       z.ways_out(), current_arch())

    def _alloc_block_pool(self, land: LandCoverMap) -> None:
        """The sparse layout's tables: each cell's block and place in it, and each env's block slots."""
        i, j = np.divmod(np.arange(self.num_cells, dtype=np.int64), self.cols)
        block = (i // BLOCK_SIDE) * self.block_cols + j // BLOCK_SIDE
        place = (i % BLOCK_SIDE) * BLOCK_SIDE + j % BLOCK_SIDE
        self.cell_block = ti.field(ti.i32, self.num_cells)  # block << 6 | place of every cell (shared by envs)
        self.cell_block.from_numpy(((block << BLOCK_SHIFT) | place).astype(np.int32))
        self.block_slot = ti.field(ti.i32, (self.num_envs, self.num_blocks))  # slot of a block, -1 = no record
        self.block_slot.fill(-1)
        self.slot_block = ti.field(ti.i32, (self.num_envs, self.block_capacity))  # block of each slot in use

    def _bake_constants(self) -> None:
        """Python scalars read inside kernels are compile-time constants: derive them once here."""
        f, w, ig = self.fire_cfg, self.wind_cfg, self.ignition_cfg
        cv = f.convection
        self.dt = f.dt
        self.uniform = bool(self.land_map.is_uniform)
        self.flood_duration = f.flood_duration
        self.conv_on = bool(cv.enabled)
        self.rad_on = bool(f.radiation.enabled)
        u_prime = w.turbulence * w.speed
        self.conv_decay = 1.0 - f.dt / cv.tau_mem
        self.conv_f1dt = (2.0 + 3.0 * cv.c0) / 4.0 * (u_prime / cv.lt) * f.dt
        self.conv_f2 = math.sqrt(cv.c0 * u_prime**3 / cv.lt * f.dt)
        self.conv_fldt = cv.fl * f.dt
        self.conv_y_st, self.conv_y_lim = cv.y_st, cv.y_lim
        self.rad_y_st, self.rad_y_lim = f.radiation.y_st, f.radiation.y_lim
        self.sqrt_dt = math.sqrt(f.dt)
        self.extent = (self.rows * self.cell_size, self.cols * self.cell_size)
        self.wind_speed = w.speed
        self.wind_dir = w.direction  # degrees, -1 = random per episode
        self.spread_prob, self.spread_noise = ig.spread_prob, ig.noise
        self.num_fires = self.sizes.num_fires
        self.num_clusters = ig.clusters
        self.pattern = PATTERNS.index(ig.pattern)
        self.reseed = ig.reseed

    def _alloc_class_table(self, land: LandCoverMap) -> tuple[np.ndarray, np.ndarray]:
        """The per-class fields, and their values as (ints, floats) arrays for :meth:`_load_tables`."""
        n = len(CLASSES)
        self.cls_ignitable = ti.field(ti.i32, n)
        self.cls_tau_ign = ti.field(ti.f32, n)
        self.cls_tau_burn = ti.field(ti.f32, n)
        self.cls_n_conv = ti.field(ti.i32, n)
        self.cls_n_rad = ti.field(ti.i32, n)
        self.cls_lr = ti.Vector.field(2, ti.f32, n)
        self.cls_sf = ti.Vector.field(2, ti.f32, n)  # mean, std of the no-wind radiation spread rate
        tau_ign = np.array([c.tau_ign for c in CLASSES], np.float32)
        tau_burn = np.array([c.tau_burn for c in CLASSES], np.float32)
        if land.is_uniform:  # the uniform map takes its times from the config (docs/model/fire.md §2.2)
            tau_ign[GENERIC_UNBURNED] = self.fire_cfg.uniform_ignition_time
            tau_burn[GENERIC_UNBURNED] = self.fire_cfg.uniform_burning_time
        ints = np.array([(c.is_ignitable, c.n_conv, c.n_rad) for c in CLASSES], np.int32)
        floats = np.array([(c.lr_min, c.lr_max, c.sf0_mean, c.sf0_std) for c in CLASSES], np.float32)
        return ints, np.column_stack([tau_ign, tau_burn, floats]).astype(np.float32)

    @ti.kernel
    def _load_tables(self, land: ti.types.ndarray(dtype=ti.i32, ndim=1),
                     ints: ti.types.ndarray(dtype=ti.i32, ndim=2), floats: ti.types.ndarray(dtype=ti.f32, ndim=2),
                     normals: ti.types.ndarray(dtype=ti.f32, ndim=1), unit: ti.types.ndarray(dtype=ti.f32, ndim=2)):
        """Every constant table in one launch: a field's ``from_numpy`` builds a kernel of its own per field, ~10 ms
        each at every start. ``ints``: ignitable, n_conv, n_rad per class; ``floats``: tau_ign, tau_burn, lr_min,
        lr_max, sf0_mean, sf0_std."""
        for c in range(self.num_cells):
            self.land[c] = land[c]
        for k in range(ints.shape[0]):
            self.cls_ignitable[k], self.cls_n_conv[k], self.cls_n_rad[k] = ints[k, 0], ints[k, 1], ints[k, 2]
            self.cls_tau_ign[k], self.cls_tau_burn[k] = floats[k, 0], floats[k, 1]
            self.cls_lr[k] = ti.Vector([floats[k, 2], floats[k, 3]])
            self.cls_sf[k] = ti.Vector([floats[k, 4], floats[k, 5]])
        for t in range(normals.shape[0]):
            self.normals[t] = normals[t]
            self.unit[t] = ti.Vector([unit[t, 0], unit[t, 1]])
        for e in range(self.num_envs):
            self.episode[e] = -1

    # ------------------------------------------------------------------------------------------ public API

    def reset(self, mask=None) -> None:
        """Start a new episode in the envs where ``mask`` (shape (E,), int32, numpy or torch) is non-zero.

        Clears every cell (its durations are redrawn when first needed), particles and lists, draws the wind
        and lights the initial fires.
        """
        check_built_in_this_runtime(self._taichi_generation, "FireSim.reset(): this simulator")
        mask = self._all if mask is None else self.int32_array(mask, (self.num_envs,), "reset mask")
        self._clear_envs(mask)
        self._start_envs(mask, self.seed_key)

    def restart_streams(self, seed: int) -> None:
        """Restart every random stream from ``seed``: the next reset starts episode 0 of each env again."""
        self.seed = int(seed)
        self.episode.fill(-1)

    def relabel(self, land: LandCoverMap) -> None:
        """Report ``land`` as this simulator's map: a map of the same contents under another name or
        georeferencing (a pooled simulator's new owner), which changes no field."""
        if land.classes.shape != self.land_map.classes.shape:
            raise ValueError(f"{land.name}: {land.classes.shape} cells, but this simulator was built for "
                             f"{self.land_map.name}'s {self.land_map.classes.shape}")
        self.land_map = land

    @property
    def seed_key(self) -> int:
        """The root key of every random stream (a hash of the seed)."""
        return rng.base_key(self.seed)

    def step(self, n: int = 1) -> np.ndarray:
        """Advance every env by ``n`` fire updates (n * dt seconds) in one kernel launch, which also reads the
        counters at its end: returns them as (E, N_COUNTS) (columns: :data:`STAT_NAMES`; the host array that the
        next ``step`` or :meth:`counters` overwrites), so that stepping and reading take one launch."""
        check_built_in_this_runtime(self._taichi_generation, "FireSim.step(): this simulator")
        if self.chunked is None:  # n = 0 only reads the counters (and builds the kernel: a warm-up)
            self._advance(max(n, 0), self._counts_host)
            return self._counts_host
        if n > 0:
            self.chunked.advance(n)
        return self.counters()

    def flood(self, requests, extinguished) -> None:
        """Drop water on cells (docs/model/fire.md §8), in order within each env.

        Args:
            requests: (E, M) int32 flat cell indices ``i * cols + j``; negative entries are ignored.
            extinguished: (E, M) int32 output, 1 where the cell was burning (and is now flooded), else 0.
        """
        requests = self.int32_array(requests, (self.num_envs, None), "flood requests")
        self._flood(requests, self.int32_array(extinguished, requests.shape, "flood output", copy_ok=False))

    def counters(self) -> np.ndarray:
        """Every env's counters now, (E, N_COUNTS) (columns: :data:`STAT_NAMES`), in one launch (a field's
        ``to_numpy`` costs 4x as much); the host array that the next call or ``step`` overwrites."""
        self._export_counts(self._counts_host)
        return self._counts_host

    def stats(self, counters: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per-env counters, each an (E,) int array (a host copy: not for the step loop); ``counters`` as returned by
        :meth:`step` saves the read."""
        c = self.counters() if counters is None else counters
        return {name: c[:, col].copy() for name, col in STAT_NAMES.items()}

    def lit_counts(self) -> np.ndarray:
        """(E,) distinct cells lit since each env's reset (burning, burned out or extinguished since)."""
        return self.counters()[:, N_LIT].copy()

    def state(self, env: int = 0) -> np.ndarray:
        """Cell states of one env as a (rows, cols) int32 array (class id, or 12/13/14 burning/burned/flooded)."""
        return self.states()[env].reshape(self.rows, self.cols)

    def states(self) -> np.ndarray:
        """Cell states of every env, (E, rows*cols) int32 (a host copy: not for the step loop)."""
        out = np.zeros((self.num_envs, self.num_cells), np.int32)
        self._export_states(out)
        return out

    def cell_records(self) -> tuple[np.ndarray, np.ndarray]:
        """Every cell record: ints (E, rows, cols, CELL_FIELDS) and f64 timers (E, rows, cols, TIMER_FIELDS).

        A cell whose durations the episode has not needed yet shows them drawn (the same values as drawing
        them later), in either layout and without storing them. The flood timer is meaningful only while a cell
        is flooded.
        """
        shape = (self.num_envs, self.rows, self.cols)
        cells = np.zeros((self.num_envs, self.num_cells, CELL_FIELDS), np.int32)
        timers = np.zeros((self.num_envs, self.num_cells, TIMER_FIELDS), np.float64)
        self._export_records(cells, timers)
        return cells.reshape(*shape, CELL_FIELDS), timers.reshape(*shape, TIMER_FIELDS)

    def particles(self, env: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Live particles of one env: convection (n, 3) and radiation (m, 3) rows of (x1 m, x2 m, intensity)."""
        c = self.counts.to_numpy()[env]
        conv = self.conv.to_numpy()[env, : c[N_CONV]]
        rad = self.rad.to_numpy()[env, : c[N_RAD]]
        rad_pos = rad[:, pt.R_O1 : pt.R_O2 + 1] + rad[:, pt.R_R, None] * rad[:, pt.R_C : pt.R_S + 1]
        return (np.column_stack([conv[:, pt.P_X1], conv[:, pt.P_X2], conv[:, pt.P_Y]]),
                np.column_stack([rad_pos, rad[:, pt.R_Y]]))

    def steps_since_reset(self) -> np.ndarray:
        """(E,) fire updates each env has made since its last reset."""
        return self.counters()[:, N_STEP].copy()

    def wind_vectors(self) -> np.ndarray:
        """(E, 2) wind velocity (m/s) along (rows, cols)."""
        return self.wind.to_numpy()

    def memory_bytes_per_env(self) -> int:
        """Bytes of Taichi field memory one env holds (cell records, lists, block tables, particle pools); the
        chunked update adds one env's worth of scratch per simulator (``chunked.memory_bytes()``)."""
        return self.sizes.bytes_per_env()

    # Test hooks: drive the cell state machine directly, without particles or the generator.
    def ignite_cells(self, mask) -> None:
        """Ignite the cells where ``mask`` (E, rows*cols int32) is non-zero and that can ignite."""
        self._ignite_cells(self.int32_array(mask, (self.num_envs, self.num_cells), "ignition mask"))

    def prescribe_exposure(self, mask) -> None:
        """Mark cells (E, rows*cols int32 mask) as visited by a particle in the next update."""
        self._prescribe_exposure(self.int32_array(mask, (self.num_envs, self.num_cells), "exposure mask"))

    @staticmethod
    def int32_array(x, shape, what, copy_ok=True):
        """Check an int array's shape; numpy inputs become contiguous int32 (torch tensors must already be).

        Public: the drone and map classes check their reset masks with it too."""
        got = tuple(x.shape)
        if len(got) != len(shape) or any(want is not None and g != want for g, want in zip(got, shape, strict=True)):
            want = tuple("M" if w is None else w for w in shape)
            raise ValueError(f"{what}: expected shape {want}, got {got}")
        if isinstance(x, np.ndarray):
            if not copy_ok and (x.dtype != np.int32 or not x.flags.c_contiguous):
                raise ValueError(f"{what}: expected a C-contiguous int32 array (written in place)")
            return np.ascontiguousarray(x, dtype=np.int32)
        return x

    # ------------------------------------------------------------------------------------------ kernels

    @ti.kernel
    def _clear_envs(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        """The first half of a reset: forget the last episode's cells (the cost that follows the footprint)."""
        if ti.static(self.sparse):
            for e, k in ti.ndrange(self.num_envs, self.block_capacity):  # hand back the blocks the episode used
                if mask[e] != 0 and k < self.counts[e, N_BLOCKS]:
                    self.block_slot[e, self.slot_block[e, k]] = -1
            for e in range(self.num_envs):
                if mask[e] != 0:
                    self.counts[e, N_BLOCKS] = 0
        else:
            for e, c in ti.ndrange(self.num_envs, self.num_cells):  # every cell of the reset envs, in parallel
                if mask[e] != 0:
                    self._reset_record(e, c, self.land[c])

    @ti.kernel
    def _start_envs(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=1), seed_key: ti.u32):
        """The second half: a new key, counters and wind, and the initial fires."""
        ti.loop_config(serialize=self.serial_envs)
        for e in range(self.num_envs):
            if mask[e] != 0:
                self.begin_episode(e, seed_key)
        ti.loop_config(serialize=self.serial_envs)
        for v in range(self.num_envs * self.env_pad):  # the generator is serial per env
            e = v // self.env_pad
            if v % self.env_pad == 0 and mask[e] != 0:
                self.light_fires(e)

    @ti.func
    def reset_env(self, e, seed_key: ti.u32):
        """A whole reset of one env, serially: for same-step autoreset inside a batched step kernel."""
        if ti.static(self.sparse):
            for k in range(self.counts[e, N_BLOCKS]):
                self.block_slot[e, self.slot_block[e, k]] = -1
        self.begin_episode(e, seed_key)
        if ti.static(not self.sparse):
            for c in range(self.num_cells):
                self._reset_record(e, c, self.land[c])
        self.light_fires(e)

    @ti.func
    def begin_episode(self, e, seed_key: ti.u32):
        self.episode[e] += 1
        self.env_key[e] = rng.key(seed_key, e, self.episode[e])
        for k in ti.static(range(N_COUNTS)):
            self.counts[e, k] = 0
        self.gen_ctr[e] = 0
        self.wind[e] = self._draw_wind(e)

    @ti.func
    def light_fires(self, e):
        light_initial_fires(self, e)
        self.counts[e, N_IGNITED_INIT] = self.counts[e, N_BURNING]

    @ti.func
    def step_env(self, e):
        """One fire update of env e (for kernels that fuse the fire with other work)."""
        self._step_env(e)

    @ti.func
    def drop_water(self, e, c) -> ti.i32:
        """Flood cell c of env e (docs/model/fire.md §8); 1 if it was burning."""
        return self._drop_water(e, c)

    # Read access for the kernels of other modules (drones, tasks, episodes, rendering, the initial-fire
    # generator): they ask by name, so the record layouts (C_*, N_*, dense or sparse) stay this module's business.

    @ti.func
    def is_burning(self, e, c) -> ti.i32:
        return ti.cast(self.cell_state(e, c) == BURNING, ti.i32)

    @ti.func
    def cell_state(self, e, c) -> ti.i32:
        """Cell c's class id, or BURNING / BURNED / FLOODED."""
        state = 0
        if ti.static(self.sparse):
            r = self._rec(e, c)
            state = self.land[c]
            if r >= 0:
                state = self.cells[e, r][C_STATE]
        else:
            state = self.cells[e, c][C_STATE]
        return state

    @ti.func
    def was_extinguished(self, e, c) -> ti.i32:
        """1 if water put cell c out while it was burning, earlier in this episode."""
        r = self._rec(e, c)
        out = 0
        if r >= 0:
            out = ti.cast((self.cells[e, r][C_FLAGS] & FLAG_EXTINGUISHED) != 0, ti.i32)
        return out

    @ti.func
    def can_ignite(self, e, c) -> ti.i32:
        """1 if cell c's current state can catch fire."""
        return self.cls_ignitable[self.cell_state(e, c)]

    @ti.func
    def mark_of(self, e, c) -> ti.i32:
        """The generator's scratch mark of cell c (0 since the reset)."""
        r = self._rec(e, c)
        m = 0
        if r >= 0:
            m = self.mark[e, r]
        return m

    @ti.func
    def set_mark(self, e, c, m) -> ti.i32:
        """Set the generator's mark of cell c; 0 if the sparse pool had no room for it (counted)."""
        r = self._touch(e, c)
        ok = 0
        if r >= 0:
            self.mark[e, r] = m
            ok = 1
        return ok

    @ti.func
    def burning_count(self, e) -> ti.i32:
        return self.counts[e, N_BURNING]

    @ti.func
    def burning_cell(self, e, k) -> ti.i32:
        """The k-th entry (k < burning_count) of env e's unordered list of burning cells."""
        return self.burning[e, k]

    @ti.func
    def burned_count(self, e) -> ti.i32:
        """Cells burned out since the reset."""
        return self.counts[e, N_BURNED]

    @ti.func
    def lit_count(self, e) -> ti.i32:
        """Distinct cells lit since the reset (burning, burned out or extinguished now, or extinguished and
        returned to their class by a drained flood)."""
        return self.counts[e, N_LIT]

    @ti.func
    def extinguished_count(self, e) -> ti.i32:
        """Burning cells put out by water since the reset."""
        return self.counts[e, N_EXTINGUISHED]

    @ti.func
    def convection_count(self, e) -> ti.i32:
        return self.counts[e, N_CONV]

    @ti.func
    def radiation_count(self, e) -> ti.i32:
        return self.counts[e, N_RAD]

    @ti.func
    def particle_count(self, e) -> ti.i32:
        """Live convection plus radiation particles."""
        return self.counts[e, N_CONV] + self.counts[e, N_RAD]

    @ti.func
    def ignite(self, e, c):
        """Light cell c (the initial-fire generator; callers check can_ignite first)."""
        r = self._touch(e, c)
        if r >= 0:
            self._ignite(e, r, c)

    @ti.func
    def report_ignition_short(self, e, missing):
        """The generator found ``missing`` fewer ignitable cells than it was asked to light."""
        self.counts[e, N_IGNITION_SHORT] = missing

    @ti.func
    def _draw_wind(self, e):
        alpha = ti.cast(self.wind_dir, ti.f32) * (math.pi / 180.0)
        if ti.static(self.wind_dir < 0):
            alpha = rng.TWO_PI * rng.uniform(rng.key(self.env_key[e], rng.DOMAIN_EPISODE, 0))
        return ti.Vector([ti.cos(alpha), ti.sin(alpha)]) * self.wind_speed

    # ------------------------------------------------------------------------------------------ cell records

    @ti.func
    def _rec(self, e, c) -> ti.i32:
        """Record index of cell c in env e; -1 where the sparse layout holds none (the cell is as reset)."""
        r = c
        if ti.static(self.sparse):
            place = self.cell_block[c]
            slot = self.block_slot[e, place >> BLOCK_SHIFT]
            r = -1
            if slot >= 0:
                r = (slot << BLOCK_SHIFT) | (place & (BLOCK_CELLS - 1))
        return r

    @ti.func
    def _touch(self, e, c) -> ti.i32:
        """Record index of cell c for writing. The sparse layout first gives the cell's block the env's next free
        slot (reset records for its cells); -1 if the env's pool is full, counted in N_DROP_BLOCK."""
        r = c
        if ti.static(self.sparse):
            place = self.cell_block[c]
            b = place >> BLOCK_SHIFT
            slot = self.block_slot[e, b]
            if slot < 0:
                n = self.counts[e, N_BLOCKS]
                if n < self.block_capacity:
                    slot = n
                    self.counts[e, N_BLOCKS] = n + 1
                    self.block_slot[e, b] = slot
                    self.slot_block[e, slot] = b
                    self._reset_block(e, b, slot)
                else:
                    self.counts[e, N_DROP_BLOCK] += 1
            r = -1
            if slot >= 0:
                r = (slot << BLOCK_SHIFT) | (place & (BLOCK_CELLS - 1))
        return r

    @ti.func
    def _reset_block(self, e, b, slot):
        i0 = (b // self.block_cols) * BLOCK_SIDE
        j0 = (b % self.block_cols) * BLOCK_SIDE
        for k in range(BLOCK_CELLS):
            i = i0 + k // BLOCK_SIDE
            j = j0 + k % BLOCK_SIDE
            cls = 0  # the part of an edge block outside the map is never read
            if i < self.rows and j < self.cols:
                cls = self.land[i * self.cols + j]
            self._reset_record(e, (slot << BLOCK_SHIFT) | k, cls)

    @ti.func
    def _reset_record(self, e, r, cls):
        """A new episode's cell: its class, no flags. Its durations are drawn when first needed.

        Most cells of an episode are never exposed nor lit, and a reset that drew all of them spent most of a
        random-action env step (ten hashes and two f64 divisions per cell). The draws are counter-based
        (keyed by episode and cell), so drawing later gives exactly the same values.
        """
        self.cells[e, r] = ti.Vector([cls, 0, -1, 0], ti.i32)
        self.mark[e, r] = 0
        self.lit[e, r] = ti.u8(0)

    @ti.func
    def _durations(self, e, c):
        """(tau_ign, tau_burn) of cell c this episode, docs/model/fire.md §2.3: durations x (1 + s*u), s in {-1, 0, 1},
        u ~ U(0.1, 0.2); tau_ign is NEVER for a class that cannot ignite."""
        cls = self.land[c]
        k = rng.key(self.env_key[e], rng.DOMAIN_CELLS, c)
        s1 = ti.cast(rng.uniform_int(rng.key(k, 0, 0), 3) - 1, ti.f64)
        u1 = 0.1 + 0.1 * ti.cast(rng.uniform(rng.key(k, 1, 0)), ti.f64)
        s2 = ti.cast(rng.uniform_int(rng.key(k, 2, 0), 3) - 1, ti.f64)
        u2 = 0.1 + 0.1 * ti.cast(rng.uniform(rng.key(k, 3, 0)), ti.f64)
        tau_burn = ti.cast(self.cls_tau_burn[cls], ti.f64) * (1.0 + s1 * u1)
        tau_ign = ti.f64(NEVER)
        if self.cls_ignitable[cls] != 0:
            tau_ign = ti.cast(self.cls_tau_ign[cls], ti.f64) * (1.0 + s2 * u2)
        return ti.Vector([tau_ign, tau_burn], ti.f64)

    @ti.func
    def _periods(self, c, tau_burn: ti.f64) -> ti.i32:
        """Convection (low 16 bits) and radiation emission periods of cell c."""
        cls = self.land[c]
        return _period(tau_burn, self.cls_n_conv[cls]) | (_period(tau_burn, self.cls_n_rad[cls]) << 16)

    @ti.func
    def _draw_durations(self, e, r, c):
        """Once per episode, before cell c (record r) is first exposed or lit: its durations and periods; also
        clears its exposure and burn timers. The flood timer is set by every flood and read only while the
        cell is flooded."""
        flags = self.cells[e, r][C_FLAGS]
        if (flags & FLAG_DRAWN) == 0:
            d = self._durations(e, c)
            self.cells[e, r][C_PERIODS] = self._periods(c, d[1])
            self.cells[e, r][C_FLAGS] = flags | FLAG_DRAWN
            self.timers[e, r][T_IGN] = d[0]
            self.timers[e, r][T_BURN_LEFT] = d[1]
            self.timers[e, r][T_BURN_TIME] = 0.0
            self.timers[e, r][T_EXPOSURE] = 0.0

    @ti.kernel
    def _export_states(self, out: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for e, c in ti.ndrange(self.num_envs, self.num_cells):
            out[e, c] = self.cell_state(e, c)

    @ti.kernel
    def _export_records(self, cells: ti.types.ndarray(dtype=ti.i32, ndim=3),
                        timers: ti.types.ndarray(dtype=ti.f64, ndim=3)):
        for e, c in ti.ndrange(self.num_envs, self.num_cells):
            rec = ti.Vector([self.land[c], 0, -1, 0], ti.i32)
            tim = ti.Vector([0.0, 0.0, 0.0, 0.0, 0.0], ti.f64)
            r = self._rec(e, c)
            if r >= 0:
                rec = self.cells[e, r]
                tim = self.timers[e, r]
            if (rec[C_FLAGS] & FLAG_DRAWN) == 0:  # what _draw_durations will store, without storing it
                d = self._durations(e, c)
                rec[C_PERIODS] = self._periods(c, d[1])
                rec[C_FLAGS] |= FLAG_DRAWN
                tim[T_IGN] = d[0]
                tim[T_BURN_LEFT] = d[1]
                tim[T_BURN_TIME] = 0.0
                tim[T_EXPOSURE] = 0.0
            for k in ti.static(range(CELL_FIELDS)):
                cells[e, c, k] = rec[k]
            for k in ti.static(range(TIMER_FIELDS)):
                timers[e, c, k] = tim[k]

    # ------------------------------------------------------------------------------------------ one update

    @ti.kernel
    def _advance(self, n_steps: ti.i32, counters: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        ti.loop_config(serialize=self.serial_envs)
        for v in range(self.num_envs * self.env_pad):
            if v % self.env_pad == 0:
                e = v // self.env_pad
                for _ in range(n_steps):
                    self._step_env(e)
                for k in ti.static(range(N_COUNTS)):  # the read a caller makes next, in the same launch
                    counters[e, k] = self.counts[e, k]

    @ti.kernel
    def _export_counts(self, counters: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        ti.loop_config(serialize=True)  # a few ints per env: no thread-pool dispatch
        for e in range(self.num_envs):
            for k in ti.static(range(N_COUNTS)):
                counters[e, k] = self.counts[e, k]

    @ti.func
    def _step_env(self, e):
        """One fire update in the reference's order (docs/model/fire.md §4); steps 2 and 4 share one pass."""
        t = self.counts[e, N_STEP] + 1
        self.counts[e, N_STEP] = t
        step_key = rng.mix32(self.env_key[e] ^ (ti.cast(t, ti.u32) * ti.u32(0x9E3779B9)))
        self._move_convection(e, t, step_key)
        self._move_radiation(e, t, step_key)
        self._drain_floods(e)
        self._expose_and_ignite(e, t)
        self._burn(e, step_key)

    @ti.func
    def _cell_of(self, x1, x2):
        """Flat index of the cell holding a point in metres, or -1 outside the grid."""
        c = -1
        if 0.0 <= x1 < self.extent[0] and 0.0 <= x2 < self.extent[1]:
            i = ti.min(ti.cast(x1 / self.cell_size, ti.i32), self.rows - 1)
            j = ti.min(ti.cast(x2 / self.cell_size, ti.i32), self.cols - 1)
            c = i * self.cols + j
        return c

    @ti.func
    def _visit(self, e, c, t):
        """A live particle sits in cell c during update t: stamp it and add it to the exposed list once."""
        r = self._touch(e, c)
        if r >= 0:
            self.cells[e, r][C_VISIT] = t
            flags = self.cells[e, r][C_FLAGS]
            if self.cls_ignitable[self.cells[e, r][C_STATE]] != 0 and (flags & FLAG_EXPOSED) == 0:
                self._draw_durations(e, r, c)
                self.cells[e, r][C_FLAGS] |= FLAG_EXPOSED
                n = self.counts[e, N_EXPOSED]
                self.exposed[e, n] = c
                self.counts[e, N_EXPOSED] = n + 1

    @ti.func
    def _move_convection(self, e, t, step_key):
        w = 0
        wind = self.wind[e]
        for i in range(self.counts[e, N_CONV]):
            h = rng.key(step_key, i, rng.DOMAIN_CONVECTION)
            p = pt.advect_convection(self.conv[e, i], wind, self.normals[rng.low16(h)],
                                     self.normals[rng.high16(h)], self.conv_decay, self.conv_f1dt,
                                     self.conv_f2, self.conv_fldt)
            c = self._cell_of(p[pt.P_X1], p[pt.P_X2])
            if c >= 0 and p[pt.P_Y] >= self.conv_y_lim:
                self.conv[e, w] = p
                w += 1
                self._visit(e, c, t)
        self.counts[e, N_CONV] = w

    @ti.func
    def _move_radiation(self, e, t, step_key):
        w = 0
        for i in range(self.counts[e, N_RAD]):
            h = rng.key(step_key, i, rng.DOMAIN_RADIATION)
            p = self.rad[e, i]
            sf = self.cls_sf[ti.cast(p[pt.R_CLS], ti.i32)]
            p = pt.advect_radiation(p, self.unit[rng.low16(h)], self.normals[rng.high16(h)],
                                    sf[0] * self.dt, sf[1] * self.sqrt_dt)
            x = pt.radiation_position(p)
            c = self._cell_of(x[0], x[1])
            if c >= 0 and p[pt.R_Y] >= self.rad_y_lim:
                self.rad[e, w] = p
                w += 1
                self._visit(e, c, t)
        self.counts[e, N_RAD] = w

    @ti.func
    def _drain_floods(self, e):
        w = 0
        for k in range(self.counts[e, N_FLOODED]):
            c = self.flooded[e, k]
            r = self._rec(e, c)  # a listed cell has a record
            f = self.timers[e, r][T_FLOOD] + ti.f64(self.dt)
            if f >= self.flood_duration:  # the flood ends: back to the original class, or burned
                self.timers[e, r][T_FLOOD] = self.flood_duration
                state = self.land[c]
                if (self.cells[e, r][C_FLAGS] & FLAG_BURNED_DOWN) != 0:
                    state = BURNED
                self.cells[e, r][C_STATE] = state
            else:
                self.timers[e, r][T_FLOOD] = f
                self.flooded[e, w] = c
                w += 1
        self.counts[e, N_FLOODED] = w

    @ti.func
    def _expose_and_ignite(self, e, t):
        """Prune unvisited cells from the exposed list, count exposure for the rest and ignite at threshold."""
        w = 0
        for k in range(self.counts[e, N_EXPOSED]):
            c = self.exposed[e, k]
            r = self._rec(e, c)
            flags = self.cells[e, r][C_FLAGS]
            if self.cells[e, r][C_VISIT] != t:
                self.cells[e, r][C_FLAGS] = flags & ~FLAG_EXPOSED
            else:
                exposure = self.timers[e, r][T_EXPOSURE] + ti.f64(self.dt)
                self.timers[e, r][T_EXPOSURE] = exposure
                if exposure >= self.timers[e, r][T_IGN]:
                    self.cells[e, r][C_FLAGS] = flags & ~FLAG_EXPOSED
                    self._ignite(e, r, c)
                else:
                    self.exposed[e, w] = c
                    w += 1
        self.counts[e, N_EXPOSED] = w

    @ti.func
    def _ignite(self, e, r, c):
        self.counts[e, N_LIT] += self._light(e, r, c)
        n = self.counts[e, N_BURNING]
        self.burning[e, n] = c
        self.counts[e, N_BURNING] = n + 1

    @ti.func
    def _light(self, e, r, c) -> ti.i32:
        """The record half of an ignition (the list half is the caller's); 1 if the cell is lit for the first
        time this episode."""
        self._draw_durations(e, r, c)
        self.cells[e, r][C_STATE] = BURNING
        first = 0
        if self.lit[e, r] == 0:
            self.lit[e, r] = ti.u8(1)
            first = 1
        return first

    @ti.func
    def _burn(self, e, step_key):
        w = 0
        for k in range(self.counts[e, N_BURNING]):
            c = self.burning[e, k]
            emits = self._burn_tick(e, self._rec(e, c))
            if (emits & EMIT_CONV) != 0:
                self._emit_convection(e, c, step_key)
            if (emits & EMIT_RAD) != 0:
                self._emit_radiation(e, c, step_key)
            if (emits & BURNED_OUT) != 0:
                self.counts[e, N_BURNED] += 1
            else:
                self.burning[e, w] = c
                w += 1
        self.counts[e, N_BURNING] = w

    @ti.func
    def _burn_tick(self, e, r) -> ti.i32:
        """One update of a burning cell's record: its timers, and BURNED once its time is up. Returns what the
        caller does with the cell, as bits: EMIT_CONV / EMIT_RAD (emit that particle) and BURNED_OUT."""
        before = self.timers[e, r][T_BURN_TIME]
        after = before + ti.f64(self.dt)
        left = self.timers[e, r][T_BURN_LEFT] - ti.f64(self.dt)
        self.timers[e, r][T_BURN_TIME] = after
        self.timers[e, r][T_BURN_LEFT] = left
        # Emit when the burning time crosses a whole second k >= 1 that is a multiple of the period.
        emits = 0
        sec_old = ti.cast(before, ti.i32)
        sec_new = ti.cast(ti.floor(after), ti.i32)
        if sec_new != sec_old:
            periods = self.cells[e, r][C_PERIODS]
            if ti.static(self.conv_on):
                if sec_new % (periods & 0xFFFF) == 0:
                    emits |= EMIT_CONV
            if ti.static(self.rad_on):
                if sec_new % (periods >> 16) == 0:
                    emits |= EMIT_RAD
        if left <= 0.0:
            self.cells[e, r][C_STATE] = BURNED
            self.cells[e, r][C_FLAGS] |= FLAG_BURNED_DOWN
            emits |= BURNED_OUT
        return emits

    @ti.func
    def _emit_convection(self, e, c, step_key):
        n = self.counts[e, N_CONV]
        if n < self.conv_capacity:
            self.conv[e, n] = self.convection_from(c, step_key)
            self.counts[e, N_CONV] = n + 1
        else:
            self.counts[e, N_DROP_CONV] += 1

    @ti.func
    def _emit_radiation(self, e, c, step_key):
        n = self.counts[e, N_RAD]
        if n < self.rad_capacity:
            self.rad[e, n] = self.radiation_from(c, step_key)
            self.counts[e, N_RAD] = n + 1
        else:
            self.counts[e, N_DROP_RAD] += 1

    @ti.func
    def convection_from(self, c, step_key):
        """A new convection particle of burning cell c (its draws are keyed by the cell, not its pool slot)."""
        h = rng.key(step_key, c, rng.DOMAIN_EMISSION)
        i = c // self.cols
        j = c % self.cols
        # The reference's particle constructor takes whole metres: the emission point is truncated.
        x1 = ti.floor((i + rng.uniform(h)) * self.cell_size)
        x2 = ti.floor((j + rng.uniform(rng.mix32(h))) * self.cell_size)
        return ti.Vector([x1, x2, 0.0, 0.0, self.conv_y_st], ti.f32)

    @ti.func
    def radiation_from(self, c, step_key):
        """A new radiation particle of burning cell c (keyed by the cell, as convection_from)."""
        cls = self.land[c]  # the mother class, never the burning state
        h = rng.key(step_key, c, rng.DOMAIN_EMISSION + 16)
        h2 = rng.mix32(h)
        sf = self.cls_sf[cls]
        lr = self.cls_lr[cls]
        sf_sample = ti.abs(sf[0] + sf[1] * self.normals[rng.low16(h)])
        length = lr[0] + (lr[1] - lr[0]) * rng.uniform(h2)
        tau = 2703.0
        if sf_sample > 0.00925:
            tau = length / sf_sample
        i = c // self.cols
        j = c % self.cols
        o1 = (i + rng.uniform(rng.mix32(h2))) * self.cell_size
        o2 = (j + rng.uniform(rng.mix32(h2 + ti.u32(1)))) * self.cell_size
        return pt.new_radiation(o1, o2, self.rad_y_st, 1.0 - self.dt / tau, cls)

    # ------------------------------------------------------------------------------------------ water

    @ti.kernel
    def _flood(self, requests: ti.types.ndarray(dtype=ti.i32, ndim=2),
               extinguished: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for e in range(self.num_envs):  # requests of one env are applied in order
            for m in range(requests.shape[1]):  # (cheap per env: no padding, see env_pad)
                c = requests[e, m]
                extinguished[e, m] = 0
                if 0 <= c < self.num_cells:
                    extinguished[e, m] = self._drop_water(e, c)

    @ti.func
    def _drop_water(self, e, c) -> ti.i32:
        """docs/model/fire.md §8: flood a cell; returns 1 if it was burning (extinguished). A drop the sparse pool has
        no room for is counted in N_DROP_BLOCK and changes nothing."""
        r = self._touch(e, c)
        was_burning = 0
        if r >= 0:
            state = self.cells[e, r][C_STATE]
            if state == BURNING:
                was_burning = 1
                _remove_from_list(self.burning, self.counts, e, N_BURNING, c)
                self.timers[e, r][T_EXPOSURE] = 0.0
                self.counts[e, N_EXTINGUISHED] += 1
                self.cells[e, r][C_FLAGS] |= FLAG_EXTINGUISHED
            elif (self.cells[e, r][C_FLAGS] & FLAG_EXPOSED) != 0:
                _remove_from_list(self.exposed, self.counts, e, N_EXPOSED, c)
                self.cells[e, r][C_FLAGS] = self.cells[e, r][C_FLAGS] & ~FLAG_EXPOSED
            if state != FLOODED:
                n = self.counts[e, N_FLOODED]
                self.flooded[e, n] = c
                self.counts[e, N_FLOODED] = n + 1
            self.cells[e, r][C_STATE] = FLOODED
            self.timers[e, r][T_FLOOD] = 0.0
            self._delete_particles_in(e, c)
        return was_burning

    @ti.func
    def _delete_particles_in(self, e, c):
        w = 0
        for i in range(self.counts[e, N_CONV]):
            p = self.conv[e, i]
            if self._cell_of(p[pt.P_X1], p[pt.P_X2]) != c:
                self.conv[e, w] = p
                w += 1
        self.counts[e, N_CONV] = w
        w = 0
        for i in range(self.counts[e, N_RAD]):
            p = self.rad[e, i]
            x = pt.radiation_position(p)
            if self._cell_of(x[0], x[1]) != c:
                self.rad[e, w] = p
                w += 1
        self.counts[e, N_RAD] = w

    # ------------------------------------------------------------------------------------------ test hooks

    @ti.kernel
    def _ignite_cells(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for e in range(self.num_envs):
            for c in range(self.num_cells):
                if mask[e, c] != 0 and self.can_ignite(e, c) != 0:
                    r = self._touch(e, c)
                    if r >= 0:
                        if (self.cells[e, r][C_FLAGS] & FLAG_EXPOSED) != 0:
                            _remove_from_list(self.exposed, self.counts, e, N_EXPOSED, c)
                            self.cells[e, r][C_FLAGS] = self.cells[e, r][C_FLAGS] & ~FLAG_EXPOSED
                        self._ignite(e, r, c)

    @ti.kernel
    def _prescribe_exposure(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for e in range(self.num_envs):
            for c in range(self.num_cells):
                if mask[e, c] != 0:
                    self._visit(e, c, self.counts[e, N_STEP] + 1)


@ti.func
def _period(tau_burn: ti.f64, n: ti.i32) -> ti.i32:
    """Emission period in whole seconds: max(1, floor((tau_burn - 1) / n)) (docs/model/fire.md §2.3)."""
    p = 1
    if n > 0:
        p = ti.max(1, ti.cast(ti.floor((tau_burn - 1.0) / n), ti.i32))
    return p


@ti.func
def _remove_from_list(lst: ti.template(), counts: ti.template(), e, col, c):
    """Remove cell c from an env's unordered cell list by moving the last entry into its slot."""
    n = counts[e, col]
    for k in range(n):
        if lst[e, k] == c:
            lst[e, k] = lst[e, n - 1]
            counts[e, col] = n - 1
            break
