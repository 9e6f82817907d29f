"""The vector-env core every level shares: the map and simulators, the torch buffers the kernels write, the
reset / step skeleton with Gymnasium's same-step autoreset, the action checks, rendering and close.

A level (:class:`roshan.env.fly.FlyVectorEnv`, :class:`roshan.env.planner.PlannerVectorEnv`) is a thin layer
on :class:`VectorEnvCore`: its spaces, the views that make its observation dict out of one buffer, and the
body of one step (:meth:`VectorEnvCore._advance`). Its kernels derive from
:class:`roshan.kernels.episode.EpisodeKernels`, whose restart kernel the core launches.

Callers tell the levels apart by what they need to know, not by type: :attr:`VectorEnvCore.flat_drones` says
how actions are shaped, :attr:`VectorEnvCore.failure_reasons` which failures the records can hold.
"""

import warnings
from collections.abc import Callable

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from roshan.config import Config
from roshan.episode import RECORD_FIELDS, RECORD_INFO, Column
from roshan.kernels.pool import FlySims, PlannerSims
from roshan.maps import LandCoverMap, check_drone_map, load_map
from roshan.runtime import check_built_in_this_runtime, ensure_taichi, taichi_generation, torch_device

CLOSED = -1  # the runtime generation of a closed env: never Taichi's, so step's one comparison catches it


