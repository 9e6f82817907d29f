"""PPO's pieces against hand computations, and PPO learning a tiny task."""

import ast
import inspect
import math

import pytest
import torch

import roshan.algos.ppo as ppo_module
from roshan import reproducible
from roshan.algos.agents import fly_ppo
from roshan.algos.distributions import ClippedGaussian, TanhNormal
from roshan.algos.frames import FrameCache
from roshan.algos.normalize import RewardScaler
from roshan.algos.ppo import PPO, Rollout, approx_kl, clip_gradients, clipped_surrogate, explained_variance
from roshan.config import PPOConfig, RNDConfig


def test_clipped_surrogate_by_hand():
    ratio = torch.tensor([0.5, 1.0, 1.5, 0.5, 1.5])
    adv = torch.tensor([1.0, -1.0, 1.0, -1.0, -1.0])
    # min(r A, clip(r) A): 0.5 | -1 | 1.2 (clipped) | -0.8 (clipped: pessimistic) | -1.5
    want = -(0.5 - 1.0 + 1.2 - 0.8 - 1.5) / 5
    assert float(clipped_surrogate(ratio, adv, 0.2)) == pytest.approx(want)


@pytest.mark.parametrize("estimator", ["k1", "k2"])
def test_kl_estimators_on_known_gaussians(estimator):
    g = torch.Generator().manual_seed(0)
    old, new = torch.distributions.Normal(0.0, 1.0), torch.distributions.Normal(0.3, 1.2)
    x = torch.randn(400_000, generator=g)  # samples of the old policy
    exact = float(torch.distributions.kl_divergence(old, new))  # log(1.2) + (1 + 0.09) / 2.88 - 0.5
    assert exact == pytest.approx(math.log(1.2) + 1.09 / 2.88 - 0.5)
    est = float(approx_kl(old.log_prob(x), new.log_prob(x), estimator))
    assert est == pytest.approx(exact, rel=0.03)


def test_k2_is_never_negative_and_zero_for_equal_policies():
    logp = torch.randn(100)
    assert float(approx_kl(logp, logp, "k2")) == 0.0
    assert float(approx_kl(logp, logp + 0.5 * torch.randn(100), "k2")) > 0.0


def test_reward_scaler_divides_by_running_std_without_shift():
    s = RewardScaler(eps=1e-8)
    r = torch.tensor([1.0, 2.0, 3.0, 4.0])
    s.update(r)
    # merge of (mean 0, var 1, count 1e-4) with (mean 2.5, var 1.25, count 4)
    n0, n = 1e-4, 4.0
    total = n0 + n
    mean = 2.5 * n / total
    var = (1.0 * n0 + 1.25 * n + 2.5**2 * n0 * n / total) / total
    assert s.mean == pytest.approx(mean) and s.var == pytest.approx(var)
    torch.testing.assert_close(s.scale(r), r / math.sqrt(var + 1e-8))
    assert bool((s.scale(-r) < 0).all())  # no shift: a penalty stays a penalty


