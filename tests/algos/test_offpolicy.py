"""Off-policy learning: replay buffer, TD3 targets and losses, IQL losses, RND, and agent checkpoints.

Hand-worked numbers are written next to each assertion (Brax ``losses_test.py`` style).
"""

import math

import pytest
import torch

from roshan.algos.buffers import ReplayBuffer
from roshan.algos.iql import IQL, awr_weights, expectile_loss, iql_q_loss
from roshan.algos.networks import DeterministicActor, TwinQ, ValueNet
from roshan.algos.normalize import RewardScaler
from roshan.algos.rnd import RND
from roshan.algos.td3 import TD3, critic_mse, smooth_target_actions, td3_target
from roshan.config import IQLConfig, RNDConfig, TD3Config

K = 3  # neighbour slots
SHAPES = {"agent": (3, 9), "neighbors": (3, K, 4), "neighbors_mask": (3, K)}


def random_obs(n: int, g: torch.Generator) -> dict[str, torch.Tensor]:
    return {"agent": torch.randn(n, 3, 9, generator=g), "neighbors": torch.randn(n, 3, K, 4, generator=g),
            "neighbors_mask": (torch.rand(n, 3, K, generator=g) > 0.3).float()}


def random_buffer(n: int = 96, capacity: int = 128, seed: int = 0) -> ReplayBuffer:
    g = torch.Generator().manual_seed(seed)
    buf = ReplayBuffer(capacity, SHAPES)
    buf.add(random_obs(n, g), torch.rand(n, 2, generator=g) * 2 - 1, torch.randn(n, generator=g),
            (torch.rand(n, generator=g) > 0.1).float(), random_obs(n, g))
    return buf


def tagged_rows(values: list[float]) -> tuple:
    """Transitions whose every field is filled with the row's tag value, so rows can be identified anywhere."""
    v = torch.tensor(values)
    n = len(values)
    obs = {k: v.view(n, *([1] * len(s))).expand(n, *s).clone() for k, s in SHAPES.items()}
    next_obs = {k: t + 0.5 for k, t in obs.items()}
    return obs, v.view(n, 1).expand(n, 2).clone(), v.clone(), torch.ones(n), next_obs


def params(net: torch.nn.Module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in net.parameters()]


def same(a: list[torch.Tensor], b: list[torch.Tensor]) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


# ---------------------------------------------------------------------------------------------- replay buffer


def test_buffer_ring_wraps_around_and_overwrites_the_oldest():
    buf = ReplayBuffer(5, SHAPES)
    buf.add(*tagged_rows([0.0, 1.0, 2.0]))
    assert len(buf) == 3 and buf.ptr == 3
    buf.add(*tagged_rows([3.0, 4.0, 5.0, 6.0]))  # rows 3, 4, then 5 and 6 wrap onto rows 0 and 1
    assert len(buf) == 5 and buf.ptr == 2
    assert buf.rewards.tolist() == [5.0, 6.0, 2.0, 3.0, 4.0]
    assert buf.actions[:, 1].tolist() == [5.0, 6.0, 2.0, 3.0, 4.0]
    assert buf.obs["neighbors"][:, 2, 1, 3].tolist() == [5.0, 6.0, 2.0, 3.0, 4.0]
    assert buf.next_obs["agent"][:, 0, 0].tolist() == [5.5, 6.5, 2.5, 3.5, 4.5]
    buf.add(*tagged_rows([10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0]))  # larger than the ring: newest 5 kept
    assert sorted(buf.rewards.tolist()) == [12.0, 13.0, 14.0, 15.0, 16.0] and buf.ptr == 2


def test_buffer_rejects_wrong_shapes():
    buf = ReplayBuffer(5, SHAPES)
    obs, actions, rewards, not_done, next_obs = tagged_rows([1.0, 2.0])
    with pytest.raises(ValueError, match="neighbors"):
        buf.add({**obs, "neighbors": obs["neighbors"][:, :, :2]}, actions, rewards, not_done, next_obs)
    with pytest.raises(ValueError, match="actions"):
        buf.add(obs, actions[:, :1], rewards, not_done, next_obs)


