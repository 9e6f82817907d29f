"""FlyAgent networks: shapes, masking, the NoNeighbor case and the reference initialisation."""

import math

import pytest
import torch

from roshan.algos.networks import ActorCritic, CollisionEncoder, SimpleEncoder, layer_init


def fake_obs(b=5, t=3, k=4, valid=True):
    g = torch.Generator().manual_seed(0)
    return {"agent": torch.randn(b, t, 9, generator=g), "neighbors": torch.randn(b, t, k, 4, generator=g),
            "neighbors_mask": torch.full((b, t, k), 1.0 if valid else 0.0)}


@pytest.mark.parametrize("enc", [SimpleEncoder(), CollisionEncoder()], ids=["simple", "collision"])
def test_encoders_give_192_features(enc):
    assert enc(fake_obs()).shape == (5, 192) and enc.out_features == 192


def test_simple_encoder_reads_only_velocity_and_goal_delta():
    enc = SimpleEncoder()
    a = fake_obs()
    b = {k: v.clone() for k, v in a.items()}
    b["agent"][..., [0, 5, 6, 7, 8]] += 3.0
    b["neighbors"] += 1.0
    assert torch.equal(enc(a), enc(b))


def test_invalid_neighbour_slots_do_not_matter():
    enc = CollisionEncoder()
    obs = fake_obs()
    obs["neighbors_mask"][:, :, 2:] = 0.0
    other = {k: v.clone() for k, v in obs.items()}
    other["neighbors"][:, :, 2:] = 100.0
    torch.testing.assert_close(enc(obs), enc(other))


def test_no_valid_neighbour_pools_to_zero_without_nan():
    enc = CollisionEncoder()
    out = enc(fake_obs(valid=False))
    assert torch.isfinite(out).all()
    obs = fake_obs(valid=False)
    other = {k: v.clone() for k, v in obs.items()}
    other["neighbors"] += 5.0
    torch.testing.assert_close(enc(obs), enc(other))


def test_initialisation_gains_and_zero_bias():
    torch.manual_seed(0)
    layer = layer_init(torch.nn.Linear(64, 64), gain=0.1)
    w = layer.weight.detach()
    torch.testing.assert_close(w @ w.T, 0.01 * torch.eye(64), atol=1e-5, rtol=0)
    assert torch.count_nonzero(layer.bias) == 0
    net = ActorCritic(collision=True)
    assert torch.equal(net.log_std, torch.zeros(2))
    mu_w = net.mu.weight.detach()
    torch.testing.assert_close(mu_w @ mu_w.T, 0.01 * torch.eye(2), atol=1e-5, rtol=0)
    hidden = net.encoder.own[0].weight.detach()  # (256, 9): orthogonal columns scaled by sqrt(2)
    torch.testing.assert_close(hidden.T @ hidden, 2.0 * torch.eye(9), atol=1e-4, rtol=0)
    assert math.isclose(float(net.value.weight.norm()), 1.0, rel_tol=1e-5)


def test_actor_critic_shapes_and_sharing():
    shared, own = ActorCritic(collision=True), ActorCritic(collision=True, share_encoder=False)
    mean, std = shared.actor(fake_obs())
    assert mean.shape == (5, 2) and std.shape == (2,) and mean.abs().max() < 1
    assert shared.critic(fake_obs()).shape == (5,)
    n_shared = sum(p.numel() for p in shared.parameters())
    n_own = sum(p.numel() for p in own.parameters())
    assert n_own > n_shared


def test_a_seeded_agent_leaves_torch_global_rng_as_it_was():
    """make_agent(seed=) draws the initial weights from the seed alone (the same as after torch.manual_seed(seed)),
    and the caller's global stream goes on as if nothing had been drawn."""
    from roshan.algos.agents import make_agent
    from roshan.config import Config

    torch.manual_seed(123)
    expected_next = torch.rand(3)
    torch.manual_seed(7)
    plain = make_agent(Config()).state_dict()["net"]
    torch.manual_seed(123)
    seeded = make_agent(Config(), seed=7).state_dict()["net"]
    assert torch.equal(torch.rand(3), expected_next)
    assert plain.keys() == seeded.keys()
    assert all(torch.equal(plain[k], seeded[k]) for k in plain)
    other = make_agent(Config(), seed=8).state_dict()["net"]
    assert not all(torch.equal(plain[k], other[k]) for k in plain)
