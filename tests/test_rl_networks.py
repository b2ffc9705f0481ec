"""Networks: tanh-Gaussian log-density against numerical references, log-std clamp, frozen critics, seeding."""

import numpy as np
import torch
from scipy.stats import norm

from vical.rl.networks import EnsembleMLP, QNetworks, TanhGaussianPolicy, squashed_gaussian_log_prob


def reference_log_density(a: np.ndarray, mean: np.ndarray, std: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """log p(a) of a = tanh(u), u ~ N(mean, std), as the central difference of the CDF Phi((atanh a - mean) / std)."""
    cdf = lambda x: norm.cdf((np.arctanh(x) - mean) / std)  # noqa: E731
    return np.log((cdf(a + h) - cdf(a - h)) / (2 * h)).sum(-1)


def test_log_prob_matches_the_numerical_derivative_of_the_squashed_cdf():
    rng = np.random.default_rng(0)
    mean = rng.normal(0.0, 1.0, (200, 3))
    log_std = rng.uniform(-1.5, 0.5, (200, 3))
    noise = rng.normal(size=(200, 3))
    pre_tanh = mean + np.exp(log_std) * noise
    ours = squashed_gaussian_log_prob(*(torch.tensor(x) for x in (noise, log_std, pre_tanh))).numpy()
    ref = reference_log_density(np.tanh(pre_tanh), mean, np.exp(log_std))
    np.testing.assert_allclose(ours, ref, rtol=1e-5, atol=1e-5)


def test_log_prob_stays_accurate_in_float32_where_tanh_saturates():
    # u = 9: 1 - tanh(u)^2 = 6e-8 underflows to 0 in float32 (a naive log(1 - a^2) gives +inf density)
    pre_tanh = np.array([[9.0, -12.0, 0.3]])
    noise = np.array([[0.5, -1.0, 0.1]])
    log_std = np.array([[0.2, -0.3, -1.0]])
    ours = squashed_gaussian_log_prob(*(torch.tensor(x, dtype=torch.float32) for x in (noise, log_std, pre_tanh)))
    # reference in float64 through the identity 1 - tanh(u)^2 = 1 / cosh(u)^2
    gaussian = norm.logpdf(noise) - log_std
    ref = (gaussian + 2.0 * np.log(np.cosh(pre_tanh))).sum(-1)
    np.testing.assert_allclose(ours.numpy(), ref, rtol=1e-6)


def test_policy_sample_is_squashed_and_its_log_prob_is_the_density_of_the_sample():
    policy = TanhGaussianPolicy(4, 2, [32, 32], -20.0, 2.0, torch.Generator().manual_seed(0))
    obs = torch.randn(500, 4, generator=torch.Generator().manual_seed(1))
    actions, log_prob = policy.sample(obs, torch.Generator().manual_seed(2))
    assert actions.shape == (500, 2) and log_prob.shape == (500,)
    assert actions.abs().max() < 1.0
    mean, log_std = policy.distribution(obs)
    ref = reference_log_density(
        actions.detach().double().numpy(), mean.detach().double().numpy(), log_std.detach().exp().double().numpy()
    )
    np.testing.assert_allclose(log_prob.detach().numpy(), ref, rtol=2e-3, atol=2e-3)
    assert torch.equal(policy.deterministic(obs), torch.tanh(mean))


def test_log_std_is_clamped_to_its_bounds():
    policy = TanhGaussianPolicy(3, 1, [8], -5.0, 2.0, torch.Generator().manual_seed(0))
    with torch.no_grad():
        policy.mlp.biases[-1][:, 1] = 50.0  # log-std head far above the upper bound
        assert torch.all(policy.distribution(torch.zeros(4, 3))[1] == 2.0)
        policy.mlp.biases[-1][:, 1] = -50.0
        assert torch.all(policy.distribution(torch.zeros(4, 3))[1] == -5.0)


def test_frozen_critic_passes_gradient_to_actions_but_not_to_its_weights():
    q = QNetworks(3, 2, [16, 16], n_q=2, generator=torch.Generator().manual_seed(0))
    actions = torch.zeros(5, 2, requires_grad=True)
    q(torch.ones(5, 3), actions, frozen=True).sum().backward()
    assert actions.grad is not None and actions.grad.abs().sum() > 0
    assert all(p.grad is None for p in q.parameters())


def test_ensemble_members_are_independent_networks():
    mlp = EnsembleMLP(2, 3, [8], 1, torch.Generator().manual_seed(0))
    x = torch.randn(6, 3, generator=torch.Generator().manual_seed(1))
    out = mlp(x)
    assert out.shape == (2, 6, 1) and not torch.allclose(out[0], out[1])
    with torch.no_grad():
        mlp.weights[0][1] += 1.0  # change member 1 only
    changed = mlp(x)
    assert torch.equal(changed[0], out[0]) and not torch.allclose(changed[1], out[1])


def test_initialisation_depends_only_on_the_generator_seed():
    make = lambda seed: QNetworks(3, 1, [16], 2, torch.Generator().manual_seed(seed))  # noqa: E731
    a, b, c = make(5), make(5), make(6)
    assert all(torch.equal(x, y) for x, y in zip(a.parameters(), b.parameters(), strict=True))
    assert not torch.equal(next(a.parameters()), next(c.parameters()))
    bound = 1 / np.sqrt(4)  # PyTorch's nn.Linear bound 1/sqrt(fan_in), fan_in = obs 3 + action 1
    assert a.mlp.weights[0].abs().max() <= bound


def test_bfloat16_hidden_layers_stay_close_to_float32_and_keep_float32_parameters_and_outputs():
    make = lambda dtype: QNetworks(3, 2, [64, 64], 2, torch.Generator().manual_seed(0), dtype)  # noqa: E731
    exact, fast = make(torch.float32), make(torch.bfloat16)
    obs = torch.randn(128, 3, generator=torch.Generator().manual_seed(1))
    actions = torch.rand(128, 2, generator=torch.Generator().manual_seed(2)) * 2 - 1
    q_exact, q_fast = exact(obs, actions), fast(obs, actions)
    assert q_fast.dtype == torch.float32
    # bfloat16 keeps 8 mantissa bits: ~0.4 % per rounding, averaged over 64 hidden units
    scale = q_exact.abs().max()
    assert (q_fast - q_exact).abs().max() < 0.02 * scale and (q_fast - q_exact).abs().max() > 0
    q_fast.sum().backward()
    assert all(p.dtype == torch.float32 and p.grad.dtype == torch.float32 for p in fast.parameters())


def test_bfloat16_backward_keeps_the_float32_forward_pass_and_rounds_only_the_gradients():
    make = lambda grad_dtype: QNetworks(3, 2, [64, 64], 2, torch.Generator().manual_seed(0), grad_dtype=grad_dtype)  # noqa: E731
    exact, fast = make(None), make(torch.bfloat16)
    obs = torch.randn(128, 3, generator=torch.Generator().manual_seed(1))
    actions = torch.rand(128, 2, generator=torch.Generator().manual_seed(2)) * 2 - 1
    q_exact, q_fast = exact(obs, actions), fast(obs, actions)
    assert torch.equal(q_exact, q_fast)
    q_exact.square().sum().backward()
    q_fast.square().sum().backward()
    for p_exact, p_fast in zip(exact.parameters(), fast.parameters(), strict=True):
        assert p_fast.grad.dtype == torch.float32
        scale = p_exact.grad.abs().max()
        assert (p_fast.grad - p_exact.grad).abs().max() < 0.03 * scale
    assert any(not torch.equal(p.grad, q.grad) for p, q in zip(exact.parameters(), fast.parameters(), strict=True))
