"""SAC update: the paper's losses, one gradient step lowers each network's own loss, targets and temperature."""

import copy

import numpy as np
import pytest
import torch

from vical.config_checks import ConfigError, from_mapping
from vical.rl.buffer import Batch
from vical.rl.sac import SAC, NonFiniteLossError, SACConfig

OBS, ACT, B = 3, 2, 64


def make_agent(**overrides) -> SAC:
    settings = {"hidden_sizes": [32, 32], "lr": 1e-3, **overrides}
    return SAC(OBS, ACT, SACConfig(**settings), seed=0)


def fixed_batch(terminated: float = 0.0) -> Batch:
    g = torch.Generator().manual_seed(123)
    return Batch(
        obs=torch.randn(B, OBS, generator=g),
        actions=torch.rand(B, ACT, generator=g) * 2 - 1,
        rewards=torch.randn(B, generator=g),
        next_obs=torch.randn(B, OBS, generator=g),
        terminated=torch.full((B,), terminated),
        discounts=torch.rand(B, generator=g) * 0.5 + 0.5,
    )


def paper_losses(agent: SAC, batch: Batch, generator_state: torch.Tensor) -> dict[str, float]:
    """The three losses of Haarnoja et al. 2018 (eqs. 5, 7, 12), recomputed from the networks with fixed noise."""
    g = torch.Generator()
    g.set_state(generator_state)
    cfg, alpha = agent.config, agent.alpha
    with torch.no_grad():
        new_actions, log_prob = agent.policy.sample(batch.obs, g)
        q_new = agent.q(batch.obs, new_actions).min(0).values
        v_loss = 0.5 * ((agent.v(batch.obs) - (q_new - alpha * log_prob)) ** 2).mean()
        q_hat = batch.rewards + cfg.gamma * batch.discounts * (1 - batch.terminated) * agent.v_target(batch.next_obs)
        q_loss = sum(0.5 * ((q_i - q_hat) ** 2).mean() for q_i in agent.q(batch.obs, batch.actions))
        policy_loss = (alpha * log_prob - q_new).mean()
    return {"losses/v_loss": float(v_loss), "losses/q_loss": float(q_loss), "losses/policy_loss": float(policy_loss)}


@pytest.mark.parametrize("n_q, alpha", [(2, "auto"), (1, 1.0)])
def test_update_reports_the_papers_losses_at_the_pre_update_parameters(n_q, alpha):
    agent = make_agent(n_q=n_q, alpha=alpha)
    batch = fixed_batch()
    expected = paper_losses(agent, batch, agent.generator.get_state())
    stats = agent.update(batch)
    for name, value in expected.items():
        assert float(stats[name]) == pytest.approx(value, rel=1e-5), name
    assert ("losses/alpha_loss" in stats) == (alpha == "auto")


def test_terminal_transitions_regress_q_onto_the_reward_alone():
    agent = make_agent(n_q=1)
    batch = fixed_batch(terminated=1.0)
    q = agent.q(batch.obs, batch.actions).detach()[0]
    stats = agent.update(batch)
    assert float(stats["losses/q_loss"]) == pytest.approx(float(0.5 * ((q - batch.rewards) ** 2).mean()), rel=1e-6)


def with_params_of(base: SAC, source: SAC, module: str) -> SAC:
    """A copy of ``base`` whose ``module`` (policy, q or v) has ``source``'s parameters."""
    hybrid = copy.deepcopy(base)
    getattr(hybrid, module).load_state_dict(getattr(source, module).state_dict())
    return hybrid


@pytest.mark.parametrize("module, loss", [("v", "v_loss"), ("q", "q_loss"), ("policy", "policy_loss")])
def test_one_update_lowers_each_networks_own_loss(module, loss):
    before = make_agent()
    batch = fixed_batch()
    noise = before.generator.get_state()
    after = copy.deepcopy(before)
    after.update(batch)
    # only `module` takes its updated weights; every other network and target stays as it was
    hybrid = with_params_of(before, after, module)
    old = paper_losses(before, batch, noise)[f"losses/{loss}"]
    new = paper_losses(hybrid, batch, noise)[f"losses/{loss}"]
    assert new < old - 1e-4 * abs(old), (old, new)


def test_target_value_network_moves_by_tau_toward_the_updated_value_network():
    agent = make_agent(tau=0.25)
    old_target = [p.clone() for p in agent.v_target.parameters()]
    agent.update(fixed_batch())
    for t_old, t_new, v_new in zip(old_target, agent.v_target.parameters(), agent.v.parameters(), strict=True):
        torch.testing.assert_close(t_new, 0.75 * t_old + 0.25 * v_new)


def test_temperature_rises_when_entropy_is_below_target_and_falls_when_above():
    batch = fixed_batch()
    low_target = make_agent(target_entropy=-100.0)  # any policy's entropy exceeds it: alpha must fall
    high_target = make_agent(target_entropy=+100.0)
    low_stats, high_stats = low_target.update(batch), high_target.update(batch)
    # Adam's first step moves log(alpha) by lr against the gradient's sign
    assert float(low_target.alpha) == pytest.approx(float(low_stats["losses/alpha"]) * torch.e**-1e-3, rel=1e-4)
    assert float(high_target.alpha) == pytest.approx(float(high_stats["losses/alpha"]) * torch.e**1e-3, rel=1e-4)


