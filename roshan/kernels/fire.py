"""FireSPIN on E independent copies of one land-cover map: cells, particles and their exchange (docs/model/fire.md).

One parallel loop runs over environments; each env's sparse work (its burning, exposed and flooded cell lists
and its particle pools) is done serially inside it. That keeps a step's cost proportional to the fire, not the
map, makes the order of every update fixed (so a seed fixes the trajectory whatever the thread count) and costs
one kernel launch per call however many envs or steps it advances.

Cell records live in one of two layouts behind the same accessors (``record_of`` / ``touch``, fire_cells.py):
dense, a record per cell, or sparse, a per-env pool of 8 x 8 blocks that a block joins when fire, particles,
water or the generator first write to one of its cells and leaves at the reset, so memory and reset cost follow
the fire's footprint. The pool is plain fields (not Taichi ``pointer`` SNodes: those keep their memory when a
field tree is destroyed, Taichi issue 5777, and do not exist on Vulkan), handed out in the fixed order of the
env's serial updates, so a trajectory is the same in either layout. A full pool is counted (``dropped_blocks``),
never silent. Which layout, and every capacity, is decided before anything is allocated
(:mod:`roshan.kernels.fire_layout`).

Cell timers are f64 sums of ``dt`` exactly as the reference accumulates them: with dt = 0.1 the sums run
slightly below whole numbers, so most whole-second emissions and the burn-out of unrandomised cells happen one
update after the integer count would say. Those events are synchronised across every cell lit at t = 0, so the
difference shows at the reference's checkpoints (e.g. a third of the forest burns out at update 36,001, not
36,000); integer step counters would not match it.
"""


import math

import numpy as np
import taichi as ti