def test_sampling_is_uniform_over_the_filled_rows_only():
    buf = ReplayBuffer(10, SHAPES)
    buf.add(*tagged_rows([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]))  # rows 7..9 stay empty (reward 0)
    g = torch.Generator().manual_seed(0)
    draws = torch.cat([buf.sample(100, g).rewards for _ in range(70)])  # 7000 draws, expect 1000 per row
    counts = torch.bincount(draws.long(), minlength=8)
    assert counts[0] == 0  # never an unfilled row
    assert (counts[1:] > 850).all() and (counts[1:] < 1150).all()  # +-15 %: about 5 standard deviations
    batch = buf.sample(4, g)
    torch.testing.assert_close(batch.next_obs["agent"][:, 0, 0], batch.rewards + 0.5)  # fields stay aligned
    assert batch.actions.shape == (4, 2) and batch.obs["neighbors_mask"].shape == (4, 3, K)


def test_iterate_visits_every_row_once_in_shuffled_order():
    buf = ReplayBuffer(10, SHAPES)
    buf.add(*tagged_rows([float(i) for i in range(7)]))
    batches = list(buf.iterate(3, torch.Generator().manual_seed(1)))
    assert [len(b.rewards) for b in batches] == [3, 3, 1]
    seen = torch.cat([b.rewards for b in batches])
    assert sorted(seen.tolist()) == list(range(7)) and seen.tolist() != list(range(7))


def test_save_load_round_trip_keeps_chronological_order(tmp_path):
    buf = ReplayBuffer(4, SHAPES)
    buf.add(*tagged_rows([0.0, 1.0, 2.0, 3.0, 4.0, 5.0]))  # ring holds [4, 5, 2, 3], oldest = 2
    path = tmp_path / "memory.pt"
    buf.save(path)
    assert [p.name for p in tmp_path.iterdir()] == ["memory.pt"]  # the temporary file was renamed away
    loaded = ReplayBuffer.load(path)
    assert len(loaded) == 4 and loaded.capacity == 4 and loaded.ptr == 0
    assert loaded.rewards.tolist() == [2.0, 3.0, 4.0, 5.0]
    for k in SHAPES:
        torch.testing.assert_close(loaded.obs[k], torch.roll(buf.obs[k], -buf.ptr, 0), rtol=0, atol=0)
        torch.testing.assert_close(loaded.next_obs[k], torch.roll(buf.next_obs[k], -buf.ptr, 0), rtol=0, atol=0)
    loaded.add(*tagged_rows([6.0]))  # the next write replaces the oldest row
    assert loaded.rewards.tolist() == [6.0, 3.0, 4.0, 5.0]
    bigger = ReplayBuffer.load(path, capacity=10)
    assert len(bigger) == 4 and bigger.ptr == 4 and bigger.rewards[:4].tolist() == [2.0, 3.0, 4.0, 5.0]


def test_load_names_the_file_when_missing_corrupt_or_foreign(tmp_path):
    with pytest.raises(ValueError, match="nope.pt.*not found"):
        ReplayBuffer.load(tmp_path / "nope.pt")
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(b"\x80\x02 this is not a torch file")
    with pytest.raises(ValueError, match="corrupt.pt"):
        ReplayBuffer.load(corrupt)
    foreign = tmp_path / "weights.pt"
    torch.save({"actor": torch.zeros(3)}, foreign)
    with pytest.raises(ValueError, match="weights.pt.*not a replay buffer"):
        ReplayBuffer.load(foreign)
    truncated = tmp_path / "truncated.pt"
    random_buffer(8, 8).save(truncated)
    truncated.write_bytes(truncated.read_bytes()[:200])
    with pytest.raises(ValueError, match="truncated.pt"):
        ReplayBuffer.load(truncated)


# ---------------------------------------------------------------------------------------------- networks


