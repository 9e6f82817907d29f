"""A cell's record (its fields: fire_records.py): where it lives in either layout, its reset, and the durations it
draws once per episode (docs/model/fire.md §2.3).

Dense layout: record r of env e is cell r. Sparse: a per-env pool of 8 x 8 blocks, where a block takes the env's
next free slot at the first write to one of its cells (:func:`touch`) and record r is cell (r & 63) of slot
r >> 6. The functions take the simulator as ``ti.template()`` (a :class:`roshan.kernels.fire.FireSim`) and use
its fields; ``ti.static(sim.sparse)`` picks the layout when a kernel is compiled.
"""

import taichi as ti

from roshan.kernels import rng
from roshan.kernels.fire_records import (
    BLOCK_CELLS,
    BLOCK_SHIFT,
    BLOCK_SIDE,
    C_FLAGS,
    C_PERIODS,
    FLAG_DRAWN,
    N_BLOCKS,
    N_DROP_BLOCK,
    NEVER,
    T_BURN_LEFT,
    T_BURN_TIME,
    T_EXPOSURE,
    T_IGN,
)


@ti.func
def record_of(sim: ti.template(), e, c) -> ti.i32:
    """Record index of cell c in env e; -1 where the sparse layout holds none (the cell is as reset)."""
    r = c
    if ti.static(sim.sparse):
        place = sim.cell_block[c]
        slot = sim.block_slot[e, place >> BLOCK_SHIFT]
        r = -1
        if slot >= 0:
            r = (slot << BLOCK_SHIFT) | (place & (BLOCK_CELLS - 1))
    return r


@ti.func
def touch(sim: ti.template(), e, c) -> ti.i32:
    """Record index of cell c for writing. The sparse layout first gives the cell's block the env's next free
    slot (reset records for its cells); -1 if the env's pool is full, counted in N_DROP_BLOCK."""
    r = c
    if ti.static(sim.sparse):
        place = sim.cell_block[c]
        b = place >> BLOCK_SHIFT
        slot = sim.block_slot[e, b]
        if slot < 0:
            n = sim.counts[e, N_BLOCKS]
            if n < sim.block_capacity:
                slot = n
                sim.counts[e, N_BLOCKS] = n + 1
                sim.block_slot[e, b] = slot
                sim.slot_block[e, slot] = b
                _reset_block(sim, e, b, slot)
            else:
                sim.counts[e, N_DROP_BLOCK] += 1
        r = -1
        if slot >= 0:
            r = (slot << BLOCK_SHIFT) | (place & (BLOCK_CELLS - 1))
    return r


@ti.func
def _reset_block(sim: ti.template(), e, b, slot):
    i0 = (b // sim.block_cols) * BLOCK_SIDE
    j0 = (b % sim.block_cols) * BLOCK_SIDE
    for k in range(BLOCK_CELLS):
        i = i0 + k // BLOCK_SIDE
        j = j0 + k % BLOCK_SIDE
        cls = 0  # the part of an edge block outside the map is never read
        if i < sim.rows and j < sim.cols:
            cls = sim.land[i * sim.cols + j]
        reset_record(sim, e, (slot << BLOCK_SHIFT) | k, cls)


@ti.func
def reset_record(sim: ti.template(), e, r, cls):
    """A new episode's cell: its class, no flags. Its durations are drawn when first needed.

    Most cells of an episode are never exposed nor lit, and a reset that drew all of them spent most of a
    random-action env step (ten hashes and two f64 divisions per cell). The draws are counter-based
    (keyed by episode and cell), so drawing later gives exactly the same values.
    """
    sim.cells[e, r] = ti.Vector([cls, 0, -1, 0], ti.i32)
    sim.mark[e, r] = 0
    sim.lit[e, r] = ti.u8(0)


@ti.func
def durations(sim: ti.template(), e, c):
    """(tau_ign, tau_burn) of cell c this episode, docs/model/fire.md §2.3: durations x (1 + s*u), s in {-1, 0, 1},
    u ~ U(0.1, 0.2); tau_ign is NEVER for a class that cannot ignite."""
    cls = sim.land[c]
    k = rng.key(sim.env_key[e], rng.DOMAIN_CELLS, c)
    s1 = ti.cast(rng.uniform_int(rng.key(k, 0, 0), 3) - 1, ti.f64)
    u1 = 0.1 + 0.1 * ti.cast(rng.uniform(rng.key(k, 1, 0)), ti.f64)
    s2 = ti.cast(rng.uniform_int(rng.key(k, 2, 0), 3) - 1, ti.f64)
    u2 = 0.1 + 0.1 * ti.cast(rng.uniform(rng.key(k, 3, 0)), ti.f64)
    tau_burn = ti.cast(sim.cls_tau_burn[cls], ti.f64) * (1.0 + s1 * u1)
    tau_ign = ti.f64(NEVER)
    if sim.cls_ignitable[cls] != 0:
        tau_ign = ti.cast(sim.cls_tau_ign[cls], ti.f64) * (1.0 + s2 * u2)
    return ti.Vector([tau_ign, tau_burn], ti.f64)


@ti.func
def emission_periods(sim: ti.template(), c, tau_burn: ti.f64) -> ti.i32:
    """Convection (low 16 bits) and radiation emission periods of cell c."""
    cls = sim.land[c]
    return _period(tau_burn, sim.cls_n_conv[cls]) | (_period(tau_burn, sim.cls_n_rad[cls]) << 16)


@ti.func
def draw_durations(sim: ti.template(), e, r, c):
    """Once per episode, before cell c (record r) is first exposed or lit: its durations and periods; also
    clears its exposure and burn timers. The flood timer is set by every flood and read only while the
    cell is flooded."""
    flags = sim.cells[e, r][C_FLAGS]
    if (flags & FLAG_DRAWN) == 0:
        d = durations(sim, e, c)
        sim.cells[e, r][C_PERIODS] = emission_periods(sim, c, d[1])
        sim.cells[e, r][C_FLAGS] = flags | FLAG_DRAWN
        sim.timers[e, r][T_IGN] = d[0]
        sim.timers[e, r][T_BURN_LEFT] = d[1]
        sim.timers[e, r][T_BURN_TIME] = 0.0
        sim.timers[e, r][T_EXPOSURE] = 0.0


@ti.func
def _period(tau_burn: ti.f64, n: ti.i32) -> ti.i32:
    """Emission period in whole seconds: max(1, floor((tau_burn - 1) / n)) (docs/model/fire.md §2.3)."""
    p = 1
    if n > 0:
        p = ti.max(1, ti.cast(ti.floor((tau_burn - 1.0) / n), ti.i32))
    return p
