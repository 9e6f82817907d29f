"""Writing the episode record (:mod:`roshan.episode`) from inside the step kernels.

One row per env, ``EPISODE_FIELDS`` in order; valid where the episode ended this step.
"""

import taichi as ti

from roshan.episode import EPISODE_FIELDS
from roshan.kernels.fire import N_BURNED, N_EXTINGUISHED

EP_SUCCESS, EP_REASON, EP_STEPS, EP_BURNED, EP_EXTINGUISHED, EP_RETURN = (EPISODE_FIELDS.index(k) for k in (
    "success", "reason", "steps", "burned_fraction", "extinguished", "return"))


@ti.func
def write_record(episode: ti.template(), fire: ti.template(), e, success, reason, steps, ret):
    """Env e's record: outcome, steps, burned fraction and extinguished cells of its fire, and its return."""
    episode[e, EP_SUCCESS] = ti.cast(success, ti.f32)
    episode[e, EP_REASON] = ti.cast(reason, ti.f32)
    episode[e, EP_STEPS] = ti.cast(steps, ti.f32)
    episode[e, EP_BURNED] = ti.cast(fire.counts[e, N_BURNED], ti.f32) / fire.num_cells
    episode[e, EP_EXTINGUISHED] = ti.cast(fire.counts[e, N_EXTINGUISHED], ti.f32)
    episode[e, EP_RETURN] = ret