def test_explained_variance():
    ret = torch.tensor([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(ret, ret) == 1.0
    assert explained_variance(ret.mean().expand(4), ret) == pytest.approx(0.0)
    assert math.isnan(explained_variance(ret, torch.ones(4)))


# ---------------------------------------------------------------------------------------------- a tiny task


def bandit_obs(B, g):
    """FlyAgent-shaped observations whose goal delta (features 3-4) is the target action; velocity 0."""
    agent = torch.zeros(B, 3, 9)
    agent[..., 3:5] = g.unsqueeze(1)
    return {"agent": agent, "neighbors": torch.zeros(B, 3, 4, 4), "neighbors_mask": torch.zeros(B, 3, 4)}


def bandit_rollout(agent: PPO, T: int, B: int, g: torch.Generator) -> Rollout:
    """One-step episodes: reward -|a - target|^2, every step terminal."""
    targets = torch.rand(T, B, 2, generator=g) * 1.6 - 0.8
    obs = {k: torch.stack([bandit_obs(B, targets[t])[k] for t in range(T)]) for k in ("agent", "neighbors",
                                                                                           "neighbors_mask")}
    samples = [agent.sample({k: v[t] for k, v in obs.items()}) for t in range(T)]
    actions = torch.stack([s.action for s in samples])
    rewards = -(actions - targets).pow(2).sum(-1)
    done = torch.ones(T, B, dtype=torch.bool)
    return Rollout(obs, torch.stack([s.stored for s in samples]), torch.stack([s.log_prob for s in samples]),
                   torch.stack([s.value for s in samples]), torch.zeros(T, B), rewards, done, torch.zeros_like(done))


@pytest.mark.parametrize("minibatch", ["samples", "sequences"])
def test_ppo_learns_a_contextual_bandit(minibatch):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    cfg = PPOConfig(lr=3e-3, horizon=8 * 128, batch_size=256, k_epochs=4, entropy_coeff=0.0,
                    minibatch=minibatch)
    agent = fly_ppo(cfg, collision=False)
    first = float(bandit_rollout(agent, 8, 128, g).rewards.mean())
    for _ in range(40):
        agent.update(bandit_rollout(agent, 8, 128, g), g)
    with torch.no_grad():
        targets = torch.rand(512, 2, generator=g) * 1.6 - 0.8
        mean = agent.act_deterministic(bandit_obs(512, targets))
    err = float((mean - targets).pow(2).sum(-1).mean())
    assert first < -1.0  # std 1 exploration around a near-zero mean
    assert err < 0.02, f"deterministic action error {err}"
    assert agent.updates == 40


def test_kl_early_stop_skips_the_rest_of_each_epoch():
    g = torch.Generator().manual_seed(0)
    cfg = PPOConfig(horizon=4 * 64, batch_size=64, k_epochs=3, kl_early_stop=True, kl_target=1e-5, lr=1e-2,
                    kl_estimator="k2")  # k2 >= 0: any real change of the policy exceeds the target
    agent = fly_ppo(cfg, collision=False)
    metrics = agent.update(bandit_rollout(agent, 4, 64, g), g)
    # epoch 1: minibatch 1 sees KL ~ 0 (float noise only) and steps, minibatch 2 sees KL > 0 and stops the epoch;
    # epochs 2 and 3 stop at their first minibatch: one gradient step in all.
    assert agent.gradient_steps == 1
    assert metrics["epochs_steps"] == 1


def test_log_std_schedules():
    g = torch.Generator().manual_seed(0)
    rho = 0.9
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=64, log_std="train_step_decay", decay_rate=rho), collision=False)
    assert not agent.net.log_std.requires_grad
    for k in range(3):
        agent.update(bandit_rollout(agent, 1, 64, g), g)
        assert float(agent.net.log_std[0]) == pytest.approx(-20.0 * (1.0 - (rho**k) ** 5))
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=64, log_std="log_step_decay", decay_rate=rho), collision=False)
    for k in range(3):
        agent.update(bandit_rollout(agent, 1, 64, g), g)
        assert float(agent.net.log_std[0]) == pytest.approx((k + 1) * math.log(rho), abs=1e-6)


def test_gradient_clipping_bounds_each_group():
    g = torch.Generator().manual_seed(0)
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=64, k_epochs=1, max_grad_norm=1e-3, lr=1.0,
                          optim=PPOConfig().optim.__class__(name="sgd", scheduler="none")), collision=False)
    before = {n: p.detach().clone() for n, p in agent.net.named_parameters()}
    agent.update(bandit_rollout(agent, 1, 64, g), g)
    actor = [n for n in before if not n.startswith("value") and not n.startswith("critic_encoder")]
    moved = torch.cat([(dict(agent.net.named_parameters())[n].detach() - before[n]).flatten() for n in actor])
    # plain SGD with lr 1: the step is the clipped gradient, so its norm is at most the clip
    assert float(moved.norm()) <= 1e-3 * (1 + 1e-4)


