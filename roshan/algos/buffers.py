"""Replay buffer for TD3 and IQL: a ring of preallocated tensors on the learner device (docs/model/learning.md §5).

Rows are single transitions; envs x drones are flattened into the row axis, so one buffer holds every drone
of every env and uniform sampling over it is uniform over all drones' transitions (newest-code sampling).
"""

from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import torch

from roshan.io import atomic_file

FORMAT = "roshan-replay-v1"


class ReplayBatch(NamedTuple):
    """A minibatch of B transitions: obs / next_obs dicts of (B, ...) tensors, actions (B, 2), rewards (B,)
    raw, not_done (B,) = 1 - termination."""

    obs: dict[str, torch.Tensor]
    actions: torch.Tensor
    rewards: torch.Tensor
    not_done: torch.Tensor
    next_obs: dict[str, torch.Tensor]

    def to(self, device: str | torch.device) -> "ReplayBatch":
        """The batch on ``device`` (no copy for tensors already there), e.g. from a CPU buffer to the learner."""
        return ReplayBatch({k: v.to(device) for k, v in self.obs.items()}, self.actions.to(device),
                           self.rewards.to(device), self.not_done.to(device),
                           {k: v.to(device) for k, v in self.next_obs.items()})


class ReplayBuffer:
    """Circular buffer of ``capacity`` transitions, allocated once as float32 tensors on ``device``.

    ``obs_shapes`` maps each observation key to its per-row shape, e.g. ``{"agent": (3, 9), "neighbors":
    (3, K, 4), "neighbors_mask": (3, K)}``. Rewards are stored raw; scaling is the learner's business.
    ``not_done`` should be ``1 - terminated``: a truncated (timed-out) transition keeps bootstrapping from
    ``next_obs``, which must then be the env's final observation (SB3 issue #633).
    """

    def __init__(self, capacity: int, obs_shapes: dict[str, tuple[int, ...]], device: str | torch.device = "cpu",
                 action_dim: int = 2):
        if capacity < 1:
            raise ValueError(f"ReplayBuffer capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.device = torch.device(device)
        self.obs_shapes = {k: tuple(int(d) for d in s) for k, s in obs_shapes.items()}
        self.action_dim = action_dim

        def zeros(*shape):
            return torch.zeros((self.capacity, *shape), dtype=torch.float32, device=self.device)

        self.obs = {k: zeros(*s) for k, s in self.obs_shapes.items()}
        self.next_obs = {k: zeros(*s) for k, s in self.obs_shapes.items()}
        self.actions = zeros(action_dim)
        self.rewards = zeros()
        self.not_done = zeros()
        self.ptr = 0  # next row to write
        self.size = 0  # rows filled so far (<= capacity)

    def __len__(self) -> int:
        return self.size

    def add(self, obs: dict[str, torch.Tensor], actions: torch.Tensor, rewards: torch.Tensor,
            not_done: torch.Tensor, next_obs: dict[str, torch.Tensor]) -> None:
        """Append a batch of B transitions in one scatter (oldest rows are overwritten once full).

        Args:
            obs, next_obs: dicts of (B, *obs_shapes[key]) tensors.
            actions: (B, action_dim). rewards, not_done: (B,) raw reward and 1 - termination.
        """
        n = actions.shape[0]
        self._check(obs, n, "obs")
        self._check(next_obs, n, "next_obs")
        if tuple(actions.shape) != (n, self.action_dim) or rewards.numel() != n or not_done.numel() != n:
            raise ValueError(f"ReplayBuffer.add: expected actions ({n}, {self.action_dim}), rewards ({n},) and "
                             f"not_done ({n},); got {tuple(actions.shape)}, {tuple(rewards.shape)}, "
                             f"{tuple(not_done.shape)}")
        keep = min(n, self.capacity)  # a batch larger than the ring keeps only its newest rows
        rows = slice(n - keep, n)
        idx = (self.ptr + torch.arange(keep, device=self.device)) % self.capacity
        for k in self.obs:
            self.obs[k][idx] = obs[k][rows].to(self.device, torch.float32)
            self.next_obs[k][idx] = next_obs[k][rows].to(self.device, torch.float32)
        self.actions[idx] = actions[rows].to(self.device, torch.float32)
        self.rewards[idx] = rewards.reshape(n)[rows].to(self.device, torch.float32)
        self.not_done[idx] = not_done.reshape(n)[rows].to(self.device, torch.float32)
        self.ptr = (self.ptr + keep) % self.capacity
        self.size = min(self.size + keep, self.capacity)

    def _check(self, obs: dict[str, torch.Tensor], n: int, name: str) -> None:
        if set(obs) != set(self.obs_shapes):
            raise ValueError(f"ReplayBuffer.add: {name} keys {sorted(obs)} != buffer keys {sorted(self.obs_shapes)}")
        for k, shape in self.obs_shapes.items():
            if tuple(obs[k].shape) != (n, *shape):
                raise ValueError(f"ReplayBuffer.add: {name}[{k!r}] has shape {tuple(obs[k].shape)}, "
                                 f"expected {(n, *shape)}")

    def gather(self, idx: torch.Tensor) -> ReplayBatch:
        """The transitions at row indices ``idx`` (B,) as a ReplayBatch."""
        idx = idx.to(self.device)
        return ReplayBatch(obs={k: v[idx] for k, v in self.obs.items()}, actions=self.actions[idx],
                           rewards=self.rewards[idx], not_done=self.not_done[idx],
                           next_obs={k: v[idx] for k, v in self.next_obs.items()})

    def sample(self, batch_size: int, generator: torch.Generator | None = None) -> ReplayBatch:
        """``batch_size`` transitions drawn uniformly with replacement from all filled rows."""
        if self.size == 0:
            raise ValueError("ReplayBuffer.sample: the buffer is empty")
        device = generator.device if generator is not None else self.device
        return self.gather(torch.randint(0, self.size, (batch_size,), generator=generator, device=device))

    def iterate(self, batch_size: int, generator: torch.Generator | None = None) -> Iterator[ReplayBatch]:
        """One pass over every filled row in random order, in minibatches of ``batch_size`` (the last one may
        be smaller)."""
        device = generator.device if generator is not None else self.device
        order = torch.randperm(self.size, generator=generator, device=device)
        for start in range(0, self.size, batch_size):
            yield self.gather(order[start:start + batch_size])

    # ------------------------------------------------------------------------------------------ save / load

    def _chronological(self, t: torch.Tensor) -> torch.Tensor:
        """Filled rows oldest first (a full ring starts at ``ptr``), on the CPU."""
        if self.size < self.capacity:
            return t[:self.size].cpu()
        return torch.roll(t, -self.ptr, dims=0).cpu()

    def save(self, path: str | Path) -> None:
        """Write the filled rows (oldest first) to ``path`` atomically: a temporary file in the same directory
        is renamed over the target, so a crash never leaves a half-written buffer."""
        path = Path(path)
        state = {"format": FORMAT, "capacity": self.capacity, "action_dim": self.action_dim,
                 "obs_shapes": {k: list(s) for k, s in self.obs_shapes.items()},
                 "obs": {k: self._chronological(v) for k, v in self.obs.items()},
                 "next_obs": {k: self._chronological(v) for k, v in self.next_obs.items()},
                 "actions": self._chronological(self.actions), "rewards": self._chronological(self.rewards),
                 "not_done": self._chronological(self.not_done)}
        with atomic_file(path) as f:
            torch.save(state, f)

    @classmethod
    def load(cls, path: str | Path, device: str | torch.device = "cpu", capacity: int | None = None) -> "ReplayBuffer":
        """A buffer saved by :meth:`save`; ``capacity`` (default: the saved one) may be larger, e.g. to append
        online transitions to an offline dataset.

        Raises:
            ValueError: naming ``path`` if it is missing, unreadable, corrupt or not a replay buffer.
        """
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"{path}: replay buffer file not found")
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as exc:  # torch raises pickle, zip and runtime errors for damaged files
            raise ValueError(f"{path}: not a readable replay buffer ({type(exc).__name__}: {exc})") from exc
        if not isinstance(state, dict) or state.get("format") != FORMAT:
            raise ValueError(f"{path}: not a replay buffer saved by roshan (expected format {FORMAT!r})")
        try:
            size = state["actions"].shape[0]
            capacity = state["capacity"] if capacity is None else capacity
            if capacity < size:
                raise ValueError(f"holds {size} transitions, more than the requested capacity {capacity}")
            buf = cls(capacity, {k: tuple(s) for k, s in state["obs_shapes"].items()}, device, state["action_dim"])
            buf.add(state["obs"], state["actions"], state["rewards"], state["not_done"], state["next_obs"])
        except (KeyError, AttributeError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: damaged replay buffer ({type(exc).__name__}: {exc})") from exc
        return buf
