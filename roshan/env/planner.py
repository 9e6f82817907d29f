"""PlannerAgent vector environment (docs/model/agents.md §13): one decision assigns every planner drone a goal among the
known fires and the groundstation; frozen FlyAgent policies then fly the drones (and the explorers) for
``interval`` low-level steps inside the batched kernels of :mod:`roshan.kernels.planner`.

The same class runs the greedy heuristic baseline (docs/model/agents.md §10.2) with ``controller="greedy"``: it ignores
the actions, and since fire layouts and wind depend only on the env seed and the episode count, a planner and
the heuristic evaluated with the same seed and number of envs play identical initial episodes.
"""

import warnings

import gymnasium as gym
import numpy as np
import torch

from roshan.algos.frozen import FrozenFlyPolicy
from roshan.config import CONTROLLERS, Config, PlannerConfig
from roshan.env.base import VectorEnvCore
from roshan.env.fly import fly_obs_views
from roshan.kernels import observe
from roshan.kernels.launch import PreparedLaunch
from roshan.kernels.planner import candidate_count, obs_layout, obs_parts
from roshan.kernels.pool import take_planner_sims
from roshan.maps import check_explorer_map
from roshan.runtime import ensure_taichi, torch_device


class PlannerVectorEnv(VectorEnvCore):
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
        planner: the planner level (default: ``config.planner``).
        evaluation: explorers move and the candidates come from ``planner.eval_fires`` (else training:
            explorers wait at the groundstation, candidates from ``planner.train_fires``).
        controller: ``"planner"`` (goals from the actions) or ``"greedy"`` (the heuristic; actions ignored).
        seed: env seed (default ``config.sim.seed``).
        fly_policy, explorer_policy: preloaded frozen policies (default: load ``planner.fly_model`` /
            ``planner.explorer_model``).
    """

    flat_drones = False  # one decision per env: (E, N) candidate indices
    # The frozen FlyAgents fly the drones and the planner's records end only by timeout or burnout
    # (kernels/planner.py): no collision or boundary rows in its reports.
    level_failures = ("timeout", "burnout")

    def __init__(self, num_envs: int = 1, config: Config | None = None, planner: PlannerConfig | None = None,
                 evaluation: bool = False, controller: str = "planner", seed: int | None = None,
                 fly_policy: FrozenFlyPolicy | None = None, explorer_policy: FrozenFlyPolicy | None = None,
                 render_mode: str | None = None):
        if controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {', '.join(CONTROLLERS)}, got {controller!r}")
        self.planner_config = pc = planner or (config.planner if config is not None else PlannerConfig())
        self.controller, self.evaluation = controller, evaluation
        self.default_caption_name = controller
        self.has_reward = controller != "greedy"  # the heuristic's episodes return 0: no reward is computed
        ensure_taichi()  # the frozen policies act on the simulator's torch device
        self.fly_policy = fly_policy or FrozenFlyPolicy(pc.fly_model, torch_device())
        self.explorer_policy = None
        if evaluation or controller == "greedy":  # in planner training the explorers wait at the groundstation
            self.explorer_policy = explorer_policy or FrozenFlyPolicy(pc.explorer_model, torch_device(),
                                                                      key="planner.explorer_model")
        ex_frames = self.explorer_policy.frames if self.explorer_policy else 1
        super().__init__(num_envs, config, seed, render_mode)
        for line in pc.inert(self.config.drones):  # the same text warns once (Python's default filter)
            warnings.warn(f"{self.level_name()}: {line}", stacklevel=2)
        n, m = self.num_drones, pc.num_explorers
        self.interval = pc.interval
        self._define_spaces(n)
        self.layout = obs_layout(self.config.drones, self.max_candidates)
        self._allocate_buffers((max(end for _, end in self.layout.values()),), ())
        dev = self.device
        self._fly_buf = torch.zeros((num_envs, n, self.fly_policy.frames, observe.frame_width(n)), device=dev)
        self._explore_buf = torch.zeros((num_envs, m, ex_frames, observe.frame_width(m)), device=dev)
        self._fly_obs = fly_obs_views(self._fly_buf, n)
        self._explore_obs = fly_obs_views(self._explore_buf, m)
        self._explore_actions = torch.zeros((num_envs, m, 2), device=dev)
        self._fly_actions = torch.zeros((num_envs, n, 2), device=dev)
        # the frozen policies' frame caches: each low-level step pushes one frame, so only the newest is encoded
        self._fly_cache = self.fly_policy.new_cache()
        self._explore_cache = self.explorer_policy.new_cache() if self.explorer_policy else None
        self._prepare_launches()

    def _check_map(self) -> None:
        """The drones' checks of every level, and a map side the explorers' stripes can share."""
        super()._check_map()
        check_explorer_map(self.land, self.planner_config.num_explorers)

    def level_name(self) -> str:
        return f"PlannerVectorEnv ({self.controller})"

    @property
    def physics_steps_per_step(self) -> int:
        return self.interval  # low-level steps per decision, one physics step each

    def _take_simulators(self, land, seed):
        explore_frames = self.explorer_policy.frames if self.explorer_policy else 1
        sims, give_back = take_planner_sims(
            land, self.config, self.planner_config, self.num_envs, seed, controller=self.controller,
            evaluation=self.evaluation, fly_frames=self.fly_policy.frames, explore_frames=explore_frames, owner=self,
            extra_bytes=self._buffer_bytes(), who=self.level_name())
        self.explorers, self.maps, self.max_candidates = sims.explorers, sims.maps, sims.max_candidates
        return sims, give_back

    def _buffer_bytes(self) -> int:
        n, pc = self.num_drones, self.planner_config
        m, k = pc.num_explorers, candidate_count(pc, self.config.drones, self.land.rows * self.land.cols)
        ex_frames = self.explorer_policy.frames if self.explorer_policy else 1
        width = max(end for _, end in obs_layout(self.config.drones, k).values())
        stacks = n * self.fly_policy.frames * observe.frame_width(n) + m * ex_frames * observe.frame_width(m)
        return self._core_buffer_bytes(width, 1) + self.num_envs * 4 * (stacks + 2 * m + 2 * n)  # + actions

    def _define_spaces(self, n: int) -> None:
        parts = obs_parts(self.config.drones, self.max_candidates)
        self.single_observation_space = gym.spaces.Dict({
            name: gym.spaces.Box(low, high, shape, np.float32) for name, (shape, low, high) in parts.items()})
        self.single_action_space = gym.spaces.MultiDiscrete(np.full(n, self.max_candidates))
        self._batched_spaces()

    def _views(self, buf: torch.Tensor) -> dict[str, torch.Tensor]:
        shapes = {name: shape for name, (shape, _, _) in obs_parts(self.config.drones, self.max_candidates).items()}
        return {name: buf[:, a:b].unflatten(1, shapes[name]) for name, (a, b) in self.layout.items()}

    def _kernel_obs(self):
        return self._obs_buf, self._final_buf, self._fly_buf, self._explore_buf

    def _prepare_launches(self) -> None:
        """The per-step kernels over the env's own buffers, set up once (roshan.kernels.launch); the frozen
        policies' actions are copied into ``_fly_actions`` / ``_explore_actions`` before each low-level step."""
        k = self.kernels
        self._launch_begin = PreparedLaunch(k.begin, self._rewards, self._dones)
        self._launch_low_step = PreparedLaunch(k.low_step, self._fly_actions, self._explore_actions, self._fly_buf,
                                               self._explore_buf, self._rewards, self._dones, self._episode)
        self._launch_finish = PreparedLaunch(k.finish, self._obs_buf, self._rewards, self._dones, self._episode)

    def _advance(self, actions) -> None:
        """One planner decision: set the goals, fly ``interval`` low-level steps, reward, observe."""
        self._launch_begin()
        if self.controller == "planner":
            self.kernels.apply(self._check_actions(actions))
        for _ in range(self.interval):
            self._fly_actions.copy_(self.fly_policy(self._fly_obs, self._fly_cache))
            if self.explorer_policy is not None:
                self._explore_actions.copy_(self.explorer_policy(self._explore_obs, self._explore_cache))
            self._launch_low_step()
        self._launch_finish()

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Every env restarts, and with it every frame stack."""
        out = super().reset(seed=seed, options=options)
        for cache in (self._fly_cache, self._explore_cache):
            if cache is not None:
                cache.clear()
        return out

    def step(self, actions):
        """One planner decision; the envs that ended restarted their drones' frame stacks (an env that ended
        between low-level steps froze its stacks for the rest of the decision, so its cached frames are stale
        too: both are re-encoded from the fresh stacks)."""
        out = super().step(actions)
        if self._dones_host is not None and not self._dones_host.any():
            return out  # nothing restarted (the host read as in the base's step)
        ended = self.terminations | self.truncations
        for cache, group in ((self._fly_cache, self.num_drones),
                             (self._explore_cache, self.planner_config.num_explorers)):
            if cache is not None:
                cache.restart(ended.repeat_interleave(group))
        return out

    def _check_actions(self, actions) -> torch.Tensor:
        actions = self._actions_tensor(actions, (self.num_envs, self.num_drones), "envs, drones")
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
