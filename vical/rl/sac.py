"""Soft Actor-Critic with a state-value network (Haarnoja, Zhou, Abbeel, Levine 2018, "Soft Actor-Critic:
Off-Policy Maximum Entropy Deep Reinforcement Learning with a Stochastic Actor", arXiv:1801.01290).

The paper's algorithm (its Algorithm 1, "SAC v1"): a soft Q-function, a state-value function V with a
Polyak-averaged target V, and a reparameterised tanh-Gaussian policy. Options beyond the paper, each
off in the authors' configuration: two Q networks with the minimum in the V and policy targets
(clipped double-Q, as in the paper's experiments and code), and an entropy temperature tuned toward a
target entropy (Haarnoja et al. 2018b, arXiv:1812.05905) instead of a fixed ``alpha``.

Departures from the paper, all deliberate:
- All losses are evaluated at the same parameters and stepped by one Adam optimiser (one parameter
  group per network); Adam's state is per parameter, so this equals the paper's separate optimisers
  with simultaneous updates, which is what the authors' TensorFlow code ran.
- No L2 regulariser on the policy's mean and log-std (the authors' code had 1e-3); the clamp on
  log-std keeps it bounded.
- The log-probability is that of the squashed action in ``[-1, 1]``; the affine map to the env's
  action bounds is a constant shift of the entropy and is left out, as in the authors' code.
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import Tensor, nn

from vical.config_checks import ConfigError, require, require_range
from vical.rl.buffer import Batch
from vical.rl.networks import QNetworks, TanhGaussianPolicy, ValueNetwork

# hidden_precision -> dtypes of the hidden-to-hidden matmuls (forward pass, backward pass)
HIDDEN_PRECISIONS = {
    "float32": (torch.float32, torch.float32),
    "bfloat16": (torch.bfloat16, torch.bfloat16),
    "bfloat16_backward": (torch.float32, torch.bfloat16),
}


@dataclass
class SACConfig:
    """Hyperparameters of :class:`SAC` (the defaults are documented and measured in ``docs/rl.md``).

    alpha: entropy temperature, a non-negative number (fixed; 0 = no entropy term) or ``"auto"`` (tuned
    toward ``target_entropy``, default ``-act_dim``, starting from ``init_alpha``).
    hidden_precision: dtype of the hidden-to-hidden matmuls (see ``EnsembleMLP``): ``float32``, ``bfloat16``
    (forward and backward passes; about 4x faster matmuls on CPUs with AVX512-BF16, much slower on CPUs
    without it) or ``bfloat16_backward`` (float32 forward pass, so exact losses and targets, and bfloat16
    gradient matmuls: two thirds of the FLOPs).
    """

    hidden_sizes: list[int] = field(default_factory=lambda: [256, 256])
    gamma: float = 0.99
    tau: float = 0.005
    lr: float = 3e-4
    batch_size: int = 256
    n_q: int = 2
    alpha: float | str = "auto"
    init_alpha: float = 1.0
    target_entropy: float | None = None
    log_std_min: float = -20.0
    log_std_max: float = 2.0
    hidden_precision: str = "float32"

    def __post_init__(self) -> None:
        self.hidden_sizes = list(self.hidden_sizes)
        require(
            len(self.hidden_sizes) > 0 and all(isinstance(h, int) and h > 0 for h in self.hidden_sizes),
            "agent.hidden_sizes",
            "a non-empty list of positive layer widths",
            self.hidden_sizes,
        )
        require_range("agent.gamma", self.gamma, 0.0, 1.0, high_open=True)
        require_range("agent.tau", self.tau, 0.0, 1.0, low_open=True)
        require_range("agent.lr", self.lr, 0.0, 1.0, low_open=True)
        ok_batch = isinstance(self.batch_size, int) and self.batch_size >= 1
        require(ok_batch, "agent.batch_size", "an integer >= 1", self.batch_size)
        require(self.n_q in (1, 2), "agent.n_q", "1 (one Q network) or 2 (clipped double-Q)", self.n_q)
        if self.alpha != "auto":
            require_range("agent.alpha", self.alpha, 0.0, None)
        require_range("agent.init_alpha", self.init_alpha, 0.0, None, low_open=True)
        if self.target_entropy is not None:
            require_range("agent.target_entropy", self.target_entropy)
        require_range("agent.log_std_max", self.log_std_max, self.log_std_min, None, low_open=True)
        require(
            self.hidden_precision in HIDDEN_PRECISIONS,
            "agent.hidden_precision",
            f"one of {sorted(HIDDEN_PRECISIONS)}",
            self.hidden_precision,
        )

    @property
    def auto_alpha(self) -> bool:
        return self.alpha == "auto"


class NonFiniteLossError(FloatingPointError):
    """A loss became NaN or infinite; ``term`` names it (e.g. ``losses/q_loss``)."""

    def __init__(self, term: str, value: float) -> None:
        super().__init__(f"{term} is {value}")
        self.term = term
        self.value = value


class SAC(nn.Module):
    """The agent: ``update(batch)`` performs one gradient step of every network; ``act`` picks actions.

    Actions are in ``[-1, 1]^act_dim``; the caller maps them to the env's bounds.
    """

    def __init__(self, obs_dim: int, act_dim: int, config: SACConfig, seed: int) -> None:
        super().__init__()
        if obs_dim < 1 or act_dim < 1:
            raise ConfigError(f"SAC needs obs_dim >= 1 and act_dim >= 1, got obs_dim={obs_dim}, act_dim={act_dim}")
        self.config = config
        self.generator = torch.Generator().manual_seed(seed)
        hidden, dtypes = config.hidden_sizes, HIDDEN_PRECISIONS[config.hidden_precision]
        self.policy = TanhGaussianPolicy(
            obs_dim, act_dim, hidden, config.log_std_min, config.log_std_max, self.generator, *dtypes
        )
        self.q = QNetworks(obs_dim, act_dim, hidden, config.n_q, self.generator, *dtypes)
        self.v = ValueNetwork(obs_dim, hidden, self.generator, *dtypes)
        self.v_target = copy.deepcopy(self.v).requires_grad_(False)
        if config.auto_alpha:
            self.log_alpha = nn.Parameter(torch.tensor(math.log(config.init_alpha)))
        self.target_entropy = float(-act_dim if config.target_entropy is None else config.target_entropy)
        # One optimiser over every trained parameter (the target V is a buffer-like copy, not trained):
        # Adam's state is per parameter, so this is the paper's separate optimisers in one fused call.
        trained = [p for p in self.parameters() if p.requires_grad]
        self.optimizer = torch.optim.Adam(trained, lr=config.lr, fused=True)

    @property
    def alpha(self) -> Tensor:
        """The current temperature as a detached scalar (exactly ``config.alpha`` when fixed)."""
        if not self.config.auto_alpha:
            return torch.tensor(float(self.config.alpha))
        return self.log_alpha.detach().exp()

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool = False) -> np.ndarray:
        """Action ``(act_dim,)`` in ``[-1, 1]`` for one observation ``(obs_dim,)``: a sample, or the mean."""
        obs_t = torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)
        if deterministic:
            action = self.policy.deterministic(obs_t)
        else:
            action = self.policy.sample(obs_t, self.generator)[0]
        return action[0].numpy()

    def losses(self, batch: Batch, clone: bool = False) -> tuple[dict[str, Tensor], dict[str, Tensor]]:
        """The losses of one update at the current parameters, with their autograd graphs, and diagnostics.

        ``clone``: the batch's actions are a demonstrator's, and the policy's loss clones them: their negative
        log-likelihood under the policy, with the same entropy term (``alpha log pi`` of the policy's own sample,
        alpha tuned as always), so the policy's mean follows the demonstrations while its spread stays at the
        target entropy. The value and Q losses are SAC's: they learn the value of the policy being cloned.

        Returns ``(losses, diagnostics)``: ``losses`` maps ``losses/v_loss``, ``losses/q_loss``,
        ``losses/policy_loss`` (and ``losses/alpha_loss`` with ``alpha: auto``) to scalar tensors, each of
        which reaches only the parameters it trains; ``diagnostics`` holds detached ``losses/alpha``,
        ``losses/entropy`` and ``losses/q_mean``. Draws the policy noise from the agent's generator.
        """
        cfg, alpha = self.config, self.alpha

        # Policy sample a ~ pi(.|s), reparameterised (eq. 11), and min_i Q_i(s, a) through frozen Q weights:
        # it drives the policy and is the V target, but must not train Q.
        new_actions, log_prob = self.policy.sample(batch.obs, self.generator)
        q_new = self.q(batch.obs, new_actions, frozen=True).min(0).values

        # V (eq. 5): regress V(s) onto E_a[min Q(s, a) - alpha log pi(a|s)].
        v = self.v(batch.obs)
        v_loss = 0.5 * (v - (q_new - alpha * log_prob).detach()).square().mean()

        # Q (eqs. 7-8): regress each Q_i(s, a) onto r + gamma d (1 - terminated) V_target(s'), d the
        # transition's own discount (1 for an ordinary step).
        with torch.no_grad():
            continuation = cfg.gamma * batch.discounts * (1.0 - batch.terminated)
            q_target = batch.rewards + continuation * self.v_target(batch.next_obs)
        q = self.q(batch.obs, batch.actions)
        q_loss = 0.5 * (q - q_target).square().mean(1).sum()

        # Policy (eq. 12): minimise E[alpha log pi(a|s) - min Q(s, a)]; cloning: E[alpha log pi(a|s)] - log pi(a_d|s).
        if clone:
            policy_loss = (alpha * log_prob).mean() - self.policy.log_prob(batch.obs, batch.actions).mean()
        else:
            policy_loss = (alpha * log_prob - q_new).mean()

        losses = {"losses/v_loss": v_loss, "losses/q_loss": q_loss, "losses/policy_loss": policy_loss}
        if cfg.auto_alpha:
            # Temperature: raise alpha while the entropy -log pi is below the target, lower it above.
            losses["losses/alpha_loss"] = -(self.log_alpha * (log_prob.detach() + self.target_entropy)).mean()
        diagnostics = {
            "losses/alpha": alpha,
            "losses/entropy": -log_prob.detach().mean(),
            "losses/q_mean": q.detach().mean(),
        }
        return losses, diagnostics

    def update(self, batch: Batch, clone: bool = False) -> dict[str, Tensor]:
        """One gradient step on a minibatch (``clone``: cloning its actions, ``losses``); returns the detached losses
        and diagnostics (tensors, no sync).

        Raises :class:`NonFiniteLossError` before any parameter changes if a loss is NaN or infinite.
        """
        losses, diagnostics = self.losses(batch, clone)
        total = sum(losses.values())
        _require_finite(total, losses)

        self.optimizer.zero_grad(set_to_none=True)
        total.backward()
        self.optimizer.step()
        with torch.no_grad():
            torch._foreach_lerp_(list(self.v_target.parameters()), list(self.v.parameters()), self.config.tau)

        return {k: l.detach() for k, l in losses.items()} | diagnostics

    def training_state(self) -> dict:
        """Networks, optimiser and the sampling generator: everything to continue updates exactly."""
        return {
            "model": self.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "generator": self.generator.get_state(),
            "config": asdict(self.config),
        }

    def load_training_state(self, state: dict) -> None:
        """Restore from :meth:`training_state`."""
        self.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])


def _require_finite(total: Tensor, losses: dict[str, Tensor]) -> None:
    if torch.isfinite(total):
        return
    for name, value in losses.items():
        if not torch.isfinite(value):
            raise NonFiniteLossError(name, float(value.detach()))
    raise NonFiniteLossError("losses/total", float(total.detach()))
