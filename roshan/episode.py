"""The episode record every vector env writes when an episode ends, and the failure reasons: what every layer
reads (envs expose it as ``info["episode_stats"]``, runs and reports summarise it). No Taichi here; the
``ti.func`` that writes a record is :func:`roshan.kernels.episode.write_record`.
"""

REASONS = ("none", "timeout", "boundary", "burnout", "collision")
TIMEOUT, BOUNDARY, BURNOUT, COLLISION = 1, 2, 3, 4
EPISODE_FIELDS = ("success", "reason", "steps", "burned_fraction", "extinguished", "return")
FAILURES = ("collision", "boundary", "timeout", "burnout")
