"""The fire model's record layout: per-cell record fields and flags, per-env counters, sparse block geometry.

Shared by the env-serial update (``fire.py``) and the chunked one (``fire_parallel.py``); other modules ask
``FireSim`` by name (``cell_state``, ``burning_count``, ...) rather than read these.
"""

# Cell records: integers (state, flags, visit stamp, emission periods) and f64 timers (seconds).
C_STATE, C_FLAGS, C_VISIT, C_PERIODS = range(4)
CELL_FIELDS = 4
T_IGN, T_BURN_LEFT, T_BURN_TIME, T_EXPOSURE, T_FLOOD = range(5)
TIMER_FIELDS = 5
FLAG_EXPOSED = 1  # the cell is in the exposed ("ticking") list
FLAG_BURNED_DOWN = 2  # burned out completely once (a flood returns it to BURNED)
FLAG_DRAWN = 4  # this episode's durations, periods and exposure/burn timers are set (see fire_cells.draw_durations)
FLAG_EXTINGUISHED = 8  # water put this cell out while it burned, this episode (read by rendering only)
NEVER = -1.0  # tau_ign of cells that cannot ignite (the reference skips their exposure)

# Per-env counters (E, N_COUNTS): list lengths, statistics and the update count since the last reset.
# A row is padded to 16 ints = one 64-byte cache line, so threads stepping neighbouring envs do not write
# to the same line (false sharing halved two-thread throughput below ~1000 envs).
(N_BURNING, N_EXPOSED, N_FLOODED, N_CONV, N_RAD, N_BURNED, N_DROP_CONV, N_DROP_RAD, N_EXTINGUISHED,
 N_IGNITED_INIT, N_IGNITION_SHORT, N_STEP, N_LIT, N_BLOCKS, N_DROP_BLOCK) = range(15)
N_COUNTS = 16
STAT_NAMES = {
    "burning": N_BURNING,
    "burned": N_BURNED,
    "convection": N_CONV,
    "radiation": N_RAD,
    "dropped_convection": N_DROP_CONV,
    "dropped_radiation": N_DROP_RAD,
    "flooded": N_FLOODED,
    "extinguished": N_EXTINGUISHED,
    "initial_fires": N_IGNITED_INIT,
    "blocks": N_BLOCKS,
    "dropped_blocks": N_DROP_BLOCK,
}
BLOCK_SIDE = 8  # sparse layout: cells per block side
BLOCK_SHIFT = 6  # log2(cells per block)
BLOCK_CELLS = 1 << BLOCK_SHIFT

# What one update does with a burning cell (FireSim.burn_tick), as bits.
EMIT_CONV, EMIT_RAD, BURNED_OUT = 1, 2, 4
