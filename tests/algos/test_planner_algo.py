"""Planner networks (masking, pointer decoding, log-prob consistency) and planner PPO on a tiny bandit."""

import pytest
import torch

from roshan.algos.agents import planner_ppo
from roshan.algos.planner_nets import (
    PLANNER_NETS,
    FleetPlannerNet,
    PointerPlannerNet,
    ThesisPlannerNet,
    candidate_validity,
    trim_candidates,
)
from roshan.algos.ppo import PPO, Rollout
from roshan.config import PlannerConfig, PPOConfig, RNDConfig

NETS = [ThesisPlannerNet, PointerPlannerNet]


@pytest.fixture(autouse=True)
def one_thread():
    """These networks are tiny: one intra-op thread is faster and does not fight other jobs for the CPU."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def random_obs(B: int, N: int, K: int, g: torch.Generator, n_valid: torch.Tensor | None = None) -> dict:
    """Observations with a random valid prefix (1..K candidates, index 0 = groundstation) and zero padding."""
    if n_valid is None:
        n_valid = torch.randint(1, K + 1, (B,), generator=g)
    mask = (torch.arange(K) < n_valid.unsqueeze(1)).float()
    fires = (torch.rand(B, K, 2, generator=g) * 2 - 1) * mask.unsqueeze(-1)
    return {"drones": torch.rand(B, N, 2, generator=g) * 2 - 1, "goals": torch.rand(B, N, 2, generator=g) * 2 - 1,
            "water": torch.rand(B, N, 1, generator=g), "fires": fires, "fires_mask": mask,
            "globals": torch.rand(B, 5, generator=g) * 2 - 1}


def pad(obs: dict, extra: int) -> dict:
    """The same observations with ``extra`` more zero-padded candidates."""
    out = dict(obs)
    out["fires"] = torch.cat([obs["fires"], torch.zeros(obs["fires"].shape[0], extra, 2)], dim=1)
    out["fires_mask"] = torch.cat([obs["fires_mask"], torch.zeros(obs["fires_mask"].shape[0], extra)], dim=1)
    return out


def test_trim_candidates_cuts_to_the_longest_valid_prefix():
    g = torch.Generator().manual_seed(0)
    obs = random_obs(3, 2, 10, g, n_valid=torch.tensor([1, 4, 2]))
    trimmed = trim_candidates(obs)
    assert trimmed["fires"].shape == (3, 4, 2) and trimmed["fires_mask"].shape == (3, 4)
    assert trimmed["drones"] is obs["drones"]
    only_groundstation = trim_candidates(random_obs(2, 2, 10, g, n_valid=torch.tensor([1, 1])))
    assert only_groundstation["fires"].shape[1] == 1


@torch.no_grad()
@pytest.mark.parametrize("net_cls", NETS)
def test_linear_layers_are_orthogonal_with_the_reference_gains(net_cls):
    net = net_cls(3)
    value_out = net.value_head if net_cls is ThesisPlannerNet else net.value_head[-1]
    linears = [m for m in net.modules() if isinstance(m, torch.nn.Linear)]
    assert len(linears) >= 5
    for m in linears:  # includes the output projections inside nn.MultiheadAttention
        gain2 = 1.0 if m is value_out else 2.0
        w = m.weight if m.weight.shape[0] <= m.weight.shape[1] else m.weight.T
        torch.testing.assert_close(w @ w.T, gain2 * torch.eye(w.shape[0]), atol=1e-5, rtol=0)
        assert bool((m.bias == 0).all())
    if net_cls is PointerPlannerNet:
        assert float(net.log_temperature) == 0.0 and float(net.log_penalty) == pytest.approx(1.6)


@torch.no_grad()
def test_thesis_net_masks_padding_and_the_groundstation_while_a_fire_is_listed():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    N, K = 3, 7
    net = ThesisPlannerNet(N)
    n_valid = torch.tensor([1, 2, 5, 7, 1, 3])
    obs = random_obs(6, N, K, g, n_valid)
    probs = net.probs(obs)
    allowed = torch.arange(K) < n_valid.unsqueeze(1)
    allowed[:, 0] = n_valid == 1  # the groundstation only when no fire is listed
    assert bool((probs[~allowed.unsqueeze(1).expand_as(probs)] == 0).all())
    torch.testing.assert_close(probs.sum(-1), torch.ones(6, N))
    for _ in range(50):
        actions, logp, entropy, _ = net.forward_act(obs, generator=g)
        assert bool(allowed.gather(1, actions).all())
        assert bool(torch.isfinite(logp).all()) and bool(torch.isfinite(entropy).all())
    actions = net.forward_act(obs, deterministic=True)[0]
    assert bool((actions[n_valid == 1] == 0).all()) and bool((actions[n_valid > 1] != 0).all())


def reference_attention(net: ThesisPlannerNet, obs: dict):
    """The thesis net's attention as nn.MultiheadAttention computes it on the embedded fires (the H-wide
    projections that ``attend`` avoids)."""
    allowed = net.allowed(obs).squeeze(1)  # one mask for all drones without a battery
    query = net.pos_emb(obs["drones"]) + net.goal_emb(obs["goals"]) + net.id_emb(net.drone_ids)
    fires = net.fire_emb(obs["fires"])
    out, weights = net.attn(query, fires, fires, key_padding_mask=~allowed, need_weights=True,
                            average_attn_weights=True)
    return weights, out


def test_thesis_attention_in_fire_coordinates_is_multihead_attention_with_its_gradients():
    """attend() works in the fires' 2 coordinates; weights, output and every parameter's gradient are
    nn.MultiheadAttention's to float rounding, with non-zero biases and a batch of uneven candidate lists."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(4)
    net = ThesisPlannerNet(3)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=g))
    obs = random_obs(40, 3, 30, g)
    obs["fires_mask"][:2, 1:] = 0.0  # rows with no fire: the groundstation alone
    actions = torch.randint(0, 3, (40, 3), generator=g)

    def grads(attention):
        net.zero_grad()
        weights, out = attention()
        loss = weights.clamp_min(1e-8).log().gather(-1, actions.unsqueeze(-1)).sum() + net.value_head(out).sum()
        loss.backward()
        return weights.detach(), out.detach(), {n: p.grad.clone() for n, p in net.named_parameters()
                                                 if p.grad is not None}

    w_ref, out_ref, g_ref = grads(lambda: reference_attention(net, obs))
    w, out, g_new = grads(lambda: net.attend(obs)[:2])
    torch.testing.assert_close(w, w_ref, atol=1e-6, rtol=1e-5)
    torch.testing.assert_close(out, out_ref, atol=1e-5, rtol=1e-5)
    assert bool((w[:2, :, 1:] == 0).all()) and set(g_new) == set(g_ref)
    for name in g_ref:
        torch.testing.assert_close(g_new[name], g_ref[name], atol=1e-4, rtol=1e-4, msg=name)