def test_offpolicy_heads_shapes_and_encoder_sharing():
    g = torch.Generator().manual_seed(0)
    obs = random_obs(5, g)
    actor = DeterministicActor(collision=True)
    a = actor(obs)
    assert a.shape == (5, 2) and a.abs().max() < 1.0
    w = actor.net[-1].weight.detach()  # (2, 300), orthogonal rows scaled by the policy gain 0.1
    torch.testing.assert_close(w @ w.T, 0.01 * torch.eye(2), atol=1e-6, rtol=0)
    shared = TwinQ(collision=True, encoder=actor.encoder)
    own = TwinQ(collision=True)
    assert shared.encoder1 is actor.encoder and shared.encoder2 is actor.encoder
    assert own.encoder1 is not own.encoder2
    n_enc = sum(p.numel() for p in actor.encoder.parameters())
    # the shared encoder is registered (once) inside `shared` too, so `own` has exactly one more encoder
    assert sum(p.numel() for p in own.parameters()) - sum(p.numel() for p in shared.parameters()) == n_enc
    q1, q2 = shared(obs, a)
    assert q1.shape == q2.shape == (5,) and not torch.equal(q1, q2)
    torch.testing.assert_close(shared.q1_value(obs, a), q1)
    assert ValueNet(collision=False)(obs).shape == (5,)


# ---------------------------------------------------------------------------------------------- TD3


def test_target_smoothing_clips_noise_then_action():
    mu_next = torch.tensor([[0.9, -0.2], [0.0, -0.95]])
    noise = torch.tensor([[0.7, 0.1], [-2.0, 0.3]])
    # noise clipped to +-0.5: [[0.5, 0.1], [-0.5, 0.3]]; 0.9 + 0.5 = 1.4 is clipped to the action bound 1
    expected = torch.tensor([[1.0, -0.1], [-0.5, -0.65]])
    torch.testing.assert_close(smooth_target_actions(mu_next, noise, 0.5), expected)


def test_clipped_double_q_target():
    rewards = torch.tensor([1.0, -0.5, 2.0])
    not_done = torch.tensor([1.0, 0.0, 1.0])
    q1 = torch.tensor([3.0, 10.0, -1.0])
    q2 = torch.tensor([2.0, -4.0, 0.5])
    # 1 + 0.9 * min(3, 2) = 2.8; terminal: -0.5; 2 + 0.9 * min(-1, 0.5) = 1.1
    torch.testing.assert_close(td3_target(rewards, not_done, q1, q2, 0.9), torch.tensor([2.8, -0.5, 1.1]))


def test_critic_mse_broadcast_defect_regresses_towards_every_target():
    q, y = torch.tensor([1.0, 2.0]), torch.tensor([0.0, 4.0])
    assert critic_mse(q, y).item() == pytest.approx((1 + 4) / 2)  # matched pairs
    assert critic_mse(q, y, broadcast_defect=True).item() == pytest.approx((1 + 9 + 4 + 4) / 4)  # all pairs


def test_td3_target_uses_target_networks_and_seeded_clipped_noise():
    torch.manual_seed(0)
    cfg = TD3Config(policy_noise=10.0, noise_clip=0.25, gamma=0.9)  # every noise entry ends up at +-0.25
    agent = TD3(cfg, collision=False)
    batch = random_buffer(16, 16).sample(16, torch.Generator().manual_seed(3))
    y = agent.compute_target(batch, torch.Generator().manual_seed(7))
    noise = 0.25 * torch.randn(16, 2, generator=torch.Generator().manual_seed(7)).sign()
    with torch.no_grad():
        a_next = (agent.actor_target(batch.next_obs) + noise).clamp(-1, 1)
        q1, q2 = agent.critic_target(batch.next_obs, a_next)
        expected = batch.rewards + 0.9 * batch.not_done * torch.minimum(q1, q2)
        torch.testing.assert_close(y, expected)
        for p in agent.critic.parameters():  # the online critic must not enter the target
            p.add_(1.0)
    torch.testing.assert_close(agent.compute_target(batch, torch.Generator().manual_seed(7)), expected)