@pytest.mark.parametrize("max_norm", [0.0, 0.5])
def test_clip_gradients_reports_each_groups_norm_before_clipping(max_norm):
    a, b, c = (torch.nn.Parameter(torch.zeros(2)) for _ in range(3))
    a.grad, b.grad, c.grad = torch.tensor([3.0, 0.0]), torch.tensor([0.0, 4.0]), torch.tensor([0.1, 0.0])
    norms = clip_gradients({"actor": [a, b], "critic": [c]}, max_norm)
    assert {k: float(v) for k, v in norms.items()} == pytest.approx({"actor": 5.0, "critic": 0.1})
    scale = max_norm / (5.0 + 1e-6) if max_norm else 1.0  # torch's clip coefficient; 0 = clipping off
    assert a.grad.tolist() == pytest.approx([3.0 * scale, 0.0]) and b.grad.tolist() == pytest.approx([0.0, 4.0 * scale])
    assert c.grad.tolist() == pytest.approx([0.1, 0.0])  # under the bound: untouched


def test_update_logs_the_gradient_norm_of_each_group():
    g = torch.Generator().manual_seed(0)
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=32, k_epochs=1), collision=False)
    stats = agent.update(bandit_rollout(agent, 1, 64, g), g)
    assert stats["grad_norm_actor"] > 0 and stats["grad_norm_critic"] > 0


def test_separate_optimizers_refuse_a_shared_encoder():
    with pytest.raises(ValueError, match="share_encoder"):
        fly_ppo(PPOConfig(separate_optimizers=True, share_encoder=True), collision=False)


def test_state_dict_round_trip_reproduces_actions():
    g = torch.Generator().manual_seed(0)
    a = fly_ppo(PPOConfig(horizon=64, batch_size=32), collision=True)
    a.update(bandit_rollout(a, 1, 64, g), g)
    b = fly_ppo(PPOConfig(horizon=64, batch_size=32), collision=True)
    b.load_state_dict(a.state_dict())
    obs = bandit_obs(16, torch.rand(16, 2, generator=g))
    torch.testing.assert_close(a.act_deterministic(obs), b.act_deterministic(obs))
    assert b.updates == 1 and b.scaler.count == a.scaler.count


def test_tanh_normal_raw_log_prob_matches_and_survives_saturation():
    dist = TanhNormal(torch.tensor([[0.3, -0.2]]), torch.tensor([0.5, 0.5]))
    u = torch.tensor([[0.4, -1.0]])
    torch.testing.assert_close(dist.log_prob_raw(u), dist.log_prob(torch.tanh(u)))
    # tanh(10) and tanh(13) are both 1.0 in float32: only the raw sample tells them apart
    far = TanhNormal(torch.tensor([[10.0, 0.0]]), torch.tensor([1.0, 1.0]))
    a, b = far.log_prob_raw(torch.tensor([[10.0, 0.0]])), far.log_prob_raw(torch.tensor([[13.0, 0.0]]))
    assert torch.isfinite(a).all() and torch.isfinite(b).all() and float(a) != float(b)
    assert torch.tanh(torch.tensor(10.0)) == torch.tanh(torch.tensor(13.0))


@pytest.mark.parametrize("tanh_dist", [False, True])
def test_act_deterministic_is_the_distribution_mode(tanh_dist):
    g = torch.Generator().manual_seed(1)
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=32, use_tanh_dist=tanh_dist), collision=True)
    with torch.no_grad():
        agent.net.mu.weight.mul_(400.0)  # push some means towards the action bounds
        obs = bandit_obs(16, torch.rand(16, 2, generator=g) * 4 - 2)
        mean, std, _ = agent.net(obs)
        expected = (TanhNormal if tanh_dist else ClippedGaussian)(mean, std).mode
        assert (expected.abs() > 0.9).any()
        torch.testing.assert_close(agent.act_deterministic(obs), expected, rtol=0, atol=0)
        torch.testing.assert_close(agent.policy.act_deterministic(obs, FrameCache()), expected, rtol=0, atol=0)