@torch.no_grad()
def test_pointer_net_never_samples_a_masked_candidate_or_a_taken_fire():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    N, K = 4, 6
    net = PointerPlannerNet(N)
    net.log_temperature.fill_(-3.0)  # sharp logits: the drones would all prefer the same fire without the mask
    for _ in range(30):
        obs = random_obs(64, N, K, g)
        actions, logp, entropy, _ = net.forward_act(obs, generator=g)
        n_valid = obs["fires_mask"].sum(-1, keepdim=True)
        assert bool((actions < n_valid).all())
        assert bool(torch.isfinite(logp).all()) and bool(torch.isfinite(entropy).all())
        fires = torch.where(actions > 0, actions, -torch.arange(1, N + 1).expand_as(actions))  # 0 -> unique
        assert bool((fires.sort(-1).values.diff(dim=-1) != 0).all()), "two drones share a fire"
    # only the groundstation listed: every drone goes there
    obs = random_obs(8, N, K, g, n_valid=torch.ones(8, dtype=torch.long))
    assert bool((net.forward_act(obs, generator=g)[0] == 0).all())
    # the decoder's per-drone distributions give masked and taken entries probability exactly 0
    obs = random_obs(32, N, K, g)
    d, fires, valid = net.encoder(obs)
    actions = net.forward_act(obs, generator=g)[0]
    probs = torch.softmax(net.decode_logits(net.base_logits(d, fires, obs), net.selectable(obs, valid), actions), -1)
    assert bool((probs[~valid.unsqueeze(1).expand_as(probs)] == 0).all())
    taken = probs[:, 1].gather(-1, actions[:, :1])  # drone 1 cannot take drone 0's fire
    assert bool((taken[actions[:, 0] > 0] == 0).all())


