"""FlyAgent vector environment: the Gymnasium face of :class:`roshan.kernels.fly.FlyKernels` (E fire maps with N
drones each, stepped by one kernel launch, same-step autoreset in a second one)."""

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from roshan.config import Config, DroneConfig, FlyConfig
from roshan.episode import EPISODE_FIELDS
from roshan.kernels import observe
from roshan.kernels.drones import DroneSim
from roshan.kernels.fire import FireSim
from roshan.kernels.fly import FlyKernels, time_limit
from roshan.kernels.render import EnvZeroFrames
from roshan.maps import load_map
from roshan.runtime import ensure_taichi, torch_device


def fly_obs_views(buf: torch.Tensor, num_drones: int) -> dict[str, torch.Tensor]:
    """The observation dict of FlyAgent frames: views of ``buf`` (E, N, T, frame_width(N))."""
    n, k = num_drones, observe.OWN_FEATURES
    return {"agent": buf[..., :k], "neighbors": buf[..., k:k + 4 * n].unflatten(-1, (n, 4)),
            "neighbors_mask": buf[..., k + 4 * n:]}


class FlyVectorEnv(gym.vector.VectorEnv):
    """E FlyAgent environments as one Gymnasium vector env whose tensors are shared with torch.

    Observations are a dict of torch views into one buffer: ``agent`` (E, N, T, 9), ``neighbors``
    (E, N, T, N, 4) and ``neighbors_mask`` (E, N, T, N) (1.0 = valid slot). Rewards are (E, N) per drone;
    terminations and truncations (E,) (a timeout truncates). The same tensor objects are returned by every
    call. Actions (E, N, 2) in [-1, 1] (torch or numpy; values outside are clipped, NaN/inf raise).

    ``info`` holds ``final_obs`` (the observation of envs that ended this step, same layout), ``episode_stats``
    (a dict of (E,) tensors: success, reason index into :data:`REASONS`, steps, burned_fraction, extinguished,
    return) and ``_episode_stats`` (the (E,) bool mask of envs whose episode ended).

    With ``FlyConfig.frame_skips = k`` one ``step`` applies the actions for k physics steps (fewer when the
    episode ends inside them) and returns the last step's rewards (the episode ``return`` sums those); step
    limits and the episode's ``steps`` count physics steps. With ``DroneConfig.use_water_limit`` the tanks are
    readable as :attr:`water`.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}

    def __init__(self, num_envs: int = 1, config: Config | None = None, fly: FlyConfig | None = None,
                 render_mode: str | None = None, seed: int | None = None):
        ensure_taichi()
        cfg = config or Config()
        self.config, self.fly_config = cfg, fly or FlyConfig()
        self.render_mode = render_mode
        land = load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows,
                        cols=cfg.map.uniform_cols)
        self.fire = FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=num_envs,
                            seed=cfg.sim.seed if seed is None else seed)
        self.drones = DroneSim(self.fire, cfg.drones)
        self.t_max = time_limit(land.rows, land.cols, land.cell_size, cfg.fire.dt, cfg.drones.max_speed,
                                cfg.ignition.fire_percentage, self.fly_config)
        self.kernels = FlyKernels(self.fire, self.drones, self.fly_config, self.t_max)
        self.num_envs = num_envs
        self.num_drones = n = cfg.drones.num_drones
        frames = self.fly_config.frames
        self.device = torch.device(torch_device())
        self._define_spaces(num_envs, n, frames)
        width = observe.frame_width(n)
        dev = self.device
        self._obs_buf = torch.zeros((num_envs, n, frames, width), dtype=torch.float32, device=dev)
        self._final_buf = torch.zeros_like(self._obs_buf)
        self._rewards = torch.zeros((num_envs, n), dtype=torch.float32, device=dev)
        self._dones = torch.zeros((num_envs, 2), dtype=torch.uint8, device=dev)
        self._episode = torch.zeros((num_envs, len(EPISODE_FIELDS)), dtype=torch.float32, device=dev)
        self._obs = self._views(self._obs_buf)
        done_bool = self._dones.view(torch.bool)
        self.terminations, self.truncations = done_bool[:, 0], done_bool[:, 1]
        # "episode_stats", not "episode": gymnasium's RecordEpisodeStatistics writes info["episode"] itself.
        self._info = {"final_obs": self._views(self._final_buf),
                      "episode_stats": {k: self._episode[:, i] for i, k in enumerate(EPISODE_FIELDS)}}
        self._viewer = EnvZeroFrames(self.drones)
        self._has_reset = False

    def _define_spaces(self, num_envs: int, n: int, frames: int) -> None:
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
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)

    def _kernel_obs(self):
        flat = self._obs_buf.view(self.num_envs, -1)
        return flat, self._final_buf.view(self.num_envs, -1), self._obs_buf, self._obs_buf

    def _views(self, buf: torch.Tensor) -> dict[str, torch.Tensor]:
        return fly_obs_views(buf, self.num_drones)

    # ------------------------------------------------------------------------------------------ gymnasium

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start new episodes in every env; ``seed`` restarts every random stream from that seed."""
        super().reset(seed=seed)
        if seed is not None:
            self.fire.seed = int(seed)
            self.fire.episode.fill(-1)
        self.kernels.reset_all(*self._kernel_obs(), self.fire.seed_key)
        self._episode.zero_()
        self._dones.zero_()
        self._has_reset = True
        return self._obs, {}

    def step(self, actions):
        """Advance every env by one FlyAgent step; envs that end are reset in the same call."""
        if not self._has_reset:
            raise gym.error.ResetNeeded("FlyVectorEnv.step() before reset(): call reset() first")
        a = self._check_actions(actions)
        k = self.kernels
        k.step(a, self._obs_buf, self._rewards, self._dones, self._episode)
        # On the CPU, reading the done flags costs microseconds and saves the reset launch (~150 us) in the
        # many steps where no episode ends; on a GPU that read would synchronise, so always launch.
        if self.device.type != "cpu" or bool(self._dones.any()):
            k.restart(*self._kernel_obs(), self.fire.seed_key, 1)
        info = dict(self._info)
        info["_episode_stats"] = self.terminations | self.truncations
        info["_final_obs"] = info["_episode_stats"]
        return self._obs, self._rewards, self.terminations, self.truncations, info

    def _check_actions(self, actions) -> torch.Tensor:
        want = (self.num_envs, self.num_drones, 2)
        if isinstance(actions, np.ndarray):
            actions = torch.from_numpy(actions)
        elif not isinstance(actions, torch.Tensor):
            actions = torch.as_tensor(np.asarray(actions))
        if tuple(actions.shape) != want:
            raise ValueError(f"actions: expected shape {want} (envs, drones, 2), got {tuple(actions.shape)}")
        a = actions.to(device=self.device, dtype=torch.float32).contiguous()
        finite = torch.isfinite(a)
        if not bool(finite.all()):
            e, d, _ = (~finite).nonzero()[0].tolist()
            raise ValueError(f"actions: non-finite value {a[e, d].tolist()} for env {e}, drone {d}")
        return a

    def render(self):
        """An RGB frame (H, W, 3) uint8 of env 0: land cover, fire, particles, drones, goals, groundstation."""
        return self._viewer.render()

    def close(self, **kwargs):
        self._viewer.close()

    @property
    def drone_config(self) -> DroneConfig:
        return self.config.drones

    @property
    def water(self) -> torch.Tensor:
        """(E, N) float32 drops left in each drone's tank: a copy on the sim device, not updated by later steps
        (always ``water_capacity`` without ``use_water_limit``)."""
        return self.drones.water.to_torch(device=self.device)