from roshan.config import FireConfig, IgnitionConfig, WindConfig
from roshan.kernels import particles as pt
from roshan.kernels import rng
from roshan.kernels.arrays import int32_array
from roshan.kernels.fire_cells import draw_durations, durations, emission_periods, record_of, reset_record, touch
from roshan.kernels.fire_layout import (
    TIMER_GROUPS,
    block_grid,
    choose_parallel,
    env_loop_padding,
    env_loop_serial,
    fire_sizes,
    grouped_vector_field,
)
from roshan.kernels.fire_parallel import ChunkedStep
from roshan.kernels.fire_records import (
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
    N_EXPOSED,
    N_EXTINGUISHED,
    N_FLOODED,
    N_IGNITED_INIT,
    N_IGNITION_SHORT,
    N_LIT,
    N_RAD,
    N_STEP,
    STAT_NAMES,
    T_BURN_LEFT,
    T_BURN_TIME,
    T_EXPOSURE,
    T_FLOOD,
    T_IGN,
    TIMER_FIELDS,
)
from roshan.kernels.ignition import PATTERNS, light_initial_fires
from roshan.maps import BURNED, BURNING, CLASSES, FLOODED, GENERIC_UNBURNED, LandCoverMap
from roshan.memory import check_fits
from roshan.runtime import check_built_in_this_runtime, check_field_room, current_arch, ensure_taichi, taichi_generation


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
        self.timers = grouped_vector_field(ti.f64, (E, R), TIMER_GROUPS)
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
        mask = self._all if mask is None else int32_array(mask, (self.num_envs,), "reset mask")
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
        requests = int32_array(requests, (self.num_envs, None), "flood requests")
        self._flood(requests, int32_array(extinguished, requests.shape, "flood output", copy_ok=False))

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
        self._ignite_cells(int32_array(mask, (self.num_envs, self.num_cells), "ignition mask"))

    def prescribe_exposure(self, mask) -> None:
        """Mark cells (E, rows*cols int32 mask) as visited by a particle in the next update."""
        self._prescribe_exposure(int32_array(mask, (self.num_envs, self.num_cells), "exposure mask"))

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
                    reset_record(self, e, c, self.land[c])

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
                reset_record(self, e, c, self.land[c])
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
            r = record_of(self, e, c)
            state = self.land[c]
            if r >= 0:
                state = self.cells[e, r][C_STATE]
        else:
            state = self.cells[e, c][C_STATE]
        return state

    @ti.func
    def was_extinguished(self, e, c) -> ti.i32:
        """1 if water put cell c out while it was burning, earlier in this episode."""
        r = record_of(self, e, c)
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
        r = record_of(self, e, c)
        m = 0
        if r >= 0:
            m = self.mark[e, r]
        return m

    @ti.func
    def set_mark(self, e, c, m) -> ti.i32:
        """Set the generator's mark of cell c; 0 if the sparse pool had no room for it (counted)."""
        r = touch(self, e, c)
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
        r = touch(self, e, c)
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
            r = record_of(self, e, c)
            if r >= 0:
                rec = self.cells[e, r]
                tim = self.timers[e, r]
            if (rec[C_FLAGS] & FLAG_DRAWN) == 0:  # what draw_durations will store, without storing it
                d = durations(self, e, c)
                rec[C_PERIODS] = emission_periods(self, c, d[1])
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
                    self.step_env(e)
                for k in ti.static(range(N_COUNTS)):  # the read a caller makes next, in the same launch
                    counters[e, k] = self.counts[e, k]

    @ti.kernel
    def _export_counts(self, counters: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        ti.loop_config(serialize=True)  # a few ints per env: no thread-pool dispatch
        for e in range(self.num_envs):
            for k in ti.static(range(N_COUNTS)):
                counters[e, k] = self.counts[e, k]

    @ti.func
    def step_env(self, e):
        """One fire update of env e in the reference's order (docs/model/fire.md §4); steps 2 and 4 share one pass.
        Public for kernels that fuse the fire with other work."""
        t = self.counts[e, N_STEP] + 1
        self.counts[e, N_STEP] = t
        step_key = rng.mix32(self.env_key[e] ^ (ti.cast(t, ti.u32) * ti.u32(0x9E3779B9)))
        pt.move_convection(self, e, t, step_key)
        pt.move_radiation(self, e, t, step_key)
        self.drain_floods(e)
        self._expose_and_ignite(e, t)
        self._burn(e, step_key)

    # cell_of, visit, drain_floods, light and burn_tick are public: the chunked update (fire_parallel.py) runs them
    # on its chunks, so that both paths share one copy of the physics.

    @ti.func
    def cell_of(self, x1, x2):
        """Flat index of the cell holding a point in metres, or -1 outside the grid."""
        c = -1
        if 0.0 <= x1 < self.extent[0] and 0.0 <= x2 < self.extent[1]:
            i = ti.min(ti.cast(x1 / self.cell_size, ti.i32), self.rows - 1)
            j = ti.min(ti.cast(x2 / self.cell_size, ti.i32), self.cols - 1)
            c = i * self.cols + j
        return c

    @ti.func
    def visit(self, e, c, t):
        """A live particle sits in cell c during update t: stamp it and add it to the exposed list once."""
        r = touch(self, e, c)
        if r >= 0:
            self.cells[e, r][C_VISIT] = t
            flags = self.cells[e, r][C_FLAGS]
            if self.cls_ignitable[self.cells[e, r][C_STATE]] != 0 and (flags & FLAG_EXPOSED) == 0:
                draw_durations(self, e, r, c)
                self.cells[e, r][C_FLAGS] |= FLAG_EXPOSED
                n = self.counts[e, N_EXPOSED]
                self.exposed[e, n] = c
                self.counts[e, N_EXPOSED] = n + 1

    @ti.func
    def drain_floods(self, e):
        w = 0
        for k in range(self.counts[e, N_FLOODED]):
            c = self.flooded[e, k]
            r = record_of(self, e, c)  # a listed cell has a record
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
            r = record_of(self, e, c)
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
        self.counts[e, N_LIT] += self.light(e, r, c)
        n = self.counts[e, N_BURNING]
        self.burning[e, n] = c
        self.counts[e, N_BURNING] = n + 1

    @ti.func
    def light(self, e, r, c) -> ti.i32:
        """The record half of an ignition (the list half is the caller's); 1 if the cell is lit for the first
        time this episode."""
        draw_durations(self, e, r, c)
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
            emits = self.burn_tick(e, record_of(self, e, c))
            if (emits & EMIT_CONV) != 0:
                pt.emit_convection(self, e, c, step_key)
            if (emits & EMIT_RAD) != 0:
                pt.emit_radiation(self, e, c, step_key)
            if (emits & BURNED_OUT) != 0:
                self.counts[e, N_BURNED] += 1
            else:
                self.burning[e, w] = c
                w += 1
        self.counts[e, N_BURNING] = w

    @ti.func
    def burn_tick(self, e, r) -> ti.i32:
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

    # ------------------------------------------------------------------------------------------ water

    @ti.kernel
    def _flood(self, requests: ti.types.ndarray(dtype=ti.i32, ndim=2),
               extinguished: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for e in range(self.num_envs):  # requests of one env are applied in order
            for m in range(requests.shape[1]):  # (cheap per env: no padding, see env_pad)
                c = requests[e, m]
                extinguished[e, m] = 0
                if 0 <= c < self.num_cells:
                    extinguished[e, m] = self.drop_water(e, c)

    @ti.func
    def drop_water(self, e, c) -> ti.i32:
        """docs/model/fire.md §8: flood cell c of env e; returns 1 if it was burning (extinguished). A drop the sparse
        pool has no room for is counted in N_DROP_BLOCK and changes nothing."""
        r = touch(self, e, c)
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
            pt.delete_particles_in(self, e, c)
        return was_burning

    # ------------------------------------------------------------------------------------------ test hooks

    @ti.kernel
    def _ignite_cells(self, mask: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for e in range(self.num_envs):
            for c in range(self.num_cells):
                if mask[e, c] != 0 and self.can_ignite(e, c) != 0:
                    r = touch(self, e, c)
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
                    self.visit(e, c, self.counts[e, N_STEP] + 1)


@ti.func
def _remove_from_list(lst: ti.template(), counts: ti.template(), e, col, c):
    """Remove cell c from an env's unordered cell list by moving the last entry into its slot."""
    n = counts[e, col]
    for k in range(n):
        if lst[e, k] == c:
            lst[e, k] = lst[e, n - 1]
            counts[e, col] = n - 1
            break