@torch.no_grad()
def test_pointer_groundstation_may_repeat():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(2)
    net = PointerPlannerNet(3)
    obs = random_obs(256, 3, 5, g, n_valid=torch.full((256,), 5))  # 4 fires for 3 drones: no forced fallback
    d, fires, valid = net.encoder(obs)
    base = net.base_logits(d, fires, obs)
    home = torch.zeros(256, 3, dtype=torch.long)  # every drone at the groundstation
    logits = net.decode_logits(base, net.selectable(obs, valid), home)
    # drone i's groundstation logit carries the soft penalty c * (number of earlier drones there), no mask
    torch.testing.assert_close(logits[..., 0], base[..., 0] - net.penalty() * torch.arange(3.0))
    torch.testing.assert_close(logits[..., 1:], base[..., 1:])
    net.log_penalty.fill_(-3.0)  # c = 0.05: repeats become common enough to observe in samples
    actions = net.forward_act(obs, generator=g)[0]
    assert bool(((actions == 0).sum(-1) >= 2).any())


@pytest.mark.parametrize("net_cls", NETS)
def test_evaluate_reproduces_the_sampled_log_probs(net_cls):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(3)
    N, K = 3, 8
    net = net_cls(N)
    obs = random_obs(40, N, K, g)
    actions, logp, entropy, value = net.forward_act(obs, generator=g)
    e_logp, e_entropy, e_value = net.evaluate(obs, actions)
    assert torch.equal(logp, e_logp) and torch.equal(entropy, e_entropy) and torch.equal(value, e_value)
    # trimming and extra padding only change which masked entries exist: same outputs up to float rounding
    for variant in (trim_candidates(obs), pad(obs, 25)):
        v_logp, v_entropy, v_value = net.evaluate(variant, actions)
        torch.testing.assert_close(v_logp, logp)
        torch.testing.assert_close(v_entropy, entropy)
        torch.testing.assert_close(v_value, value)
    # deterministic actions are reproduced as well
    actions, logp = net.forward_act(obs, deterministic=True)[:2]
    assert torch.equal(net.evaluate(obs, actions)[0], logp)
    assert torch.equal(net.forward_act(pad(obs, 25), deterministic=True)[0], actions)


@torch.no_grad()
def test_thesis_joint_log_prob_is_the_sum_of_per_drone_categoricals():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(4)
    net = ThesisPlannerNet(2)
    obs = random_obs(16, 2, 5, g, n_valid=torch.full((16,), 5))
    actions, logp, entropy, _ = net.forward_act(obs, generator=g)
    dist = torch.distributions.Categorical(probs=net.probs(obs))  # attention weights, averaged over heads
    torch.testing.assert_close(logp, dist.log_prob(actions).sum(-1))
    torch.testing.assert_close(entropy, dist.entropy().sum(-1))


# ---------------------------------------------------------------------------------------------- PPO


def test_thesis_temperature_sharpens_the_categorical_to_p_to_the_one_over_t():
    g = torch.Generator().manual_seed(3)
    obs = random_obs(8, 3, 12, g, n_valid=torch.full((8,), 12))
    plain = ThesisPlannerNet(3)
    sharp = ThesisPlannerNet(3, temperature=0.25)
    sharp.load_state_dict(plain.state_dict())
    with torch.no_grad():
        p = plain.probs(obs).clamp_min(1e-8)
        expected = torch.softmax(p.log() * 4.0 + torch.log(torch.isfinite(plain.heads(obs)[0]).float()), -1)
        got = torch.softmax(sharp.heads(obs)[0], -1)
        torch.testing.assert_close(got, expected, atol=1e-5, rtol=1e-4)
        assert torch.equal(got.argmax(-1), p.argmax(-1))  # deterministic evaluation is unchanged
        h = lambda q: -(q * q.clamp_min(1e-12).log()).sum(-1)  # noqa: E731
        assert bool((h(got) < h(torch.softmax(plain.heads(obs)[0], -1))).all())


