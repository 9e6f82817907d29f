"""FlyAgent vector environment: the Gymnasium face of :class:`roshan.kernels.fly.FlyKernels` (E fire maps with N
drones each, stepped by one kernel launch, same-step autoreset in a second one), a layer on
:class:`roshan.env.base.VectorEnvCore`."""

import gymnasium as gym
import numpy as np
import torch

from roshan.config import Config, DroneConfig, FlyConfig
from roshan.env.base import VectorEnvCore
from roshan.kernels import observe
from roshan.kernels.launch import PreparedLaunch
from roshan.kernels.pool import take_fly_sims


def fly_obs_views(buf: torch.Tensor, num_drones: int) -> dict[str, torch.Tensor]:
    """The observation dict of FlyAgent frames: views of ``buf`` (E, N, T, frame_width(N))."""
    n, k = num_drones, observe.OWN_FEATURES
    return {"agent": buf[..., :k], "neighbors": buf[..., k:k + 4 * n].unflatten(-1, (n, 4)),
            "neighbors_mask": buf[..., k + 4 * n:]}


class FlyVectorEnv(VectorEnvCore):
    """E FlyAgent environments as one Gymnasium vector env whose tensors are shared with torch.

    Observations are a dict of torch views into one buffer: ``agent`` (E, N, T, 9), ``neighbors``
    (E, N, T, N, 4) and ``neighbors_mask`` (E, N, T, N) (1.0 = valid slot). Rewards are (E, N) per drone;
    terminations and truncations (E,) (a timeout truncates). The same tensor objects are returned by every
    call. Actions (E, N, 2) in [-1, 1] (torch or numpy; values outside are clipped, NaN/inf raise).

    ``info`` holds ``final_obs`` (the observation of envs that ended this step, same layout), ``episode_stats``
    (a dict of (E,) tensors: success, reason index into :data:`REASONS`, steps, burned_fraction, extinguished,
    return), ``episode_fire`` (burning_fraction, lit_fraction at the end) and ``_episode_stats`` (the (E,) bool
    mask of envs whose episode ended).

    With ``FlyConfig.frame_skips = k`` one ``step`` applies the actions for k physics steps (fewer when the
    episode ends inside them) and returns the last step's rewards (the episode ``return`` sums those); step
    limits and the episode's ``steps`` count physics steps. With ``DroneConfig.use_water_limit`` the tanks are
    readable as :attr:`water`. ``fly`` overrides the task section of ``config`` (default: ``config.fly``).
    """

    def __init__(self, num_envs: int = 1, config: Config | None = None, fly: FlyConfig | None = None,
                 render_mode: str | None = None, seed: int | None = None):
        self.fly_config = fly or (config.fly if config is not None else FlyConfig())
        super().__init__(num_envs, config, seed, render_mode)
        n, frames = self.num_drones, self.fly_config.frames
        self._define_spaces(n, frames)
        self._allocate_buffers((n, frames, observe.frame_width(n)), (n,))
        # The step kernel reads the actions from a buffer of their own, so that its launch is set up once.
        self._actions = torch.zeros((num_envs, n, 2), dtype=torch.float32, device=self.device)
        self._actions_host = self._actions.numpy() if self.device.type == "cpu" else None
        self._launch_step = PreparedLaunch(self.kernels.step, self._actions, self._obs_buf, self._rewards,
                                           self._dones, self._episode)

    @property
    def fights_fire(self) -> bool:
        """The complex policy puts fires out; the simple one flies to goals (a fire or a corner)."""
        return self.fly_config.policy == "complex"

    def level_name(self) -> str:
        return f"FlyVectorEnv ({self.fly_config.policy} policy)"

    @property
    def physics_steps_per_step(self) -> int:
        return self.fly_config.frame_skips

    def _take_simulators(self, land, seed):
        return take_fly_sims(land, self.config, self.fly_config, self.num_envs, seed, owner=self,
                             extra_bytes=self._buffer_bytes(), who=self.level_name())

    def _buffer_bytes(self) -> int:
        n = self.num_drones
        actions = self.num_envs * n * 2 * 4
        return self._core_buffer_bytes(n * self.fly_config.frames * observe.frame_width(n), n) + actions

    def _define_spaces(self, n: int, frames: int) -> None:
        box = gym.spaces.Box
        # Every feature is clipped to [-1, 1] except the drone id (0..N-1, fed raw as in the reference).
        low = np.full((n, frames, observe.OWN_FEATURES), -1.0, np.float32)
        high = np.ones_like(low)
        low[..., 0], high[..., 0] = 0.0, n - 1
        self.single_observation_space = gym.spaces.Dict({
            "agent": box(low, high, dtype=np.float32),
            "neighbors": box(-1.0, 1.0, (n, frames, n, 4), np.float32),
            "neighbors_mask": box(0.0, 1.0, (n, frames, n), np.float32),
        })
        self.single_action_space = box(-1.0, 1.0, (n, 2), np.float32)
        self._batched_spaces()

    def _views(self, buf: torch.Tensor) -> dict[str, torch.Tensor]:
        return fly_obs_views(buf, self.num_drones)

    def _kernel_obs(self):
        # The observation is the frame stack itself; no explorers (the second stack is never touched).
        E = self.num_envs
        return self._obs_buf.view(E, -1), self._final_buf.view(E, -1), self._obs_buf, self._obs_buf

    def _advance(self, actions) -> None:
        self._take_actions(actions)
        self._launch_step()

    def _take_actions(self, actions) -> None:
        """Copy ``actions`` (float32, on the sim device) into the step kernel's buffer; non-finite values raise."""
        a = self._actions
        a.copy_(self._actions_tensor(actions, (self.num_envs, self.num_drones, 2), "envs, drones, 2"))
        # numpy's check of a few floats costs ~1 us where torch's costs ~20 us (three small ops)
        finite = np.isfinite(self._actions_host).all() if self._actions_host is not None else bool(a.isfinite().all())
        if not finite:
            e, d, _ = (~a.isfinite()).nonzero()[0].tolist()
            raise ValueError(f"actions: non-finite value {a[e, d].tolist()} for env {e}, drone {d}")

    @property
    def drone_config(self) -> DroneConfig:
        return self.config.drones

    @property
    def water(self) -> torch.Tensor:
        """(E, N) float32 drops left in each drone's tank: a copy on the sim device, not updated by later steps
        (always ``water_capacity`` without ``use_water_limit``)."""
        return self.drones.water.to_torch(device=self.device)