@pytest.mark.parametrize("tanh_dist", [False, True])
def test_sampling_without_a_generator_is_the_distributions_own_sample(tanh_dist):
    """FlyAgent rollouts draw from torch's global RNG exactly as ``Normal.sample`` did (runs reproduce); a
    generator makes the draw its own stream."""
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=32, use_tanh_dist=tanh_dist), collision=False)
    obs = bandit_obs(16, torch.rand(16, 2) * 2 - 1)
    with torch.no_grad():
        mean, std, value = agent.net(obs)
        torch.manual_seed(5)
        sample = agent.sample(obs)
        torch.manual_seed(5)
        want = torch.distributions.Normal(mean, std.expand_as(mean)).sample()
    dist = (TanhNormal if tanh_dist else ClippedGaussian)(mean, std)
    want = want if tanh_dist else want.clamp(-1.0, 1.0)
    torch.testing.assert_close(sample.stored, want, rtol=0, atol=0)
    torch.testing.assert_close(sample.action, dist.to_action(want), rtol=0, atol=0)
    torch.testing.assert_close(sample.log_prob, dist.log_prob_raw(want))
    torch.testing.assert_close(sample.value, value)
    a = agent.act(obs, generator=torch.Generator().manual_seed(2))
    torch.testing.assert_close(agent.act(obs, generator=torch.Generator().manual_seed(2)), a, rtol=0, atol=0)
    assert not torch.equal(a, agent.act(obs, generator=torch.Generator().manual_seed(3)))


def test_rnd_adds_its_scaled_novelty_to_the_scaled_rewards_and_trains_its_predictor():
    g = torch.Generator().manual_seed(0)
    cfg = PPOConfig(horizon=64, batch_size=32, k_epochs=1)
    assert fly_ppo(cfg, collision=False, rnd=RNDConfig(enabled=False)).rnd is None  # off: nothing changes
    agent = fly_ppo(cfg, collision=False, rnd=RNDConfig(enabled=True, coef=0.5, hidden=16, out=8))
    rollout = bandit_rollout(agent, 2, 32, g)
    features = rollout.obs["agent"].flatten(0, 1).flatten(1)
    with torch.no_grad():
        raw = agent.rnd.intrinsic_reward(features)
    predictor = [p.detach().clone() for p in agent.rnd.predictor.parameters()]
    metrics = agent.update(rollout, g)
    # the novelty is divided by its own running std (this batch merged first), times rnd.coef
    want = 0.5 * raw.view(2, 32) / agent.rnd.scaler.std
    assert metrics["rnd_intrinsic"] == pytest.approx(float(want.mean()), rel=1e-5)
    scaled = rollout.rewards / agent.scaler.std
    assert metrics["rewards_scaled"] == pytest.approx(float((scaled + want).mean()), rel=1e-5)
    assert metrics["rnd_loss"] > 0 and any(not torch.equal(a, b) for a, b in
                                           zip(predictor, agent.rnd.predictor.parameters(), strict=True))
    clone = fly_ppo(cfg, collision=False, rnd=RNDConfig(enabled=True, coef=0.5, hidden=16, out=8))
    clone.load_state_dict(agent.state_dict())
    torch.testing.assert_close(clone.rnd.intrinsic_reward(features), agent.rnd.intrinsic_reward(features))


@pytest.mark.parametrize("bound", [0.0, 3.0])
def test_mean_bound_brings_a_saturated_mean_back_where_samples_differ(bound):
    # Both pre-tanh means start at 8, deep in tanh's flat tail: every sample is the action ~ +1, the reward cannot
    # tell samples apart and the surrogate has no gradient. Only the mean_bound penalty pulls the means back to
    # where samples differ, and from there the bandit is learned.
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    cfg = PPOConfig(lr=3e-3, horizon=8 * 128, batch_size=256, k_epochs=4, entropy_coeff=0.0, use_tanh_dist=True,
                    mean_bound=bound)
    agent = fly_ppo(cfg, collision=False)
    with torch.no_grad():
        agent.net.mu.bias.fill_(8.0)
    for _ in range(40):
        agent.update(bandit_rollout(agent, 8, 128, g), g)
    with torch.no_grad():
        targets = torch.rand(512, 2, generator=g) * 1.6 - 0.8
        err = float((agent.act_deterministic(bandit_obs(512, targets)) - targets).pow(2).sum(-1).mean())
    if bound:
        assert err < 0.05
    else:
        assert err > 1.0  # still the action (1, 1) everywhere


