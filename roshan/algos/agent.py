"""The one protocol every trained agent follows (PPO at both levels, TD3, IQL), so loops, evaluation and the
frozen low-level policies never ask which algorithm they hold."""

from typing import Protocol, runtime_checkable

import torch


@runtime_checkable
class Agent(Protocol):
    """What runs, evaluation and the planner's frozen FlyAgents call.

    Observations are dicts of batch-first tensors, one row per decision maker (FlyAgent: a drone; planner: an
    env). Algorithms with a likelihood also have ``evaluate``: PPO's (log-prob, entropy, value) of stored
    actions; IQL's is ``log_prob``.
    """

    # the state_dict entries a weights-only load (evaluation, fine-tuning) reads: the networks
    weight_keys: tuple[str, ...]

    def act(self, obs: dict[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """The actions the agent explores with while collecting: PPO samples its policy, TD3 adds Gaussian noise,
        IQL executes its noise-free action (as the reference does)."""
        ...

    def act_deterministic(self, obs: dict[str, torch.Tensor], cache=None) -> torch.Tensor:
        """The evaluation actions: the policy's mode (PPO), mu(s) (TD3), tanh(mu) (IQL). ``cache`` is a
        :meth:`new_cache` object kept by a caller that acts on the same rows step after step; it gives the same
        actions with less work (PPO's FlyAgent encodes only the newest frame), or is ignored."""
        ...

    def new_cache(self):
        """A fresh acting cache for :meth:`act_deterministic` (``clear()``, ``restart(rows)``)."""
        ...

    def state_dict(self) -> dict:
        """Everything needed to resume: networks, optimisers, schedules, counters."""
        ...

    def load_state_dict(self, state: dict, weights_only: bool = False) -> None:
        """Restore :meth:`state_dict`; ``weights_only`` restores the networks alone (evaluation, fine-tuning)."""
        ...
