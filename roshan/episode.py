"""The episode record every vector env writes when an episode ends, and the failure reasons: what every layer
reads (envs expose it as ``info["episode_stats"]``, runs and reports summarise it). No Taichi here; the
``ti.func`` that writes a record is :func:`roshan.kernels.episode.write_record`.
"""

from dataclasses import dataclass

# lost: with a battery (drones.energy), a FlyAgent drone came down with an empty battery, or every planner drone did
REASONS = ("none", "timeout", "boundary", "burnout", "collision", "lost")
TIMEOUT, BOUNDARY, BURNOUT, COLLISION, LOST = 1, 2, 3, 4, 5
EPISODE_FIELDS = ("success", "reason", "steps", "burned_fraction", "extinguished", "return")
# The fire at the episode's end, as fractions of the map's cells: burning then, and every cell lit in the
# episode (burning, burned out or extinguished). Kept beside the record (``info["episode_fire"]``), not in it:
# ``EPISODE_FIELDS`` is the layout the pinned record hashes and the training logs read.
FIRE_FIELDS = ("burning_fraction", "lit_fraction")


@dataclass(frozen=True)
class Column:
    """One of the record's extra columns: a figure the drones count over an episode. Every layer above the kernels
    handles these alike, by this declaration: ``info``, episode sets, the episodes CSV, summaries, tables, the
    ``Evaluation/*`` TensorBoard scalars, the eval JSON and map suites."""

    name: str  # its key in the record, in info, episode sets, summaries and the eval JSON
    header: str  # its column in the episodes CSV, and its TensorBoard tag (Evaluation/<header>_mean, ...)
    is_count: bool  # whole numbers (int in episode sets and the CSV); else a float >= 0
    label: str = ""  # a row "<label> (per episode)" of the evaluation table and a column of a map suite; "": none


# The record's extra columns, in the order the kernels write them: the drones' batteries over the episode
# (:meth:`roshan.kernels.battery.Battery.totals`), zero without drones.energy.
EXTRA_COLUMNS = (
    # drones that came down with an empty battery; a row of the tables, since the "lost" rate counts only the
    # episodes that lost every drone (50 of 64 drones down reads 0.0 % there)
    Column("drones_lost", "Drones_Lost", is_count=True, label="Drones lost"),
    Column("battery_swaps", "Battery_Swaps", is_count=True),  # swaps at the groundstation
    Column("energy_used", "Energy_Used", is_count=False),  # joules drawn, summed over the drones
    Column("base_time", "Base_Time", is_count=False),  # seconds landed at the groundstation, the drones' mean
)
EXTRA_FIELDS = tuple(c.name for c in EXTRA_COLUMNS)
RECORD_FIELDS = EPISODE_FIELDS + FIRE_FIELDS + EXTRA_FIELDS  # the columns of the record array the kernels write
# The record as an env hands it out: info key -> its columns (each a dict of (E,) tensors). "episode_stats", not
# "episode": gymnasium's RecordEpisodeStatistics writes info["episode"] itself.
RECORD_INFO = {"episode_stats": EPISODE_FIELDS, "episode_fire": FIRE_FIELDS, "episode_energy": EXTRA_FIELDS}
FAILURES = ("collision", "boundary", "timeout", "burnout", "lost")
