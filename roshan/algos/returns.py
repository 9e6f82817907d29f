"""Generalised advantage estimation as a pure function (Schulman et al. 2016, arXiv:1506.02438)."""

import torch


def gae(rewards: torch.Tensor, values: torch.Tensor, next_values: torch.Tensor, terminations: torch.Tensor,
        truncations: torch.Tensor, gamma: float, lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Advantages and returns for a rollout, with terminations and truncations kept apart.

    Args:
        rewards: [T, B] rewards r_t.
        values: [T, B] V(s_t).
        next_values: [T, B] V(s'_t) of the true next state: the env's ``final_obs`` where the episode ended
            at t (same-step autoreset), else s_{t+1}; the last row bootstraps the rollout.
        terminations: [T, B] the episode ended in a terminal state at t: no value after it.
        truncations: [T, B] the episode was cut at t (time limit): bootstrap from V(s'_t), as SB3 does
            for timeouts (SB3 issue #633).
        gamma, lam: discount and GAE lambda.

    Returns:
        (advantages, returns), both [T, B]; returns = advantages + values.
    """
    not_terminal = 1.0 - terminations.float()
    not_done = 1.0 - torch.maximum(terminations.float(), truncations.float())  # the trace stops at any end
    deltas = rewards + gamma * not_terminal * next_values - values
    advantages = torch.zeros_like(rewards)
    running = torch.zeros_like(rewards[0])
    for t in range(rewards.shape[0] - 1, -1, -1):
        running = deltas[t] + gamma * lam * not_done[t] * running
        advantages[t] = running
    return advantages, advantages + values