def bandit_rollout(agent: PPO, obs: dict, T: int, g: torch.Generator) -> Rollout:
    """One-step episodes: reward 1 when drone 0 picks candidate 2 and drone 1 picks candidate 3."""
    E = obs["drones"].shape[0]
    samples = [agent.sample(obs, generator=g) for _ in range(T)]
    actions = torch.stack([s.action for s in samples])
    rewards = ((actions[..., 0] == 2) & (actions[..., 1] == 3)).float()
    done = torch.ones(T, E, dtype=torch.bool)
    stacked = {k: v.unsqueeze(0).expand(T, *v.shape) for k, v in obs.items()}
    return Rollout(stacked, torch.stack([s.stored for s in samples]), torch.stack([s.log_prob for s in samples]),
                   torch.stack([s.value for s in samples]), torch.zeros(T, E), rewards, done, torch.zeros_like(done))


@pytest.mark.parametrize("network", ["thesis", "pointer", "fleet"])
def test_planner_ppo_learns_a_joint_bandit(network):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(5)
    cfg = PPOConfig(lr=3e-3, horizon=8 * 16, batch_size=64, k_epochs=4, entropy_coeff=0.0, value_loss_coef=0.5)
    agent = planner_ppo(cfg, PlannerConfig(network=network), num_drones=2)
    one = random_obs(1, 2, 4, g, n_valid=torch.tensor([4]))  # one fixed scene, seen by 16 envs
    obs = {k: v.expand(16, *v.shape[1:]) for k, v in one.items()}
    first = float(bandit_rollout(agent, obs, 8, g).rewards.mean())
    for _ in range(20):
        metrics = agent.update(bandit_rollout(agent, obs, 8, g), g)
    assert all(v == v for k, v in metrics.items() if k != "explained_variance"), metrics  # no NaN
    actions = agent.act_deterministic(obs)
    assert first < 0.3
    assert bool((actions == torch.tensor([2, 3])).all()), actions
    assert agent.updates == 20 and agent.gradient_steps == 20 * 4 * 2


@pytest.mark.parametrize("network", ["thesis", "pointer", "fleet"])
def test_state_dict_round_trip_gives_identical_outputs(network):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(6)
    cfg = PPOConfig(horizon=32, batch_size=16)
    a = planner_ppo(cfg, PlannerConfig(network=network), num_drones=3)
    a.update(bandit_rollout(a, random_obs(8, 3, 6, g), 4, g), g)
    b = planner_ppo(cfg, PlannerConfig(network=network), num_drones=3)
    b.load_state_dict(a.state_dict())
    obs = random_obs(16, 3, 6, g)
    sa = a.sample(obs, generator=torch.Generator().manual_seed(7))
    sb = b.sample(obs, generator=torch.Generator().manual_seed(7))
    assert all(torch.equal(x, y) for x, y in zip(sa, sb, strict=True))
    assert torch.equal(a.act_deterministic(obs), b.act_deterministic(obs))
    assert b.updates == 1 and b.gradient_steps == a.gradient_steps and b.scaler.count == a.scaler.count
    assert b.optimizers[0].state_dict()["state"].keys() == a.optimizers[0].state_dict()["state"].keys()


def test_planner_rnd_reads_drones_goals_water_and_globals():
    g = torch.Generator().manual_seed(8)
    agent = planner_ppo(PPOConfig(horizon=32, batch_size=16), PlannerConfig(), num_drones=3,
                        rnd=RNDConfig(enabled=True, hidden=16, out=8))
    obs = random_obs(8, 3, 6, g)
    features = agent.policy.novelty_features(obs)
    assert features.shape == (8, agent.policy.novelty_dim) == (8, 5 * 3 + 5)
    torch.testing.assert_close(features[:, -5:], obs["globals"])
    metrics = agent.update(bandit_rollout(agent, obs, 4, g), g)
    assert metrics["rnd_intrinsic"] > 0 and metrics["rnd_loss"] > 0


