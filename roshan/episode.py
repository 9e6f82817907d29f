"""The episode record every vector env writes when an episode ends, and the failure reasons: what every layer
reads (envs expose it as ``info["episode_stats"]``, runs and reports summarise it). No Taichi here; the
``ti.func`` that writes a record is :func:`roshan.kernels.episode.write_record`.
"""

REASONS = ("none", "timeout", "boundary", "burnout", "collision")
TIMEOUT, BOUNDARY, BURNOUT, COLLISION = 1, 2, 3, 4
EPISODE_FIELDS = ("success", "reason", "steps", "burned_fraction", "extinguished", "return")
# The fire at the episode's end, as fractions of the map's cells: burning then, and every cell lit in the
# episode (burning, burned out or extinguished). Kept beside the record (``info["episode_fire"]``), not in it:
# ``EPISODE_FIELDS`` is the layout the pinned record hashes and the training logs read.
FIRE_FIELDS = ("burning_fraction", "lit_fraction")
RECORD_FIELDS = EPISODE_FIELDS + FIRE_FIELDS  # the columns of the record array the kernels write
FAILURES = ("collision", "boundary", "timeout", "burnout")