def test_mean_bound_penalty_is_the_squared_excess_once():
    cfg = PPOConfig(use_tanh_dist=True, mean_bound=3.0, mean_bound_coef=2.0)
    agent = fly_ppo(cfg, collision=False)
    with torch.no_grad():
        agent.net.mu.weight.zero_()
        agent.net.mu.bias.copy_(torch.tensor([4.5, -1.0]))
    obs = bandit_obs(6, torch.zeros(6, 2))
    penalty = agent.policy.evaluate(obs, torch.zeros(6, 2)).penalty
    assert float(penalty.detach()) == pytest.approx(2.0 * 1.5**2)
    penalty.backward()
    assert agent.net.mu.bias.grad.tolist() == pytest.approx([2.0 * 2 * 1.5, 0.0])  # pulls only the first mean in
    off = fly_ppo(PPOConfig(use_tanh_dist=False, mean_bound=3.0), collision=False)
    assert off.policy.evaluate(obs, torch.zeros(6, 2)).penalty == 0.0  # the Gaussian's mean is tanh(mu) already


def floats(net: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in net.state_dict().items() if v.is_floating_point()}


def test_weight_average_is_the_exponential_average_over_updates_and_acts_deterministically():
    g = torch.Generator().manual_seed(0)
    d = 0.75
    agent = fly_ppo(PPOConfig(horizon=64, batch_size=32, lr=1e-2, ema_decay=d), collision=True)
    w = [floats(agent.net)]
    for _ in range(2):
        agent.update(bandit_rollout(agent, 1, 64, g), g)
        w.append(floats(agent.net))
    # avg_0 = w_0, avg_k = d avg_(k-1) + (1 - d) w_k (learning one step per update, not per minibatch)
    want = {k: d * (d * w[0][k] + (1 - d) * w[1][k]) + (1 - d) * w[2][k] for k in w[0]}
    got = floats(agent.average.policy.net)
    for k in want:
        torch.testing.assert_close(got[k], want[k], rtol=1e-6, atol=1e-7)
    assert not torch.equal(got["mu.weight"], w[2]["mu.weight"])  # the live weights moved on
    obs = bandit_obs(16, torch.rand(16, 2, generator=g) * 2 - 1)
    live = fly_ppo(PPOConfig(horizon=64, batch_size=32), collision=True)
    live.net.load_state_dict(agent.net.state_dict())
    averaged = fly_ppo(PPOConfig(horizon=64, batch_size=32), collision=True)
    averaged.net.load_state_dict(agent.average.policy.net.state_dict())
    torch.testing.assert_close(agent.act_deterministic(obs), averaged.act_deterministic(obs), rtol=0, atol=0)
    assert not torch.equal(agent.act_deterministic(obs), live.act_deterministic(obs))
    # training keeps sampling from the live weights
    torch.testing.assert_close(agent.policy.net(obs)[0], live.net(obs)[0], rtol=0, atol=0)