@torch.no_grad()
@pytest.mark.parametrize("net_cls", NETS)
def test_with_a_battery_the_nets_read_energy_and_may_send_a_drone_home_while_fires_burn(net_cls):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(5)
    obs = random_obs(6, 3, 9, g, n_valid=torch.full((6,), 9))  # fires listed in every row
    obs["energy"] = torch.rand(6, 3, 2, generator=g) * 0.45  # every battery below half: home is a candidate
    plain, aware = net_cls(3), net_cls(3, resources=True)
    assert not any("energy" in k for k in plain.state_dict())  # without a battery: the nets as before
    actions = torch.zeros((6, 3), dtype=torch.long)  # everyone home
    assert bool(torch.isfinite(aware.evaluate(obs, actions)[0]).all())  # the groundstation is a candidate
    if net_cls is ThesisPlannerNet:
        assert bool((plain.probs(obs)[..., 0] == 0).all()) and bool((aware.probs(obs)[..., 0] > 0).all())
        # home is offered while fires burn only to a drone whose battery or tank is below half
        fills = {**obs, "energy": obs["energy"].clone(), "water": obs["water"].clone()}
        fills["energy"][..., 0] = torch.tensor([0.5, 0.49, 0.9])
        fills["water"][..., 0] = torch.tensor([0.5, 0.9, 0.2])
        probs = aware.probs(fills)
        assert bool((probs[:, 0, 0] == 0).all()) and bool((probs[:, 1:, 0] > 0).all())
        assert bool((probs[:, 0, 1:].sum(-1) > 0.99).all())
    else:  # the pointer nets offer home by the same rule: a stocked drone's nearest candidate is often its base
        fills = {**obs, "energy": obs["energy"].clone(), "water": obs["water"].clone()}
        fills["energy"][..., 0] = torch.tensor([0.5, 0.49, 0.9])
        fills["water"][..., 0] = torch.tensor([0.5, 0.9, 0.2])
        allowed = aware.selectable(fills, candidate_validity(fills["fires_mask"]))
        assert allowed.shape == (6, 3, 9) and bool((~allowed[:, 0, 0]).all()) and bool(allowed[:, 1:, 0].all())
        for _ in range(20):
            drawn = aware.forward_act(fills, generator=g)[0]
            assert bool((drawn[:, 0] != 0).all())  # drone 0 is stocked: never sent home while fires burn
        assert bool(plain.selectable(fills, candidate_validity(fills["fires_mask"]))[..., 0].all())  # no battery
    drained = {**obs, "energy": torch.zeros_like(obs["energy"])}
    assert not torch.allclose(aware.evaluate(obs, actions)[0], aware.evaluate(drained, actions)[0])
    assert not torch.allclose(aware.value(obs), aware.value(drained))


def nearest_valid(obs: dict, taken: torch.Tensor | None = None, home: bool = False) -> torch.Tensor:
    """(B, N) index of each drone's nearest listed fire (index >= 1; with ``home`` the groundstation, index 0, too),
    by hand; ``taken`` (B, K) bool excluded."""
    dist = (obs["fires"].unsqueeze(1) - obs["drones"].unsqueeze(2)).norm(dim=-1)  # (B, N, K)
    out = obs["fires_mask"] == 0
    out[:, 0] = not home
    if taken is not None:
        out = out | taken
    return dist.masked_fill(out.unsqueeze(1), float("inf")).argmin(-1)


