"""The episode record every vector env writes when an episode ends, and the failure reasons: what every layer
reads (envs expose it as ``info["episode_stats"]``, runs and reports summarise it). No Taichi here; the
``ti.func`` that writes a record is :func:`roshan.kernels.episode.write_record`.
"""

# lost: with a battery (drones.energy), a FlyAgent drone came down with an empty battery, or every planner drone did
REASONS = ("none", "timeout", "boundary", "burnout", "collision", "lost")
TIMEOUT, BOUNDARY, BURNOUT, COLLISION, LOST = 1, 2, 3, 4, 5
EPISODE_FIELDS = ("success", "reason", "steps", "burned_fraction", "extinguished", "return")
# The fire at the episode's end, as fractions of the map's cells: burning then, and every cell lit in the
# episode (burning, burned out or extinguished). Kept beside the record (``info["episode_fire"]``), not in it:
# ``EPISODE_FIELDS`` is the layout the pinned record hashes and the training logs read.
FIRE_FIELDS = ("burning_fraction", "lit_fraction")
# The drones' batteries over the episode (zero without drones.energy): drones lost, battery swaps at the
# groundstation, joules drawn (sums over the drones) and seconds landed there (the mean over the drones).
ENERGY_FIELDS = ("drones_lost", "battery_swaps", "energy_used", "base_time")
RECORD_FIELDS = EPISODE_FIELDS + FIRE_FIELDS + ENERGY_FIELDS  # the columns of the record array the kernels write
FAILURES = ("collision", "boundary", "timeout", "burnout", "lost")