def test_weight_average_survives_resume_and_is_what_a_weights_only_load_acts_with():
    g = torch.Generator().manual_seed(0)
    cfg = PPOConfig(horizon=64, batch_size=32, lr=1e-2, ema_decay=0.9)
    a = fly_ppo(cfg, collision=True)
    a.update(bandit_rollout(a, 1, 64, g), g)
    state = a.state_dict()
    obs = bandit_obs(16, torch.rand(16, 2, generator=g) * 2 - 1)
    resumed = fly_ppo(cfg, collision=True)
    resumed.load_state_dict(state)
    torch.testing.assert_close(resumed.act_deterministic(obs), a.act_deterministic(obs), rtol=0, atol=0)
    torch.testing.assert_close(resumed.policy.net(obs)[0], a.policy.net(obs)[0], rtol=0, atol=0)
    for cfg_b in (cfg, PPOConfig(horizon=64, batch_size=32)):  # evaluation builds the agent from the run's config
        frozen = fly_ppo(cfg_b, collision=True)
        frozen.load_state_dict(state, weights_only=True)
        torch.testing.assert_close(frozen.act_deterministic(obs), a.act_deterministic(obs), rtol=0, atol=0)
    assert "net_average" not in fly_ppo(PPOConfig(), collision=True).state_dict()
    del state["net_average"]
    with pytest.raises(ValueError, match="ema_decay"):
        fly_ppo(cfg, collision=True).load_state_dict(state)


# The weights and logged metrics after three updates of each minibatch mode, with the mean bound and the KL stop, in
# the reproducible mode (conftest.py) with one torch thread, as training runs them: one pin for every CPU. Recorded on
# an AMD EPYC (torch 2.13.0 CPU build, the Linear layers on the pinned OpenBLAS); outside the mode the same updates
# gave 100040a1 / c3942e45 there and 90b1468b / a95fdc9c on an Intel Xeon (two threads), which is why the mode
# exists (roshan/reproducible.py).
UPDATE_PINS = {"samples": "9655f97b", "sequences": "92839252"}


def update_fingerprint(minibatch: str) -> str:
    import hashlib
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(3)
    cfg = PPOConfig(lr=3e-3, horizon=4 * 64, batch_size=64, k_epochs=3, use_tanh_dist=True, mean_bound=0.5,
                    kl_early_stop=True, kl_target=0.02, max_grad_norm=0.5, minibatch=minibatch)
    agent = fly_ppo(cfg, collision=True)
    h = hashlib.sha256()
    for _ in range(3):
        metrics = agent.update(bandit_rollout(agent, 4, 64, g), g)
        h.update(repr(sorted((k, round(v, 6)) for k, v in metrics.items() if v == v)).encode())
    for v in agent.net.state_dict().values():
        h.update(v.detach().contiguous().numpy().tobytes())
    h.update(repr((agent.gradient_steps, agent.updates)).encode())
    return h.hexdigest()[:8]


@pytest.mark.parametrize("minibatch", ["samples", "sequences"])
def test_an_update_is_pinned_bit_for_bit(minibatch):
    # one thread: the order in which parallel sums combine depends on the thread count
    assert reproducible.check() is None
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        assert update_fingerprint(minibatch) == UPDATE_PINS[minibatch]
    finally:
        torch.set_num_threads(threads)


def code_lines(fn, lines: list[str]) -> int:
    """Lines of a function (an ``ast`` node over ``lines``) that are neither blank, comment nor docstring."""
    doc = fn.body[0] if ast.get_docstring(fn) else None
    skip = set(range(doc.lineno, doc.end_lineno + 1)) if doc else set()
    return sum(1 for i in range(fn.lineno, fn.end_lineno + 1)
               if i not in skip and lines[i - 1].strip() and not lines[i - 1].strip().startswith("#"))


def test_an_update_reads_in_one_screen():
    """issue 31: PPO.update and what it calls up to the loss (the advantages, one epoch's minibatches, the policy
    change and the gradient step) fit in about 60 lines of code: 67 today, 70 with the recurrent epoch."""
    source = inspect.getsource(ppo_module)
    tree, lines = ast.parse(source), source.splitlines()
    functions = {node.name: node for node in tree.body if isinstance(node, ast.FunctionDef)}
    ppo_class = next(node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == "PPO")
    functions.update({node.name: node for node in ppo_class.body if isinstance(node, ast.FunctionDef)})
    chain = ("update", "advantages", "_sample_epoch", "policy_change", "normalized_advantages", "_gradient_step")
    counts = {name: code_lines(functions[name], lines) for name in chain}
    assert sum(counts.values()) <= 70, counts
    assert code_lines(functions["_column_epoch"], lines) <= counts["_sample_epoch"] + 5
