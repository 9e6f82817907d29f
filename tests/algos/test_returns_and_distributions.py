"""GAE against a naive loop and a hand-worked example; the action distributions' densities."""

import math

import pytest
import torch

from roshan.algos.distributions import ClippedGaussian, TanhNormal
from roshan.algos.returns import gae


def naive_gae(r, v, nv, term, trunc, gamma, lam):
    T, B = r.shape
    adv = torch.zeros(T, B)
    for b in range(B):
        a = 0.0
        for t in reversed(range(T)):
            boot = 0.0 if term[t, b] else nv[t, b]
            delta = r[t, b] + gamma * boot - v[t, b]
            carry = 0.0 if (term[t, b] or trunc[t, b]) else a
            a = delta + gamma * lam * carry
            adv[t, b] = a
    return adv


def test_gae_matches_a_naive_loop():
    g = torch.Generator().manual_seed(0)
    T, B = 17, 5
    r, v, nv = (torch.randn(T, B, generator=g) for _ in range(3))
    term = torch.rand(T, B, generator=g) < 0.15
    trunc = (torch.rand(T, B, generator=g) < 0.1) & ~term
    adv, ret = gae(r, v, nv, term, trunc, 0.99, 0.95)
    torch.testing.assert_close(adv, naive_gae(r, v, nv, term, trunc, 0.99, 0.95))
    torch.testing.assert_close(ret, adv + v)


def test_gae_hand_worked_example_with_truncation():
    # One env, 3 steps; the episode is truncated at t = 1 (bootstrap from V(final_obs) = 2.0) and the next
    # episode runs on at t = 2 (bootstrap 0.5). gamma = 0.5, lambda = 0.5.
    r = torch.tensor([[1.0], [0.0], [1.0]])
    v = torch.tensor([[1.0], [1.0], [1.0]])
    nv = torch.tensor([[1.0], [2.0], [0.5]])
    term = torch.zeros(3, 1, dtype=torch.bool)
    trunc = torch.tensor([[False], [True], [False]])
    adv, _ = gae(r, v, nv, term, trunc, 0.5, 0.5)
    # delta = r + 0.5 * nv - v: [0.5, 0.0, 0.25]; A2 = 0.25; A1 = 0.0 (trace cut); A0 = 0.5 + 0.25 * 0.0
    torch.testing.assert_close(adv, torch.tensor([[0.5], [0.0], [0.25]]))
    term[1] = True  # the same step as a real termination: no bootstrap at all
    adv, _ = gae(r, v, nv, term, torch.zeros_like(term), 0.5, 0.5)
    torch.testing.assert_close(adv[1], torch.tensor([-1.0]))


def test_tanh_normal_log_prob_is_the_change_of_variables():
    mu, std = torch.tensor([[0.3, -1.2]]), torch.tensor([0.7, 0.4])
    dist = TanhNormal(mu, std)
    a = torch.tensor([[0.2, -0.9]])
    u = torch.atanh(a)
    base = torch.distributions.Normal(mu, std).log_prob(u)
    h = 1e-6  # |da/du| by central differences
    jac = (torch.tanh(u.double() + h) - torch.tanh(u.double() - h)) / (2 * h)
    expected = (base.double() - torch.log(jac)).sum(-1)
    torch.testing.assert_close(dist.log_prob(a).double(), expected, atol=1e-5, rtol=0)


def test_tanh_normal_is_finite_at_the_bounds_and_integrates_to_one():
    dist = TanhNormal(torch.tensor([[2.5]]), torch.tensor([0.3]))
    edge = dist.log_prob(torch.tensor([[1.0]]))
    assert torch.isfinite(edge)
    xs = torch.linspace(-1 + 1e-7, 1 - 1e-7, 400_001).unsqueeze(-1)
    dens = TanhNormal(torch.tensor([[0.4]]).expand(len(xs), 1), torch.tensor([0.5])).log_prob(xs).exp()
    assert float(torch.trapezoid(dens, xs.squeeze(-1))) == pytest.approx(1.0, abs=1e-3)
    s = dist.rsample()
    assert s.abs().max() < 1 and s.requires_grad is False


def test_clipped_gaussian_uses_the_clamped_action():
    dist = ClippedGaussian(torch.tensor([[0.9, 0.0]]), torch.tensor([1.0, 1.0]))
    lp = dist.log_prob(torch.tensor([[3.0, 0.0]]))
    expected = torch.distributions.Normal(torch.tensor([0.9, 0.0]), 1.0).log_prob(torch.tensor([1.0, 0.0])).sum()
    torch.testing.assert_close(lp, expected.unsqueeze(0))
    assert dist.sample().abs().max() <= 1.0
    assert dist.entropy().item() == pytest.approx(2 * (0.5 * math.log(2 * math.pi * math.e)))


@pytest.mark.parametrize("mu, std", [(0.0, 1.0), (2.0, 0.85), (5.0, 0.85), (-3.0, 0.3)])
def test_squashed_entropy_is_the_entropy_of_the_actions(mu, std):
    # H[tanh(u)] = -E[log p(a)] by Monte Carlo over a million samples, against the quadrature.
    d = TanhNormal(torch.tensor([[mu, mu]]), torch.tensor([std, std]))
    u = d.base.sample((1_000_000,))[:, 0]
    mc = -d.log_prob_raw(u).mean() / 2  # averaged over the two dimensions, as entropy() is
    assert float(d.squashed_entropy()[0]) == pytest.approx(float(mc), abs=0.01)


def test_squashed_entropy_pulls_a_saturated_mean_back_where_the_base_entropy_does_not():
    mu = torch.tensor([[4.0, -4.0]], requires_grad=True)
    d = TanhNormal(mu, torch.tensor([0.85, 0.85]))
    assert float(d.squashed_entropy()[0]) < float(d.entropy()[0]) - 2.0
    d.squashed_entropy().sum().backward()
    assert mu.grad[0, 0] < 0 < mu.grad[0, 1]  # ascending the bonus moves both means towards 0
    assert not d.entropy().requires_grad  # the base entropy does not depend on the mean at all


def test_the_written_out_gauss_hermite_rule_is_numpys_and_integrates_polynomials_exactly():
    """The 5-node rule is written out (numpy's LAPACK would compute it with CPU-chosen kernels at import): it must be
    numpy's rule, and integrate E[Z^k] of a standard normal exactly up to degree 9."""
    import numpy as np

    from roshan.algos import distributions as d

    x, w = np.polynomial.hermite.hermgauss(5)
    np.testing.assert_allclose(d._GH_X, x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(d._GH_W, w, rtol=0, atol=1e-15)
    nodes, weights = d._GH_X * math.sqrt(2.0), d._GH_W / math.sqrt(math.pi)
    for k, moment in enumerate([1, 0, 1, 0, 3, 0, 15, 0, 105, 0]):
        assert float(np.sum(weights * nodes ** k)) == pytest.approx(moment, abs=1e-12)
