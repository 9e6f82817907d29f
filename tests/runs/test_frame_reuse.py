"""Frame reuse is exact: cached acting and sequence minibatches give the same network outputs as encoding every
stacked observation, on real rollouts of the collision env (episodes restart inside the rollout)."""

import pytest
import torch

from roshan.algos.agents import fly_ppo
from roshan.algos.frames import FrameCache, gather_stacks, stack_index
from roshan.config import Config, PPOConfig
from roshan.runs.collect import DroneRows, RolloutCollector
from roshan.runs.envs import make_env


def collision_run(num_envs=4, horizon=4 * 4 * 24, **ppo):
    cfg = Config()
    fly = cfg.fly.__class__(policy="complex", collision=True)
    ppo_cfg = PPOConfig(horizon=horizon, batch_size=horizon // 2, use_tanh_dist=True, share_encoder=False, **ppo)
    return cfg.__class__(fly=fly, ppo=ppo_cfg, sim=cfg.sim.__class__(envs=num_envs, seed=3))


def test_stack_index_by_hand():
    # T = 5, one column, F = 3, the episode restarts at t = 2.
    restart = torch.tensor([[False], [False], [True], [False], [False]])
    idx = stack_index(restart, 3)[:, 0].tolist()
    # distinct frames: 0 = obs[0] frame 2, 1 = obs[0] frame 1, 2 + t = obs[t] frame 0
    assert idx == [[2, 1, 0], [3, 2, 1], [4, 4, 4], [5, 4, 4], [6, 5, 4]]


def test_gather_stacks_picks_rows():
    distinct = torch.arange(4 * 2 * 1, dtype=torch.float32).view(4, 2, 1)  # L = 4, c = 2, D = 1
    index = torch.tensor([[[2, 1], [3, 3]], [[0, 0], [1, 2]]])  # T = 2, c = 2, F = 2
    out = gather_stacks(distinct, index)[..., 0]
    assert out.tolist() == [[[4.0, 2.0], [7.0, 7.0]], [[0.0, 0.0], [3.0, 5.0]]]


@pytest.mark.slow
def test_cached_acting_and_sequence_minibatches_match_full_encoding():
    torch.manual_seed(0)
    cfg = collision_run()
    env = make_env(cfg, cfg.sim.envs, seed=5)
    agent = fly_ppo(cfg.ppo, collision=True)
    collector = RolloutCollector(env, agent, DroneRows(env.num_drones), steps=24)
    rollout = collector.collect()
    ended = rollout.terminations | rollout.truncations
    assert bool(ended[:-1].any()), "the rollout should contain episode restarts"
    T, B = rollout.log_probs.shape
    with torch.no_grad():
        full = [agent.net({k: v[t] for k, v in rollout.obs.items()}) for t in range(T)]
        # acting with the cache gave the same values as a full forward pass
        values = torch.stack([f[2] for f in full])
        torch.testing.assert_close(rollout.values, values, rtol=1e-5, atol=1e-5)
        # the sequence path rebuilds every stack from distinct frames
        restart = torch.cat([torch.zeros_like(ended[:1]), ended[:-1]])
        cols = torch.tensor([0, 5, 9, B - 1])
        mean, _, value = agent.policy.forward_columns({k: v[:, cols] for k, v in rollout.obs.items()},
                                                      stack_index(restart, 3)[:, cols])
        want_mean = torch.stack([f[0][cols] for f in full]).flatten(0, 1)
        want_value = torch.stack([f[2][cols] for f in full]).flatten(0, 1)
        torch.testing.assert_close(mean, want_mean, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(value, want_value, rtol=1e-5, atol=1e-5)


def test_frame_cache_restarted_rows_use_the_new_frame_only():
    cfg = collision_run()
    agent = fly_ppo(cfg.ppo, collision=True)
    B, K = 3, 4
    obs = {"agent": torch.randn(B, 3, 9), "neighbors": torch.randn(B, 3, K, 4),
           "neighbors_mask": torch.ones(B, 3, K)}
    cache = FrameCache()
    cache.encode(agent.net, obs)
    fresh = {"agent": obs["agent"][:, :1].expand(B, 3, 9).clone(),
             "neighbors": obs["neighbors"][:, :1].expand(B, 3, K, 4).clone(),
             "neighbors_mask": torch.ones(B, 3, K)}
    with torch.no_grad():
        cache.restart(torch.tensor([True, True, True]))
        za, _ = cache.encode(agent.net, fresh)
        want, _ = agent.net.encode_frames(fresh)
    torch.testing.assert_close(za, want)
