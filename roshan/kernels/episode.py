"""Episode bookkeeping shared by the task kernels of every level: the record (:mod:`roshan.episode`) written
when an episode ends, the per-env counters, and the same-step autoreset kernel.

One record row per env, ``RECORD_FIELDS`` in order; valid where the episode ended this step.
"""

import taichi as ti

from roshan.config import ConfigError
from roshan.config.schema import INT32_MAX
from roshan.episode import EXTRA_FIELDS, RECORD_FIELDS

EP_SUCCESS, EP_REASON, EP_STEPS, EP_BURNED, EP_EXTINGUISHED, EP_RETURN, EP_BURNING, EP_LIT = (
    RECORD_FIELDS.index(k) for k in ("success", "reason", "steps", "burned_fraction", "extinguished", "return",
                                     "burning_fraction", "lit_fraction"))
EP_EXTRA = RECORD_FIELDS.index(EXTRA_FIELDS[0])  # the extra columns follow one another from here


@ti.func
def write_record(episode: ti.template(), fire: ti.template(), e, success, reason, steps, ret):
    """Env e's record: outcome, steps, its fire (fractions of the map burned out, burning now and ever lit;
    extinguished cells as a count) and its return."""
    episode[e, EP_SUCCESS] = ti.cast(success, ti.f32)
    episode[e, EP_REASON] = ti.cast(reason, ti.f32)
    episode[e, EP_STEPS] = ti.cast(steps, ti.f32)
    episode[e, EP_BURNED] = ti.cast(fire.burned_count(e), ti.f32) / fire.num_cells
    episode[e, EP_EXTINGUISHED] = ti.cast(fire.extinguished_count(e), ti.f32)
    episode[e, EP_RETURN] = ret
    episode[e, EP_BURNING] = ti.cast(fire.burning_count(e), ti.f32) / fire.num_cells
    episode[e, EP_LIT] = ti.cast(fire.lit_count(e), ti.f32) / fire.num_cells


@ti.func
def write_extra(episode: ti.template(), drones: ti.template(), e):
    """Env e's extra columns (:data:`roshan.episode.EXTRA_COLUMNS`): what its drones counted over the episode
    (:meth:`roshan.kernels.drones.DroneSim.record_totals`)."""
    totals = drones.record_totals(e)
    for k in ti.static(range(len(EXTRA_FIELDS))):
        episode[e, EP_EXTRA + k] = totals[k]


@ti.data_oriented
class EpisodeKernels:
    """The episode half of a level's kernels over a FireSim: step limit, step count, return, the ``ended``
    flags and the kernel that restarts the flagged envs.

    A subclass provides ``new_episode(obs, frames, explore_frames, e, seed_key)`` (a ``ti.func`` resetting
    env e, whose fire is already reset, and writing its first observation). Observations reach the kernels as
    ``obs`` / ``final_obs`` (the level's observation rows, (E, W)) and the FlyAgent frame stacks of the drones and
    of the explorers (the FlyAgent level has no explorers and passes its own frames again; they are not touched).

    Resetting in its own kernel, shared with ``reset()``, compiles the reset code once instead of inlining it
    into the step kernel too (a fresh machine compiled the fused version for ~25 s).
    """

    def __init__(self, fire, t_max: int):
        if t_max > INT32_MAX:  # counted in int32 fields: a slow drone or a tiny fire.dt would wrap the count
            raise ConfigError(f"the episode's step limit T_max = {t_max:.3g} steps (docs/model/agents.md §5) is more "
                              f"than a step counter holds ({INT32_MAX}); raise drones.max_speed or fire.dt, or lower "
                              "fly.k_turn")
        self.fire, self.t_max = fire, t_max
        E = fire.num_envs
        self.ended = ti.field(ti.i32, E)  # the episode ended: restart() resets the env
        self.remaining = ti.field(ti.i32, E)  # physics steps left
        self.steps = ti.field(ti.i32, E)  # physics steps so far (the TTE)
        self.ret = ti.field(ti.f32, E)

    @staticmethod
    def field_bytes(num_envs: int) -> int:
        """Bytes of the episode fields of ``num_envs`` envs (ended, remaining, steps, ret)."""
        return 16 * num_envs

    def reset_all(self, obs, final_obs, frames, explore_frames, seed_key: int) -> None:
        """Start a new episode in every env (``final_obs`` untouched)."""
        self.ended.fill(1)
        self.restart(obs, final_obs, frames, explore_frames, seed_key, 0)

    def restart(self, obs, final_obs, frames, explore_frames, seed_key: int, keep_final: int) -> None:
        """Reset the envs flagged in ``ended``, first copying their observation to ``final_obs``: the fires in
        one kernel, then the level's part (``new_episode``) in another. One kernel holding both compiled 2-3x
        slower than the two (Taichi's passes grow faster than the code they optimise); envs are independent,
        so the trajectories are the same."""
        self._restart_fires(obs, final_obs, seed_key, keep_final)
        self._restart_level(obs, frames, explore_frames, seed_key)

    @ti.kernel
    def _restart_fires(self, obs: ti.types.ndarray(dtype=ti.f32, ndim=2),
                       final_obs: ti.types.ndarray(dtype=ti.f32, ndim=2), seed_key: ti.u32, keep_final: ti.i32):
        ti.loop_config(serialize=self.fire.serial_envs)
        for v in range(self.fire.num_envs * self.fire.env_pad):
            e = v // self.fire.env_pad
            if v % self.fire.env_pad == 0 and self.ended[e] != 0:
                if keep_final != 0:
                    for k in range(obs.shape[1]):
                        final_obs[e, k] = obs[e, k]
                self.fire.reset_env(e, seed_key)

    @ti.kernel
    def _restart_level(self, obs: ti.types.ndarray(dtype=ti.f32, ndim=2),
                       frames: ti.types.ndarray(dtype=ti.f32, ndim=4),
                       explore_frames: ti.types.ndarray(dtype=ti.f32, ndim=4), seed_key: ti.u32):
        ti.loop_config(serialize=self.fire.serial_envs)
        for v in range(self.fire.num_envs * self.fire.env_pad):
            e = v // self.fire.env_pad
            if v % self.fire.env_pad == 0 and self.ended[e] != 0:
                self.new_episode(obs, frames, explore_frames, e, seed_key)
                self.ended[e] = 0

    @ti.func
    def start_counters(self, e):
        self.remaining[e] = self.t_max
        self.steps[e] = 0
        self.ret[e] = 0.0

    @ti.func
    def close_episode(self, episode: ti.template(), dones: ti.template(), e, success, reason, truncated):
        """Write env e's record and done flags: truncated (a pure time-out) or terminated."""
        write_record(episode, self.fire, e, success, reason, self.steps[e], self.ret[e])
        write_extra(episode, self.drones, e)
        dones[e, 0] = ti.cast(1 - truncated, ti.u8)
        dones[e, 1] = ti.cast(truncated, ti.u8)