class VectorEnvCore(gym.vector.VectorEnv):
    """E environments of one level as one Gymnasium vector env whose tensors are shared with torch.

    Every call returns the same tensor objects: observation views into one buffer, rewards, terminations and
    truncations (E,) (a time-out truncates). ``info`` holds ``final_obs`` (the observation of envs that ended
    this step, same layout), the episode record as dicts of (E,) tensors (:data:`roshan.episode.RECORD_INFO`:
    ``episode_stats``, ``episode_fire`` (the fire at the episode's end) and the extra columns the drones count,
    zero where they count none, :attr:`extra_columns`) and ``_episode_stats`` (the (E,) bool mask of envs whose
    episode ended).

    A subclass defines :meth:`_take_simulators` (its bundle from :mod:`roshan.kernels.pool`), calls
    :meth:`_allocate_buffers`, and defines :meth:`_views`, :meth:`_kernel_obs` and :meth:`_advance`.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}
    # True: actions are one (E, N, 2) velocity per drone and a policy sees the drones as one batch of E * N
    # (roshan.algos.networks.flatten_drones); False: actions are one decision per env, (E, N) indices.
    flat_drones = True
    level_failures = ("collision", "boundary", "timeout")  # the failures an episode record of the level can hold
    default_caption_name = "FlyAgent"  # who flies, in the caption of rendered frames (caption_name)
    has_reward = True  # False where the controller earns no reward (the greedy heuristic): reports leave it out
    # True where the drones' objective is putting fires out (complex FlyAgent, planner, heuristic): such an env
    # refuses a map where no fire can start, and its episodes succeed only once a fire was lit and put out.
    fights_fire = True

    def __init__(self, num_envs: int, config: Config | None, seed: int | None, render_mode: str | None):
        ensure_taichi()
        # step/reset/render refuse to run on a reset runtime, or after close() (which sets it to CLOSED)
        self._taichi_generation = taichi_generation()
        self.config = cfg = config or Config()
        self.render_mode = render_mode
        self.num_envs = num_envs
        self.num_drones = cfg.drones.num_drones
        self.device = torch.device(torch_device())
        self.land = load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows,
                             cols=cfg.map.uniform_cols)
        self._check_map()
        # The simulators of an earlier, closed env of the same build when there is one: no new fields, no compiling.
        sims, self._give_back_sims = self._take_simulators(self.land, cfg.sim.seed if seed is None else seed)
        self.fire, self.drones, self.kernels, self._viewer = sims.fire, sims.drones, sims.kernels, sims.viewer
        self.t_max = sims.t_max
        self._has_reset = False
        # Frames: the caption's controller name, and env 0's last frame of an episode (with a render_mode).
        self.caption_name = self.default_caption_name
        self.final_frame: np.ndarray | None = None

    # ------------------------------------------------------------------------------------------ construction

    def _take_simulators(self, land: LandCoverMap, seed: int) -> tuple[FlySims | PlannerSims, Callable[[], None]]:
        """The level's simulator bundle (fire, drone groups, task kernels, renderer) and the call that gives it
        back to the pool: the one place simulators are made (roshan.kernels.pool builds or reuses them)."""
        raise NotImplementedError

    def level_name(self) -> str:
        """The env as messages name it (``FlyVectorEnv (complex policy)``)."""
        return type(self).__name__

    def _check_map(self) -> None:
        """Refuse a map too small for drones, or one where no fire can start when fires are the objective
        (MapError); warn where no fire is lit at a reset on purpose (``ignition.fire_percentage = 0``)."""
        pct = self.config.ignition.fire_percentage
        check_drone_map(self.land, pct, self.fights_fire, self.level_name(), self.config.drones.bases)
        if self.fights_fire and pct == 0:
            warnings.warn(f"{self.level_name()}: ignition.fire_percentage = 0 lights no fire at a reset; an episode "
                          "whose fires are not lit by hand (FireSim.ignite_cells) runs until its time limit and "
                          "never counts as a success", stacklevel=4)
        for line in self.config.drones.inert():  # the same text warns once (Python's default filter)
            warnings.warn(f"{self.level_name()}: {line}", stacklevel=4)

    @property
    def physics_steps_per_step(self) -> int:
        """Physics steps one :meth:`step` runs: the FlyAgent's ``frame_skips``, the planner's ``interval``."""
        raise NotImplementedError

    @property
    def failure_reasons(self) -> tuple[str, ...]:
        """The failures an episode record can hold: the level's and the drones'
        (:attr:`roshan.config.sim.DroneConfig.failures`)."""
        return self.level_failures + self.config.drones.failures

    @property
    def extra_columns(self) -> tuple[Column, ...]:
        """The record's extra columns this env's drones count
        (:attr:`roshan.config.sim.DroneConfig.counted_columns`)."""
        return self.config.drones.counted_columns

    @property
    def max_env_steps(self) -> int:
        """The most :meth:`step` calls an episode may last (:attr:`t_max` counts physics steps)."""
        return max(1, -(-self.t_max // self.physics_steps_per_step))

    def _buffer_bytes(self) -> int:
        """Bytes of the torch buffers the level allocates next to its simulators (the memory estimate counts
        them before anything is allocated)."""
        raise NotImplementedError

    def _core_buffer_bytes(self, obs_floats: int, reward_floats: int) -> int:
        """Bytes :meth:`_allocate_buffers` takes for observations of ``obs_floats`` floats per env (twice: the
        final copy) and rewards of ``reward_floats``."""
        return self.num_envs * (8 * obs_floats + 4 * reward_floats + 2 + 4 * len(RECORD_FIELDS))

    def _allocate_buffers(self, obs_shape: tuple[int, ...], reward_shape: tuple[int, ...]) -> None:
        """The tensors the kernels write: observations (E, *obs_shape) and their final copy, rewards
        (E, *reward_shape), done flags, episode records; the views and info dict handed out."""
        E, dev = self.num_envs, self.device
        self._obs_buf = torch.zeros((E, *obs_shape), dtype=torch.float32, device=dev)
        self._final_buf = torch.zeros_like(self._obs_buf)
        self._rewards = torch.zeros((E, *reward_shape), dtype=torch.float32, device=dev)
        self._dones = torch.zeros((E, 2), dtype=torch.uint8, device=dev)
        self._dones_host = self._dones.numpy() if dev.type == "cpu" else None  # the same memory, read by numpy
        self._episode = torch.zeros((E, len(RECORD_FIELDS)), dtype=torch.float32, device=dev)
        self._obs = self._views(self._obs_buf)
        done_bool = self._dones.view(torch.bool)
        self.terminations, self.truncations = done_bool[:, 0], done_bool[:, 1]
        self._info = {"final_obs": self._views(self._final_buf),
                      **{key: {k: self._episode[:, RECORD_FIELDS.index(k)] for k in fields}
                         for key, fields in RECORD_INFO.items()}}

    def _batched_spaces(self) -> None:
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)

    # ------------------------------------------------------------------------------------------ the level

    def _views(self, buf: torch.Tensor) -> dict[str, torch.Tensor]:
        """The observation dict: views of ``buf`` (the observation buffer or its final copy)."""
        raise NotImplementedError

    def _kernel_obs(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """What the restart kernel writes: observation rows (E, W), their final copy (E, W), the FlyAgent frame
        stacks of the drones and of the explorers."""
        raise NotImplementedError

    def _advance(self, actions) -> None:
        """One step of every env: check ``actions``, run the level's kernels (rewards, dones, records)."""
        raise NotImplementedError

    # ------------------------------------------------------------------------------------------ gymnasium

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start new episodes in every env; ``seed`` restarts every random stream from that seed."""
        self._check_runtime("reset()")
        super().reset(seed=seed)
        if seed is not None:
            self.fire.restart_streams(seed)
        self.kernels.reset_all(*self._kernel_obs(), self.fire.seed_key)
        self._episode.zero_()
        self._dones.zero_()
        self._has_reset = True
        return self._obs, {}

    @torch.no_grad()
    def step(self, actions):
        """Advance every env by one step; envs that end are reset in the same call."""
        if self._taichi_generation != taichi_generation():  # inline test: this is the hot path (closed envs too)
            self._check_runtime("step()")
        if not self._has_reset:
            raise gym.error.ResetNeeded(f"{type(self).__name__}.step() before reset(): call reset() first")
        self._advance(actions)
        if self.render_mode is not None:  # frames only (a host read): env 0's final state, before the autoreset
            self.final_frame = self.render() if bool(self._dones[0].any()) else None
        # On the CPU, reading the done flags costs a microsecond (numpy's view; torch's any() costs ~10) and saves
        # the reset launch (~150 us) in the many steps where no episode ends; on a GPU that read would
        # synchronise, so always launch.
        if self._dones_host is None or self._dones_host.any():
            self.kernels.restart(*self._kernel_obs(), self.fire.seed_key, 1)
        info = dict(self._info)
        info["_episode_stats"] = self.terminations | self.truncations
        info["_final_obs"] = info["_episode_stats"]
        return self._obs, self._rewards, self.terminations, self.truncations, info

    def _check_runtime(self, call: str) -> None:
        if self._taichi_generation == CLOSED:  # its simulators went back to the pool and may be another env's now
            raise gym.error.ClosedEnvironmentError(
                f"{type(self).__name__}.{call}: this env was closed (its simulators may belong to another env "
                "now); build a new one")
        check_built_in_this_runtime(self._taichi_generation, f"{type(self).__name__}.{call}: this env")

    def _actions_tensor(self, actions, want: tuple[int, ...], axes: str) -> torch.Tensor:
        """``actions`` (torch, numpy or nested lists) as a tensor of shape ``want`` (its axes named in errors)."""
        if isinstance(actions, np.ndarray):
            actions = torch.from_numpy(actions)
        elif not isinstance(actions, torch.Tensor):
            actions = torch.as_tensor(np.asarray(actions))
        if tuple(actions.shape) != want:
            raise ValueError(f"actions: expected shape {want} ({axes}), got {tuple(actions.shape)}")
        return actions

    def render(self):
        """An RGB frame (H, W, 3) uint8 of env 0: land cover, fire, particles, drones, goals, groundstation (the
        planner adds its explorers and dims the fires no drone has seen), with a caption band above the map
        (:meth:`caption`) and a legend band below it.

        Rendering happens after the same-step autoreset, so on a step where env 0's episode ended this shows the
        next episode's first state. An env built with ``render_mode="rgb_array"`` has :meth:`step` render env 0's
        final state into :attr:`final_frame` before it resets (None on steps where env 0 did not end).
        """
        self._check_runtime("render()")
        return self._viewer.render(self.caption())

    def caption(self) -> str:
        """Env 0's caption: who flies, the episode number (1 for env 0's first episode since the env was reset
        with a seed: the ``Episode`` of that episode in an evaluation's episodes.csv), physics steps and simulated
        time since the reset, and the cells burning now."""
        steps = int(self.kernels.steps[0])
        burning = int(self.fire.stats()["burning"][0])
        return (f"{self.caption_name} | episode {int(self.fire.episode[0]) + 1} | step {steps} | "
                f"t = {steps * self.config.fire.dt:.1f} s | fires left {burning}")

    def close(self, **kwargs):
        """Give the simulators back to the pool (idempotent); step, reset and render raise
        ``gymnasium.error.ClosedEnvironmentError`` afterwards."""
        self._taichi_generation = CLOSED
        self.closed = True
        self._viewer.close()
        self._give_back_sims()
