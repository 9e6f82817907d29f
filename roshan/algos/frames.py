"""Frame reuse for stacked FlyAgent observations: the env pushes one frame per step, so consecutive stacks share
all but their newest frame. Acting encodes only the newest frame (:class:`FrameCache`), and the ``sequences``
minibatches encode each distinct frame of a drone's rollout once (:func:`stack_index`, :func:`gather_stacks`).
A policy without frame stacks keeps a :class:`NoCache`."""

import torch

from roshan.algos.networks import ActorCritic


def stack_index(restart: torch.Tensor, frames: int) -> torch.Tensor:
    """Where frame j of the stack at step t comes from, for drone columns of a rollout.

    The env pushes one frame per step and fills the whole stack with copies of the first frame of an episode,
    so frame j of obs[t] is frame 0 of obs[max(t - j, s)], s = the step the episode (re)started in this
    rollout; steps before the rollout are frames of obs[0]. Distinct frames are numbered F-1+t for frame 0 of
    obs[t] and F-1-j for frame j of obs[0].

    Args:
        restart: [T, B] bool, obs[t] is the first observation of an episode.
        frames: F, the stack depth.

    Returns:
        [T, B, F] long indices into the [T + F - 1] distinct frames of each column.
    """
    T = restart.shape[0]
    t = torch.arange(T, device=restart.device).unsqueeze(1).expand_as(restart)
    start = torch.where(restart, t, torch.full_like(t, -T - frames)).cummax(dim=0).values
    j = torch.arange(frames, device=restart.device)
    return frames - 1 + torch.maximum(t.unsqueeze(-1) - j, start.unsqueeze(-1))


def gather_stacks(distinct: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Stacks [T, c, F, D] from distinct frame embeddings [L, c, D] and :func:`stack_index` [T, c, F]."""
    L, c, D = distinct.shape
    T, _, F = index.shape
    idx = index.permute(1, 0, 2).reshape(c, T * F, 1).expand(c, T * F, D)
    return distinct.transpose(0, 1).gather(1, idx).view(c, T, F, D).transpose(0, 1)


class NoCache:
    """The acting cache of a policy without frame stacks: nothing to keep between steps."""

    def clear(self) -> None:
        pass

    def restart(self, rows: torch.Tensor) -> None:
        pass


class FrameCache:
    """Per-frame embeddings of the previous step's stacks, so acting encodes only the newest frame.

    Valid only while the parameters do not change: :meth:`clear` it after every update. Rows whose episode
    restarted since the previous :meth:`encode` must be marked with :meth:`restart`: their stack holds copies of
    one frame, not the previous stack shifted.
    """

    def __init__(self):
        self.za: torch.Tensor | None = None
        self.zc: torch.Tensor | None = None
        self.restarted: torch.Tensor | None = None

    def clear(self) -> None:
        self.za = self.zc = self.restarted = None

    def restart(self, rows: torch.Tensor) -> None:
        """Mark rows (B,) bool whose episode restarted since the previous :meth:`encode`."""
        self.restarted = rows

    def encode(self, net: ActorCritic, obs: dict[str, torch.Tensor]):
        """The per-frame embeddings (actor's, critic's or None) of ``obs``'s stacks."""
        restarted, self.restarted = self.restarted, None
        if self.za is None:
            self.za, self.zc = net.encode_frames(obs)
            return self.za, self.zc
        na, nc = net.encode_frames({k: v[:, :1] for k, v in obs.items()})
        self.za = self._shift(self.za, na, restarted)
        self.zc = None if nc is None else self._shift(self.zc, nc, restarted)
        return self.za, self.zc

    @staticmethod
    def _shift(old: torch.Tensor, new: torch.Tensor, restarted: torch.Tensor | None) -> torch.Tensor:
        z = torch.cat([new, old[:, :-1]], dim=1)
        if restarted is not None:  # a restarted episode's stack is copies of its first frame
            z = torch.where(restarted[:, None, None], new.expand_as(z), z)
        return z