@torch.no_grad()
def test_a_strong_distance_prior_makes_each_drone_choose_its_nearest_fire():
    """planner.distance_prior: the thesis net's argmax becomes greedy's nearest fire; the pointer net's, drone by
    drone in id order, the nearest candidate no earlier drone took. Off (0) the nets have no extra parameter."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(3)
    N, K = 3, 12
    obs = random_obs(64, N, K, g, n_valid=torch.randint(N + 2, K + 1, (64,), generator=g))
    thesis = ThesisPlannerNet(N, distance_prior=1000.0)
    assert bool((thesis.forward_act(obs, deterministic=True)[0] == nearest_valid(obs)).all())
    assert not bool((ThesisPlannerNet(N).forward_act(obs, deterministic=True)[0] == nearest_valid(obs)).all())

    pointer = PointerPlannerNet(N, distance_prior=1000.0)  # its groundstation is always a candidate, and repeats
    actions = pointer.forward_act(obs, deterministic=True)[0]
    taken = torch.zeros(64, K, dtype=torch.bool)
    for i in range(N):
        assert bool((actions[:, i] == nearest_valid(obs, taken, home=True)[:, i]).all()), f"drone {i}"
        taken.scatter_(1, actions[:, i:i + 1], actions[:, i:i + 1] > 0)

    for net in (ThesisPlannerNet(N), PointerPlannerNet(N)):
        assert net.prior is None and not any("prior" in k for k in net.state_dict())


def test_the_distance_priors_weight_is_learned_by_the_actors_optimiser():
    g = torch.Generator().manual_seed(4)
    obs = random_obs(16, 2, 6, g)
    agent = planner_ppo(PPOConfig(), PlannerConfig(distance_prior=10.0), 2)
    prior = agent.policy.net.prior.log_weight
    assert any(p is prior for p in agent.groups["actor"]) and not any(p is prior for p in agent.groups["critic"])
    actions = agent.policy.net.forward_act(obs, generator=g)[0]
    agent.policy.net.evaluate(obs, actions)[0].sum().backward()
    assert prior.grad is not None and float(prior.grad.abs()) > 0
    torch.testing.assert_close(prior.detach().exp(), torch.tensor([10.0]))


@torch.no_grad()
def test_distinct_goals_give_each_fire_to_one_drone_and_are_scored_as_they_were_drawn():
    """planner.distinct_goals (thesis net): drones choose in id order from the fires no earlier drone took; with
    the strong prior, drone i takes the nearest free fire (greedy's rule), and evaluate() scores what forward_act
    drew with the same log-probs. With fewer fires than drones, the last drones share rather than go home."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(5)
    N, K = 3, 12
    obs = random_obs(64, N, K, g, n_valid=torch.randint(N + 2, K + 1, (64,), generator=g))
    net = ThesisPlannerNet(N, distance_prior=1000.0, distinct_goals=True)
    actions = net.forward_act(obs, deterministic=True)[0]
    taken = torch.zeros(64, K, dtype=torch.bool)
    for i in range(N):
        assert bool((actions[:, i] == nearest_valid(obs, taken)[:, i]).all()), f"drone {i}"
        taken.scatter_(1, actions[:, i:i + 1], True)

    sampler = ThesisPlannerNet(N, distinct_goals=True)
    drawn, log_prob, entropy, _ = sampler.forward_act(obs, generator=g)
    assert bool((drawn[:, 1:] != drawn[:, :1]).all()) and bool((drawn[:, 2] != drawn[:, 1]).all())
    again = sampler.evaluate(obs, drawn)
    torch.testing.assert_close(again[0], log_prob)
    torch.testing.assert_close(again[1], entropy)

    two_fires = random_obs(16, N, K, g, n_valid=torch.full((16,), 3))  # groundstation + 2 fires for 3 drones
    shared = sampler.forward_act(two_fires, generator=g)[0]
    assert bool((shared > 0).all()) and bool((shared[:, 0] != shared[:, 1]).all())


# ---------------------------------------------------------------------------------------------- any fleet


def permuted(obs: dict, order: torch.Tensor) -> dict:
    """The same scenes with the drones (axis 1 of the per-drone parts) in ``order``."""
    return {k: v[:, order] if k in ("drones", "goals", "water", "energy") else v for k, v in obs.items()}


def test_the_fleet_net_is_blind_to_the_drones_order():
    """Permuting the drones permutes their representations and goal scores, and leaves the value as it was: no drone
    is known by its index."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(11)
    net = FleetPlannerNet(num_drones=5)
    obs = random_obs(6, 5, 7, g)
    order = torch.tensor([3, 0, 4, 1, 2])
    d, fires, valid = net.encoder(obs)
    dp, _, _ = net.encoder(permuted(obs, order))
    assert torch.allclose(dp, d[:, order], atol=1e-5)
    assert torch.allclose(net.base_logits(dp, fires, permuted(obs, order)), net.base_logits(d, fires, obs)[:, order],
                          atol=1e-5)
    assert torch.allclose(net.value(permuted(obs, order)), net.value(obs), atol=1e-5)
    pointer = PointerPlannerNet(num_drones=5)  # the check can fail: the id embedding tells drones apart
    assert not torch.allclose(pointer.encoder(permuted(obs, order))[0], pointer.encoder(obs)[0][:, order], atol=1e-3)


def test_where_no_two_drones_want_one_fire_permuting_them_permutes_their_goals():
    """A strong distance prior sends each drone to the fire under it; drones on distinct fires want distinct fires,
    so the order of decoding decides nothing and the decisions follow the drones."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(12)
    N, K = 4, 8
    obs = random_obs(3, N, K, g, n_valid=torch.tensor([K, K, K]))
    obs["drones"] = obs["fires"][:, 1:N + 1].clone()  # drone i sits on candidate i + 1
    net = FleetPlannerNet(N, distance_prior=1000.0)
    order = torch.tensor([2, 0, 3, 1])
    actions = net.forward_act(obs, deterministic=True)[0]
    assert torch.equal(actions, torch.arange(1, N + 1).expand(3, -1))
    assert torch.equal(net.forward_act(permuted(obs, order), deterministic=True)[0], actions[:, order])


def test_one_fleet_net_flies_any_number_of_drones():
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(13)
    trained = FleetPlannerNet(num_drones=4)
    for n in (2, 4, 8, 16):
        other = FleetPlannerNet(num_drones=n)
        other.load_state_dict(trained.state_dict())  # the same weights whatever the fleet
        actions, log_prob, entropy, value = other.forward_act(random_obs(5, n, 20, g))
        assert actions.shape == (5, n) and log_prob.shape == value.shape == (5,)
        assert torch.isfinite(log_prob).all() and torch.isfinite(value).all()
    with pytest.raises(RuntimeError):  # an id-embedding net is built for one fleet size
        PointerPlannerNet(num_drones=8).load_state_dict(PointerPlannerNet(num_drones=4).state_dict())


def test_the_fleet_size_is_a_model_key_except_for_the_fleet_net():
    from roshan.checkpoints import config_differences, model_keys
    from roshan.config import ANY_FLEET_NETWORKS, load_config

    assert ANY_FLEET_NETWORKS == tuple(n for n, net in PLANNER_NETS.items() if getattr(net, "knows_ids", True) is False)
    for network, refused in (("pointer", True), ("fleet", False)):
        four = load_config(None, ["train.algo=planner", f"planner.network={network}", "drones.num_drones=4"])
        sixteen = load_config(None, ["train.algo=planner", f"planner.network={network}", "drones.num_drones=16"])
        diffs = config_differences(sixteen, four, model_keys(four))
        assert bool(diffs) is refused, (network, diffs)


def test_with_two_bases_the_thesis_net_offers_both_only_when_no_fire_is_listed():
    """``bases`` = 2: candidates 0 and 1 are the bases. Both are masked while a fire is listed, both offered when
    none is, and with distinct goals either may be taken by several drones."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    N, K = 3, 7
    net = ThesisPlannerNet(N, bases=2, distinct_goals=True)
    n_valid = torch.tensor([2, 3, 5, 7, 2, 4])
    obs = random_obs(6, N, K, g, n_valid)
    probs = net.probs(obs)
    allowed = torch.arange(K) < n_valid.unsqueeze(1)
    allowed[:, :2] = (n_valid == 2).unsqueeze(1)  # the bases only when no fire is listed
    assert bool((probs[~allowed.unsqueeze(1).expand_as(probs)] == 0).all())
    for _ in range(30):
        actions, logp, _, _ = net.forward_act(obs, generator=g)
        assert bool(allowed.gather(1, actions).all()) and bool(torch.isfinite(logp).all())
    logp_again = net.evaluate(obs, actions)[0]
    torch.testing.assert_close(logp_again, logp)


@torch.no_grad()
@pytest.mark.parametrize("net_cls", [PointerPlannerNet, FleetPlannerNet])
def test_with_two_bases_the_pointer_nets_let_either_base_repeat_and_take_each_fire_once(net_cls):
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(3)
    net = net_cls(3, bases=2)
    obs = random_obs(256, 3, 6, g, n_valid=torch.full((256,), 6))  # 4 fires for 3 drones
    d, fires, valid = net.encoder(obs, net.bases)
    base = net.base_logits(d, fires, obs)
    both = torch.ones(256, 3, dtype=torch.long)  # every drone to base 1
    logits = net.decode_logits(base, net.selectable(obs, valid), both)
    torch.testing.assert_close(logits[..., 1], base[..., 1] - net.penalty() * torch.arange(3.0))  # no mask
    torch.testing.assert_close(logits[..., 0], base[..., 0])
    net.log_penalty.fill_(-3.0)
    for _ in range(5):
        actions = net.forward_act(obs, generator=g)[0]
        for row in actions:
            fires_taken = row[row >= 2].tolist()
            assert len(fires_taken) == len(set(fires_taken))  # each fire once per decision
    assert bool(((actions == 1).sum(-1) >= 2).any() or ((actions == 0).sum(-1) >= 2).any())  # a base repeats