def test_broadcast_defect_switch_changes_the_critic_loss():
    torch.manual_seed(0)
    plain = TD3(TD3Config(), collision=False)
    defect = TD3(TD3Config(broadcast_defect=True), collision=False)
    defect.load_state_dict(plain.state_dict())
    batch = random_buffer(32, 32).sample(32, torch.Generator().manual_seed(0))
    y = plain.compute_target(batch, torch.Generator().manual_seed(1))
    with torch.no_grad():
        q1, q2 = plain.critic(batch.obs, batch.actions)
    expected_plain = ((q1 - y) ** 2).mean() + ((q2 - y) ** 2).mean()
    expected_defect = ((q1[:, None] - y[None, :]) ** 2).mean() + ((q2[:, None] - y[None, :]) ** 2).mean()
    loss_plain = plain.update_batch(batch, torch.Generator().manual_seed(1))["loss/critic"]
    loss_defect = defect.update_batch(batch, torch.Generator().manual_seed(1))["loss/critic"]
    torch.testing.assert_close(loss_plain, expected_plain)
    torch.testing.assert_close(loss_defect, expected_defect)
    assert abs(loss_defect - loss_plain) > 0.05  # Q ~ 0 at init, so the two differ by the spread of y


@pytest.mark.parametrize("share", [False, True], ids=["own-encoders", "shared-encoder"])
def test_td3_delays_the_actor_and_soft_updates_targets(share):
    torch.manual_seed(0)
    agent = TD3(TD3Config(policy_freq=2, tau=0.25, share_encoder=share), collision=False)
    buf = random_buffer(64, 64)
    head, targets = params(agent.actor.net), params(agent.actor_target) + params(agent.critic_target)
    critic = params(agent.critic)
    agent.update_batch(buf.sample(32))  # iteration 1: critic only
    assert not same(critic, params(agent.critic))
    assert same(head, params(agent.actor.net))
    assert same(targets, params(agent.actor_target) + params(agent.critic_target))
    old_actor_t, old_critic_t = params(agent.actor_target), params(agent.critic_target)
    metrics = agent.update_batch(buf.sample(32))  # iteration 2: actor step, then both targets move by tau
    assert "loss/actor" in metrics and not same(head, params(agent.actor.net))
    for old, new, online in zip(old_actor_t, params(agent.actor_target), params(agent.actor), strict=True):
        torch.testing.assert_close(new, old + 0.25 * (online - old))
    for old, new, online in zip(old_critic_t, params(agent.critic_target), params(agent.critic), strict=True):
        torch.testing.assert_close(new, old + 0.25 * (online - old))
    assert agent.critic_target.encoder1 is not agent.actor.encoder  # targets are copies, not views
    if share:
        assert agent.critic.encoder1 is agent.actor.encoder
        enc_param = next(agent.actor.encoder.parameters())
        assert any(enc_param is p for group in agent.critic_optimizer.param_groups for p in group["params"])


def test_td3_updates_and_checkpoint_round_trip_reproduce_actions():
    torch.manual_seed(0)
    cfg = TD3Config(batch_size=32, k_epochs=3)
    agent = TD3(cfg, collision=True)
    buf = random_buffer()
    for _ in range(2):
        metrics = agent.update(buf, torch.Generator().manual_seed(0))
        assert all(math.isfinite(v) for v in metrics.values())
    assert agent.iterations == 6 and {"loss/critic", "loss/actor", "lr/actor", "lr/critic"} <= set(metrics)
    obs = random_obs(8, torch.Generator().manual_seed(5))
    clone = TD3(cfg, collision=True)
    clone.load_state_dict(agent.state_dict())
    assert torch.equal(clone.act_deterministic(obs), agent.act_deterministic(obs))
    explore = agent.act(obs, generator=torch.Generator().manual_seed(2))
    assert torch.equal(clone.act(obs, generator=torch.Generator().manual_seed(2)), explore)
    assert not torch.equal(explore, agent.act_deterministic(obs)) and explore.abs().max() <= 1.0
    # optimiser, scheduler, target and counter state came along: one more update stays identical
    agent.update(buf, torch.Generator().manual_seed(9))
    clone.update(buf, torch.Generator().manual_seed(9))
    assert torch.equal(clone.act_deterministic(obs), agent.act_deterministic(obs))
    with pytest.raises(ValueError, match="collision"):
        TD3(cfg, collision=False).load_state_dict(agent.state_dict())
    evaluator = TD3(cfg, collision=True)  # evaluation loads the networks only; targets are re-copied from them
    evaluator.load_state_dict(agent.state_dict(), weights_only=True)
    assert torch.equal(evaluator.act_deterministic(obs), agent.act_deterministic(obs)) and evaluator.iterations == 0
    assert same(params(evaluator.critic_target), params(agent.critic))


