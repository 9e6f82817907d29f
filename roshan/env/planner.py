"""PlannerAgent vector environment (agents.md 13): one decision assigns every planner drone a goal among the
known fires and the groundstation; frozen FlyAgent policies then fly the drones (and the explorers) for
``interval`` low-level steps inside the batched kernels of :mod:`roshan.kernels.planner`.

The same class runs the greedy heuristic baseline (agents.md 10.2) with ``controller="greedy"``: it ignores
the actions, and since fire layouts and wind depend only on the env seed and the episode count, a planner and
the heuristic evaluated with the same seed and number of envs play identical initial episodes.
"""

from dataclasses import replace

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from roshan.algos.frozen import FrozenFlyPolicy
from roshan.config import CONTROLLERS, Config, PlannerConfig
from roshan.env.fly import fly_obs_views
from roshan.episode import EPISODE_FIELDS
from roshan.kernels import observe
from roshan.kernels.drones import DroneSim
from roshan.kernels.explore import ExploreMaps
from roshan.kernels.fire import FireSim
from roshan.kernels.planner import PlannerKernels, obs_layout, planner_time_limit
from roshan.kernels.render import EnvZeroFrames
from roshan.kernels.rewards import PlannerCoefficients
from roshan.maps import load_map
from roshan.runtime import ensure_taichi, torch_device