def test_fixed_temperature_never_changes():
    agent = make_agent(alpha=0.2)
    for _ in range(3):
        stats = agent.update(fixed_batch())
    assert float(stats["losses/alpha"]) == pytest.approx(0.2) and "losses/alpha_loss" not in stats


def test_non_finite_loss_is_named_and_leaves_parameters_untouched():
    agent = make_agent()
    batch = fixed_batch()._replace(rewards=torch.full((B,), float("inf")))
    before = copy.deepcopy(agent.state_dict())
    with pytest.raises(NonFiniteLossError, match="losses/q_loss is inf") as err:
        agent.update(batch)
    assert err.value.term == "losses/q_loss"
    assert all(torch.equal(before[k], v) for k, v in agent.state_dict().items())


def policy_mean(agent: SAC, obs: torch.Tensor) -> torch.Tensor:
    """The policy's pre-squash mean ``(act_dim,)`` for one observation, by a plain forward pass of its weights.

    The policy MLP's output is ``[mean, log_std]``: the mean head is its first ``act_dim`` units.
    """
    mlp = agent.policy.mlp
    x = obs.double()
    for i, (w, b) in enumerate(zip(mlp.weights, mlp.biases, strict=True)):
        x = w[0].double() @ x + b[0, :, 0].double()
        if i < len(mlp.weights) - 1:
            x = x.relu()
    return x[:ACT]


def test_deterministic_action_is_the_squashed_mean_and_sampling_follows_the_seed():
    a, b = make_agent(), make_agent()
    for obs in fixed_batch().obs[:5]:
        expected = torch.tanh(policy_mean(a, obs)).detach().float().numpy()
        np.testing.assert_allclose(a.act(obs.numpy(), deterministic=True), expected, rtol=1e-5, atol=1e-6)
    obs = fixed_batch().obs[0].numpy()
    assert (a.act(obs) == b.act(obs)).all()  # same seed, same noise
    assert not (a.act(obs) == a.act(obs)).all()  # fresh noise on every call


def networks_reached(agent: SAC, loss: torch.Tensor) -> set[str]:
    """Names of the networks whose parameters get a non-zero gradient from ``loss``."""
    networks = {"q": agent.q, "v": agent.v, "policy": agent.policy, "v_target": agent.v_target}
    params = {name: list(net.parameters()) for name, net in networks.items()}
    if agent.config.auto_alpha:
        params["log_alpha"] = [agent.log_alpha]
    reached = set()
    for name, ps in params.items():
        grads = torch.autograd.grad(loss, ps, retain_graph=True, allow_unused=True)
        if any(g is not None and bool(g.abs().sum() > 0) for g in grads):
            reached.add(name)
    return reached


@pytest.mark.parametrize("n_q, alpha", [(2, "auto"), (1, 1.0)])
def test_each_loss_reaches_only_the_network_it_trains(n_q, alpha):
    agent = make_agent(n_q=n_q, alpha=alpha)
    # let the target V take gradients here, so any path from a loss into it would show up
    agent.v_target.requires_grad_(True)
    losses, _ = agent.losses(fixed_batch())
    reached = {name: networks_reached(agent, loss) for name, loss in losses.items()}
    expected = {"losses/v_loss": {"v"}, "losses/q_loss": {"q"}, "losses/policy_loss": {"policy"}}
    if alpha == "auto":
        expected["losses/alpha_loss"] = {"log_alpha"}
    assert reached == expected


def test_target_value_network_is_never_trained():
    agent = make_agent()
    assert not any(p.requires_grad for p in agent.v_target.parameters())
    optimised = {id(p) for group in agent.optimizer.param_groups for p in group["params"]}
    assert not optimised & {id(p) for p in agent.v_target.parameters()}
    agent.update(fixed_batch())
    assert all(p.grad is None for p in agent.v_target.parameters())


@pytest.mark.parametrize(
    "setting, message",
    [
        ({"gamma": 1.0}, r"agent\.gamma must be a number in \[0\.0, 1\.0\), got 1\.0"),
        ({"tau": 0.0}, r"agent\.tau must be a number in \(0\.0, 1\.0\]"),
        ({"n_q": 3}, r"agent\.n_q must be 1 \(one Q network\) or 2"),
        ({"alpha": -0.1}, r"agent\.alpha must be a number in \[0\.0, inf\)"),
        ({"hidden_sizes": []}, r"agent\.hidden_sizes must be a non-empty list"),
        ({"batch_size": 0}, r"agent\.batch_size must be an integer >= 1"),
        ({"log_std_min": 3.0}, r"agent\.log_std_max must be a number in \(3\.0, inf\)"),
        ({"gama": 0.9}, r"agent: unknown setting\(s\) \['gama'\]"),
        (
            {"hidden_precision": "float16"},
            r"agent\.hidden_precision must be one of \['bfloat16', 'bfloat16_backward', 'float32'\]",
        ),
    ],
)
def test_bad_settings_fail_naming_the_key(setting, message):
    with pytest.raises(ConfigError, match=message):
        from_mapping(SACConfig, setting, "agent")