# ---------------------------------------------------------------------------------------------- IQL


def test_expectile_loss_exact_values():
    u = torch.tensor([2.0, -1.0, 0.5, 0.0])
    # weights tau = 0.7 above zero, 0.3 otherwise: (0.7 * 4 + 0.3 * 1 + 0.7 * 0.25 + 0) / 4 = 0.81875
    assert expectile_loss(u, 0.7).item() == pytest.approx(0.81875)
    assert expectile_loss(torch.tensor([-2.0]), 0.9).item() == pytest.approx(0.1 * 4)
    assert expectile_loss(torch.tensor([3.0, -3.0]), 0.5).item() == pytest.approx(0.5 * 9)  # tau 0.5: half MSE


def test_awr_weights_are_clipped_at_max_weight():
    adv = torch.tensor([0.0, 1.0, math.log(100.0) / 3.0 + 0.1, 1000.0, -2.0])  # exp(3 * 1000) overflows to inf
    expected = torch.tensor([1.0, math.exp(3.0), 100.0, 100.0, math.exp(-6.0)])
    torch.testing.assert_close(awr_weights(adv, 3.0, 100.0), expected)


def test_iql_q_loss_matched_and_broadcast_defect():
    q1, q2 = torch.tensor([1.0, 2.0]), torch.tensor([0.0, 1.0])
    rewards, not_done, next_v = torch.tensor([1.0, 0.0]), torch.tensor([1.0, 0.0]), torch.tensor([2.0, 5.0])
    # y = [1 + 0.5 * 2, 0] = [2, 0]: ((1-2)^2 + (0-2)^2 + (2-0)^2 + (1-0)^2) / 2 = 5
    assert iql_q_loss(q1, q2, rewards, not_done, next_v, 0.5).item() == pytest.approx(5.0)
    # y[i, j] = r_j + 0.5 * nd_j * V'_i = [[2, 0], [3.5, 0]]: (1+4 + 1+0 + 2.25+6.25 + 4+1) / 4 = 4.875
    assert iql_q_loss(q1, q2, rewards, not_done, next_v, 0.5, broadcast_defect=True).item() == pytest.approx(4.875)


@pytest.mark.parametrize("tanh", [True, False], ids=["tanh-normal", "gaussian"])
def test_iql_actor_log_prob_uses_fixed_std(tanh):
    torch.manual_seed(0)
    agent = IQL(IQLConfig(use_tanh_dist=tanh), collision=False)
    obs = random_obs(4, torch.Generator().manual_seed(0))
    mean = agent.act_deterministic(obs)
    std = math.exp(-3.0)
    gauss_peak = 2 * (-math.log(std) - 0.5 * math.log(2 * math.pi))  # log N(x; x, std) summed over 2 dims
    with torch.no_grad():
        logp = agent.log_prob(obs, mean)
    if tanh:  # the squashed density adds -log(1 - a^2) per dimension at u = mu
        torch.testing.assert_close(logp, gauss_peak - torch.log1p(-mean.pow(2)).sum(-1))
    else:
        torch.testing.assert_close(logp, torch.full((4,), gauss_peak))