class PlannerVectorEnv(gym.vector.VectorEnv):
    """E planner environments as one Gymnasium vector env whose tensors are shared with torch.

    Observation: a dict of torch views into one (E, W) buffer: ``drones`` (E, N, 2), ``goals`` (E, N, 2),
    ``water`` (E, N, 1), ``fires`` (E, K, 2) candidates (index 0 = groundstation, then fire cells in row-major
    order, zero padded), ``fires_mask`` (E, K) 1.0 = valid, ``globals`` (E, 5) (fire count, fire centroid, wind).
    Action: (E, N) integer candidate indices; an index past the valid list sends the drone to the
    groundstation. Rewards (E,); terminations / truncations (E,) (a timeout truncates). ``info`` holds
    ``final_obs`` and ``episode_stats`` like :class:`roshan.env.fly.FlyVectorEnv`; ``steps`` in the record is
    the TTE in low-level steps.

    Args:
        num_envs: E.
        config: simulator sections (map, fire, wind, ignition, planner drones, sim).
        planner: the planner level.
        evaluation: explorers move and the candidates come from ``planner.eval_fires`` (else training:
            explorers wait at the groundstation, candidates from ``planner.train_fires``).
        controller: ``"planner"`` (goals from the actions) or ``"greedy"`` (the heuristic; actions ignored).
        seed: env seed (default ``config.sim.seed``).
        fly_policy, explorer_policy: preloaded frozen policies (default: load ``planner.fly_model`` /
            ``planner.explorer_model``).
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}
    is_planner = True  # actions are per-env candidate indices, not per-drone velocities

    def __init__(self, num_envs: int = 1, config: Config | None = None, planner: PlannerConfig | None = None,
                 evaluation: bool = False, controller: str = "planner", seed: int | None = None,
                 fly_policy: FrozenFlyPolicy | None = None, explorer_policy: FrozenFlyPolicy | None = None,
                 render_mode: str | None = None):
        if controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}, got {controller!r}")
        ensure_taichi()
        cfg = config or Config()
        pc = planner or PlannerConfig()
        self.config, self.planner_config, self.controller = cfg, pc, controller
        self.evaluation, self.render_mode = evaluation, render_mode
        self.fly_policy = fly_policy or FrozenFlyPolicy(pc.fly_model, torch_device())
        move_explorers = evaluation or controller == "greedy"
        self.explorer_policy = None
        if move_explorers:
            self.explorer_policy = explorer_policy or FrozenFlyPolicy(pc.explorer_model, torch_device())
        land = load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows,
                        cols=cfg.map.uniform_cols)
        self.fire = FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=num_envs,
                            seed=cfg.sim.seed if seed is None else seed)
        self.drones = DroneSim(self.fire, cfg.drones)
        explorer_cfg = replace(cfg.drones, num_drones=pc.num_explorers, max_speed=pc.explorer_speed,
                               view_range=pc.explorer_view_range)
        self.explorers = DroneSim(self.fire, explorer_cfg)
        self.maps = ExploreMaps(self.fire, self.explorers, pc.num_explorers, pc.explorer_view_range,
                                version=pc.meander, index_bound=pc.explorer_index_bound)
        self.t_max = planner_time_limit(land.rows, land.cols, land.cell_size, cfg.fire.dt, cfg.drones.max_speed,
                                        cfg.ignition.fire_percentage, pc.time_limit)
        self.max_candidates = pc.max_candidates or land.rows * land.cols + 1
        fires = pc.eval_fires if evaluation else pc.train_fires
        self.kernels = PlannerKernels(
            self.fire, self.drones, self.explorers, self.maps, interval=pc.interval, t_max=self.t_max,
            coef=PlannerCoefficients.resolve(pc.rewards), greedy=controller == "greedy",
            move_explorers=move_explorers, detected=fires == "detected" or controller == "greedy",
            burnout=pc.burnout, max_candidates=self.max_candidates, fly_frames=self.fly_policy.frames,
            explore_frames=self.explorer_policy.frames if self.explorer_policy else 1)
        self.num_envs = num_envs
        self.num_drones = n = cfg.drones.num_drones
        self.interval = pc.interval
        self.device = dev = torch.device(torch_device())
        self._define_spaces(num_envs, n)
        self.layout = obs_layout(n, self.max_candidates)
        width = max(end for _, end in self.layout.values())
        self._obs_buf = torch.zeros((num_envs, width), dtype=torch.float32, device=dev)
        self._final_buf = torch.zeros_like(self._obs_buf)
        m = pc.num_explorers
        self._fly_buf = torch.zeros((num_envs, n, self.fly_policy.frames, observe.frame_width(n)), device=dev)
        ex_frames = self.explorer_policy.frames if self.explorer_policy else 1
        self._explore_buf = torch.zeros((num_envs, m, ex_frames, observe.frame_width(m)), device=dev)
        self._fly_obs = fly_obs_views(self._fly_buf, n)
        self._explore_obs = fly_obs_views(self._explore_buf, m)
        self._explore_actions = torch.zeros((num_envs, m, 2), device=dev)
        self._rewards = torch.zeros(num_envs, dtype=torch.float32, device=dev)
        self._dones = torch.zeros((num_envs, 2), dtype=torch.uint8, device=dev)
        self._episode = torch.zeros((num_envs, len(EPISODE_FIELDS)), dtype=torch.float32, device=dev)
        self._obs = self._views(self._obs_buf)
        done_bool = self._dones.view(torch.bool)
        self.terminations, self.truncations = done_bool[:, 0], done_bool[:, 1]
        self._info = {"final_obs": self._views(self._final_buf),
                      "episode_stats": {k: self._episode[:, i] for i, k in enumerate(EPISODE_FIELDS)}}
        self._viewer = EnvZeroFrames(self.drones)
        self._has_reset = False

    def _define_spaces(self, num_envs: int, n: int) -> None:
        box, k = gym.spaces.Box, self.max_candidates
        self.single_observation_space = gym.spaces.Dict({
            "drones": box(-np.inf, np.inf, (n, 2), np.float32),  # outside [-1, 1] when a drone leaves the map
            "goals": box(-1.0, 1.0, (n, 2), np.float32),
            "water": box(0.0, 1.0, (n, 1), np.float32),
            "fires": box(-1.0, 1.0, (k, 2), np.float32),
            "fires_mask": box(0.0, 1.0, (k,), np.float32),
            "globals": box(-2.0, 1.0, (5,), np.float32),
        })
        self.single_action_space = gym.spaces.MultiDiscrete(np.full(n, k))
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)

    def _views(self, buf: torch.Tensor) -> dict[str, torch.Tensor]:
        n, k = self.num_drones, self.max_candidates
        shapes = {"drones": (n, 2), "goals": (n, 2), "water": (n, 1), "fires": (k, 2), "fires_mask": (k,),
                  "globals": (5,)}
        return {name: buf[:, a:b].unflatten(1, shapes[name]) for name, (a, b) in self.layout.items()}

    # ------------------------------------------------------------------------------------------ gymnasium

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start new episodes in every env; ``seed`` restarts every random stream from that seed."""
        super().reset(seed=seed)
        if seed is not None:
            self.fire.seed = int(seed)
            self.fire.episode.fill(-1)
        k = self.kernels
        k.reset_all(self._obs_buf, self._final_buf, self._fly_buf, self._explore_buf, self.fire.seed_key)
        self._episode.zero_()
        self._dones.zero_()
        self._has_reset = True
        return self._obs, {}

    @torch.no_grad()
    def step(self, actions):
        """One planner decision: set the goals, fly ``interval`` low-level steps, reward, observe; envs that end
        are reset in the same call."""
        if not self._has_reset:
            raise gym.error.ResetNeeded("PlannerVectorEnv.step() before reset(): call reset() first")
        k = self.kernels
        k.begin(self._rewards, self._dones)
        if self.controller == "planner":
            k.apply(self._check_actions(actions))
        for _ in range(self.interval):
            fly_actions = self.fly_policy(self._fly_obs).contiguous()
            if self.explorer_policy is not None:
                self._explore_actions = self.explorer_policy(self._explore_obs).contiguous()
            k.low_step(fly_actions, self._explore_actions, self._fly_buf, self._explore_buf, self._rewards,
                       self._dones, self._episode)
        k.finish(self._obs_buf, self._rewards, self._dones, self._episode)
        if self.device.type != "cpu" or bool(self._dones.any()):
            k.restart(self._obs_buf, self._final_buf, self._fly_buf, self._explore_buf, self.fire.seed_key, 1)
        info = dict(self._info)
        info["_episode_stats"] = self.terminations | self.truncations
        info["_final_obs"] = info["_episode_stats"]
        return self._obs, self._rewards, self.terminations, self.truncations, info

    def _check_actions(self, actions) -> torch.Tensor:
        want = (self.num_envs, self.num_drones)
        if isinstance(actions, np.ndarray):
            actions = torch.from_numpy(actions)
        elif not isinstance(actions, torch.Tensor):
            actions = torch.as_tensor(np.asarray(actions))
        if tuple(actions.shape) != want:
            raise ValueError(f"actions: expected shape {want} (envs, drones), got {tuple(actions.shape)}")
        if actions.is_floating_point() or actions.is_complex():
            raise ValueError(f"actions: expected integer candidate indices, got dtype {actions.dtype}")
        a = actions.to(device=self.device, dtype=torch.int64).contiguous()
        bad = (a < 0) | (a >= self.max_candidates)
        if bool(bad.any()):
            e, d = bad.nonzero()[0].tolist()
            raise ValueError(f"actions: candidate index {int(a[e, d])} for env {e}, drone {d} is outside "
                             f"[0, {self.max_candidates})")
        return a

    # ------------------------------------------------------------------------------------------ helpers

    @property
    def candidate_counts(self) -> torch.Tensor:
        """(E,) valid candidates per env, groundstation included (a copy)."""
        return self.kernels.cand_count.to_torch(device=self.device)

    def goals(self) -> np.ndarray:
        """(E, N, 2) current drone goals in grid units (a copy; tests, rendering)."""
        return self.drones.goal.to_numpy()

    def render(self):
        """An RGB frame (H, W, 3) uint8 of env 0: land cover, fire, drones with their goals, explorers."""
        return self._viewer.render()

    def close(self, **kwargs):
        self._viewer.close()
