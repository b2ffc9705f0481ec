"""SAC gradients against a straightforward reference: per-member ``F.linear`` MLPs, one autograd pass per loss.

The agent's networks use a hand-written backward pass (``vical.rl.networks._EnsembleMLPFunction``) that skips
unneeded gradients; these tests recompute every loss of one update from the same parameters and noise with
plain autograd and require every parameter's gradient to match.
"""

import pytest
import torch
from torch.nn import functional as F

from vical.rl.buffer import Batch
from vical.rl.networks import LOG_2, LOG_SQRT_2PI, EnsembleMLP, QNetworks
from vical.rl.sac import SAC, SACConfig

OBS, ACT, B = 3, 2, 64


def fixed_batch(seed: int = 7) -> Batch:
    g = torch.Generator().manual_seed(seed)
    return Batch(
        obs=torch.randn(B, OBS, generator=g),
        actions=torch.rand(B, ACT, generator=g) * 2 - 1,
        rewards=torch.randn(B, generator=g),
        next_obs=torch.randn(B, OBS, generator=g),
        terminated=(torch.rand(B, generator=g) < 0.2).float(),
        discounts=torch.rand(B, generator=g) * 0.5 + 0.5,
    )


def reference_mlp(params: dict[str, torch.Tensor], prefix: str, x: torch.Tensor, member: int) -> torch.Tensor:
    """Member ``member`` of an ``EnsembleMLP`` as a chain of ``F.linear`` and ReLU on batch-major ``x (B, in)``."""
    n = sum(1 for name in params if name.startswith(f"{prefix}.weights."))
    for i in range(n):
        w, b = params[f"{prefix}.weights.{i}"][member], params[f"{prefix}.biases.{i}"][member, :, 0]
        x = F.linear(x, w, b)
        if i < n - 1:
            x = F.relu(x)
    return x


def reference_gradients(agent: SAC, batch: Batch, generator_state: torch.Tensor) -> dict[str, torch.Tensor]:
    """Every trained parameter's gradient of the summed SAC losses, each loss differentiated on its own."""
    cfg = agent.config
    params = {name: p.detach().clone().requires_grad_(True) for name, p in agent.named_parameters() if p.requires_grad}
    target = {name: p.detach() for name, p in agent.v_target.named_parameters()}
    g = torch.Generator()
    g.set_state(generator_state)

    out = reference_mlp(params, "policy.mlp", batch.obs, 0)
    mean, log_std = out[:, :ACT], out[:, ACT:].clamp(cfg.log_std_min, cfg.log_std_max)
    noise = torch.randn(mean.shape, generator=g)
    u = mean + log_std.exp() * noise
    action = torch.tanh(u)
    log_prob = (-0.5 * noise**2 - log_std - LOG_SQRT_2PI - 2.0 * (LOG_2 - u - F.softplus(-2.0 * u))).sum(-1)
    alpha = params["log_alpha"].detach().exp() if cfg.auto_alpha else torch.tensor(float(cfg.alpha))

    frozen_q = {name: p.detach() for name, p in params.items()}  # the policy loss must not train Q
    q_new = (
        torch.stack(
            [reference_mlp(frozen_q, "q.mlp", torch.cat([batch.obs, action], -1), i)[:, 0] for i in range(cfg.n_q)]
        )
        .min(0)
        .values
    )
    v = reference_mlp(params, "v.mlp", batch.obs, 0)[:, 0]
    v_loss = 0.5 * ((v - (q_new - alpha * log_prob).detach()) ** 2).mean()
    with torch.no_grad():
        v_next = reference_mlp(target, "mlp", batch.next_obs, 0)[:, 0]
        q_hat = batch.rewards + cfg.gamma * batch.discounts * (1.0 - batch.terminated) * v_next
    q_loss = sum(
        0.5 * ((reference_mlp(params, "q.mlp", torch.cat([batch.obs, batch.actions], -1), i)[:, 0] - q_hat) ** 2).mean()
        for i in range(cfg.n_q)
    )
    policy_loss = (alpha * log_prob - q_new).mean()
    losses = [v_loss, q_loss, policy_loss]
    if cfg.auto_alpha:
        losses.append(-(params["log_alpha"] * (log_prob.detach() + agent.target_entropy)).mean())

    grads = {name: torch.zeros_like(p) for name, p in params.items()}
    for loss in losses:
        for name, grad in zip(params, torch.autograd.grad(loss, list(params.values()), allow_unused=True), strict=True):
            if grad is not None:
                grads[name] += grad
    return grads


@pytest.mark.parametrize(
    "settings",
    [
        {"n_q": 2, "alpha": "auto"},
        {"n_q": 1, "alpha": 1.0},
        {"n_q": 2, "alpha": "auto", "hidden_sizes": [32]},
        {"n_q": 2, "alpha": 0.2, "hidden_sizes": [16, 24, 8]},
    ],
)
def test_every_parameter_gradient_matches_the_reference_computation(settings):
    agent = SAC(OBS, ACT, SACConfig(**{"hidden_sizes": [32, 32], **settings}), seed=3)
    batch = fixed_batch()
    # one update first, so that the networks are not at their initial values (and V differs from V target)
    agent.update(fixed_batch(seed=8))
    expected = reference_gradients(agent, batch, agent.generator.get_state())
    losses, _ = agent.losses(batch)
    agent.optimizer.zero_grad(set_to_none=True)
    sum(losses.values()).backward()
    for name, p in agent.named_parameters():
        if not p.requires_grad:
            assert p.grad is None, name
            continue
        assert p.grad is not None and p.grad.dtype == torch.float32, name
        torch.testing.assert_close(p.grad, expected[name], rtol=1e-5, atol=1e-6, msg=name)


def test_mlp_input_and_weight_gradients_match_autograd_of_the_plain_network():
    mlp = EnsembleMLP(3, 5, [16, 16], 2, torch.Generator().manual_seed(0))
    x = torch.randn(3, 40, 5, generator=torch.Generator().manual_seed(1), requires_grad=True)
    weights = torch.randn(3, 40, 2, generator=torch.Generator().manual_seed(2))
    (mlp(x) * weights).sum().backward()
    params = {f"m.{name}": p.detach().clone().requires_grad_(True) for name, p in mlp.named_parameters()}
    x_ref = x.detach().clone().requires_grad_(True)
    out = torch.stack([reference_mlp(params, "m", x_ref[i], i) for i in range(3)])
    (out * weights).sum().backward()
    torch.testing.assert_close(x.grad, x_ref.grad, rtol=1e-5, atol=1e-6)
    for name, p in mlp.named_parameters():
        torch.testing.assert_close(p.grad, params[f"m.{name}"].grad, rtol=1e-5, atol=1e-6, msg=name)


def test_frozen_pass_gives_the_input_gradient_of_the_trained_pass():
    q = QNetworks(OBS, ACT, [32, 32], 2, torch.Generator().manual_seed(0))
    obs = torch.randn(B, OBS, generator=torch.Generator().manual_seed(1))
    actions = torch.rand(B, ACT, generator=torch.Generator().manual_seed(2)).requires_grad_(True)
    (grad_frozen,) = torch.autograd.grad(q(obs, actions, frozen=True).min(0).values.sum(), actions)
    (grad_trained,) = torch.autograd.grad(q(obs, actions).min(0).values.sum(), actions)
    assert torch.equal(grad_frozen, grad_trained)
    assert all(p.grad is None for p in q.parameters())