def test_iql_scales_rewards_as_the_reference_and_soft_updates_the_target():
    torch.manual_seed(0)
    agent = IQL(IQLConfig(batch_size=40, tau=0.1), collision=False)
    buf = random_buffer(96)
    target_before = params(agent.critic_target)
    first = agent.offline_pass(buf, torch.Generator().manual_seed(0))
    assert first["reward_std"] == pytest.approx(1.0)  # initial estimator, not updated: raw rewards
    assert agent.iterations == 3 and agent.passes == 1  # ceil(96 / 40) minibatches
    assert not same(target_before, params(agent.critic_target))
    second = agent.offline_pass(buf, torch.Generator().manual_seed(1))
    third = agent.offline_pass(buf, torch.Generator().manual_seed(2))
    expected = RewardScaler()
    expected.update(buf.rewards[:96])
    assert second["reward_std"] == pytest.approx(expected.std)
    expected.update(buf.rewards[:96])  # the same dataset again: the count keeps growing
    assert third["reward_std"] == pytest.approx(expected.std)
    assert agent.reward_scaler.count == pytest.approx(1e-4 + 2 * 96)
    # one step: the target critic moves by tau towards the online critic after the step
    old = params(agent.critic_target)
    agent.update_batch(buf.sample(16, torch.Generator().manual_seed(3)))
    for o, new, online in zip(old, params(agent.critic_target), params(agent.critic), strict=True):
        torch.testing.assert_close(new, o + 0.1 * (online - o))


@pytest.mark.parametrize("share", [True, False], ids=["shared-encoder", "own-encoders"])
def test_iql_updates_and_checkpoint_round_trip_reproduce_actions(share):
    torch.manual_seed(0)
    cfg = IQLConfig(batch_size=32, k_epochs=2, share_encoder=share)
    agent = IQL(cfg, collision=True)
    buf = random_buffer()
    assert (agent.value.encoder is agent.actor.encoder) == share
    before = params(agent.actor)
    metrics = agent.offline_pass(buf, torch.Generator().manual_seed(0))
    metrics.update(agent.update(buf, torch.Generator().manual_seed(1)))
    assert all(math.isfinite(v) for v in metrics.values()) and agent.iterations == 3 + 2
    assert not same(before, params(agent.actor))
    obs = random_obs(8, torch.Generator().manual_seed(5))
    clone = IQL(cfg, collision=True)
    clone.load_state_dict(agent.state_dict())
    assert torch.equal(clone.act_deterministic(obs), agent.act_deterministic(obs))
    # the reference executes noise-free actions online
    assert torch.equal(agent.act(obs, generator=torch.Generator().manual_seed(1)), agent.act_deterministic(obs))
    agent.offline_pass(buf, torch.Generator().manual_seed(4))
    clone.offline_pass(buf, torch.Generator().manual_seed(4))
    assert torch.equal(clone.act_deterministic(obs), agent.act_deterministic(obs))
    with pytest.raises(ValueError, match="share_encoder"):
        IQL(IQLConfig(share_encoder=not share), collision=True).load_state_dict(agent.state_dict())
    evaluator = IQL(cfg, collision=True)
    evaluator.load_state_dict(agent.state_dict(), weights_only=True)
    assert torch.equal(evaluator.act_deterministic(obs), agent.act_deterministic(obs)) and evaluator.passes == 0


# ---------------------------------------------------------------------------------------------- RND


def test_rnd_intrinsic_reward_drops_on_a_trained_batch():
    torch.manual_seed(0)
    rnd = RND(27, RNDConfig(lr=1e-3))
    seen = torch.randn(64, 3, 9, generator=torch.Generator().manual_seed(0))  # flattened to 27 features
    unseen = torch.randn(64, 3, 9, generator=torch.Generator().manual_seed(1)) * 3.0
    target = params(rnd.target)
    before = rnd.intrinsic_reward(seen)
    assert before.shape == (64,) and (before > 0).all()
    for i in range(100):
        rnd.update(seen, 32, torch.Generator().manual_seed(i))
    after = rnd.intrinsic_reward(seen)
    assert after.mean() < 0.1 * before.mean()
    assert rnd.intrinsic_reward(unseen).mean() > 5 * after.mean()  # novelty still pays
    assert same(target, params(rnd.target))  # the target stays frozen
    scaled = rnd.scaled_intrinsic(seen)
    torch.testing.assert_close(scaled, after / rnd.scaler.std)
    clone = RND(27, RNDConfig(lr=1e-3))
    clone.load_state_dict(rnd.state_dict())
    assert torch.equal(clone.intrinsic_reward(unseen), rnd.intrinsic_reward(unseen))
