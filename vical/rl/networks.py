"""Networks of Soft Actor-Critic: ensembles of MLPs, Q and V critics, the tanh-squashed Gaussian policy.

Every network is an *ensemble* of ``E`` independent MLPs evaluated in one batched matmul per layer
(``torch.baddbmm``): the two Q networks of clipped double-Q cost one call per layer instead of two.
Inside, activations are feature-major, ``(E, features, B)``, and weights ``(E, out, in)`` (as
``nn.Linear``): with MKL on this project's CPUs that layout made the narrow output layers (1 or a few
units) ~4x faster than batch-major ``(E, B, features)``.
Weights are initialised from an explicit ``torch.Generator`` (PyTorch's default ``nn.Linear`` bounds,
``U(-1/sqrt(fan_in), 1/sqrt(fan_in))``), so construction never touches the global RNG.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import torch
from torch import Tensor, nn
from torch.nn import functional as F

LOG_2 = math.log(2.0)
LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


class EnsembleMLP(nn.Module):
    """``E`` independent ReLU MLPs ``in_dim -> hidden... -> out_dim``; input ``(B, in)`` or ``(E, B, in)``.

    Output shape ``(E, B, out_dim)``. ``frozen=True`` evaluates with detached weights: gradients flow
    to the input (e.g. the policy's action) but never into this network's parameters.

    ``hidden_dtype``: the dtype of the hidden-to-hidden matmuls of the forward pass, ``grad_dtype`` (default
    ``hidden_dtype``) that of the backward pass; nearly all the FLOPs are there. ``torch.bfloat16`` runs them
    ~4x faster on CPUs with AVX512-BF16 (oneDNN accumulates in float32); parameters, the input layer (raw
    observations) and the output layer (Q/V values, policy mean and log-std) stay float32. With only
    ``grad_dtype=torch.bfloat16`` the outputs (and so every loss and target) are exactly the float32 ones
    and only the gradients are rounded.
    """

    def __init__(
        self,
        n_members: int,
        in_dim: int,
        hidden_sizes: Sequence[int],
        out_dim: int,
        generator: torch.Generator,
        hidden_dtype: torch.dtype = torch.float32,
        grad_dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        sizes = [in_dim, *hidden_sizes, out_dim]
        self.n_members = n_members
        self.hidden_dtype = hidden_dtype
        self.grad_dtype = hidden_dtype if grad_dtype is None else grad_dtype
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in itertools.pairwise(sizes):
            bound = 1.0 / math.sqrt(fan_in)
            self.weights.append(nn.Parameter(_uniform((n_members, fan_out, fan_in), bound, generator)))
            self.biases.append(nn.Parameter(_uniform((n_members, fan_out, 1), bound, generator)))

    def forward(self, x: Tensor, frozen: bool = False) -> Tensor:
        x = x.transpose(-1, -2)  # feature-major (.., in, B)
        if x.dim() == 2:
            x = x.expand(self.n_members, *x.shape)
        params = [*self.weights, *self.biases]
        if frozen:
            params = [p.detach() for p in params]
        if torch.is_grad_enabled() and (x.requires_grad or any(p.requires_grad for p in params)):
            out = _EnsembleMLPFunction.apply(x, self.hidden_dtype, self.grad_dtype, *params)
        else:  # no graph to record (targets, acting): the same forward pass, saving nothing
            out = _mlp_forward(x, params, self.hidden_dtype, None)
        return out.transpose(1, 2)


def _mlp_forward(x: Tensor, params: Sequence[Tensor], hidden_dtype: torch.dtype, saved: list | None) -> Tensor:
    """``(E, in, B) -> (E, out, B)``; appends each layer's ``(input, weight)`` to ``saved`` unless it is None."""
    n = len(params) // 2
    last = n - 1
    for i in range(n):
        w, b = params[i], params[n + i]
        hidden = 0 < i < last  # a hidden-to-hidden layer
        if hidden:
            w, b = w.to(hidden_dtype), b.to(hidden_dtype)
        x = x.to(w.dtype)
        if saved is not None:
            saved.append((x, w, hidden))
        x = torch.baddbmm(b, w, x)
        if i < last:
            x = x.relu_()  # in place: the backward pass needs the layer inputs only
    return x


class _EnsembleMLPFunction(torch.autograd.Function):
    """The ensemble MLP with a hand-written backward pass (no double backward).

    ``apply(x, hidden_dtype, grad_dtype, *weights, *biases)``, ``x`` feature-major ``(E, in, B)``, returns
    ``(E, out, B)``. The backward pass computes the gradients autograd computes for :func:`_mlp_forward`
    (bit-identical in float32 on the tested CPUs), only those that are needed (``needs_input_grad``:
    none for detached weights, none for an input that needs none), with the hidden layers' matmuls in
    ``grad_dtype``, which may differ from the forward pass's ``hidden_dtype`` (autograd cannot do that).
    """

    @staticmethod
    def forward(ctx, x: Tensor, hidden_dtype: torch.dtype, grad_dtype: torch.dtype, *params: Tensor) -> Tensor:  # type: ignore[override]
        saved: list[tuple[Tensor, Tensor, bool]] = []
        out = _mlp_forward(x, params, hidden_dtype, saved)
        # the backward pass's operands: hidden layers' inputs and weights in grad_dtype
        inputs = [a.to(grad_dtype) if hidden else a for a, _, hidden in saved]
        weights = [w.to(grad_dtype) if hidden else w for _, w, hidden in saved]
        ctx.n_layers = len(saved)
        ctx.save_for_backward(*inputs, *weights)
        return out

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor | None, ...]:  # type: ignore[override]
        n = ctx.n_layers
        saved = ctx.saved_tensors
        inputs, weights = saved[:n], saved[n:]
        needs = ctx.needs_input_grad  # (x, hidden_dtype, grad_dtype, *weights, *biases)
        grad_w: list[Tensor | None] = [None] * n
        grad_b: list[Tensor | None] = [None] * n
        grad_x = None
        for i in reversed(range(n)):
            w, a = weights[i], inputs[i]
            g = grad.to(w.dtype)
            if needs[3 + i]:
                grad_w[i] = _outer_sum(g, a).float()
            if needs[3 + n + i]:
                grad_b[i] = g.sum(-1, keepdim=True).float()
            if i == 0 and not needs[0]:
                break
            grad = _transposed_product(w, g)
            if i > 0:  # through the ReLU that produced this layer's input (a >= 0, zero where clipped)
                grad = torch.ops.aten.threshold_backward(grad, a, 0)
            else:
                grad_x = grad.float()
        return grad_x, None, None, *grad_w, *grad_b


def _outer_sum(g: Tensor, a: Tensor) -> Tensor:
    """``g @ a^T`` ``(E, out, in)`` from ``g (E, out, B)``, ``a (E, in, B)``: the weight gradient.

    For the output layer's 1-2 units this is the transpose of ``a @ g^T``, which MKL computed several times
    faster (the narrow side as the result's columns, as autograd's orientation has for the input layer).
    """
    if g.shape[1] < a.shape[1]:
        return torch.bmm(a, g.transpose(1, 2)).transpose(1, 2)
    return torch.bmm(g, a.transpose(1, 2))


def _transposed_product(w: Tensor, g: Tensor) -> Tensor:
    """``w^T @ g`` ``(E, in, B)``: the gradient with respect to a layer's input (an outer product for one unit)."""
    if w.shape[1] == 1:
        return w.transpose(1, 2) * g
    return torch.bmm(w.transpose(1, 2), g)


def _uniform(shape: tuple[int, ...], bound: float, generator: torch.Generator) -> Tensor:
    return torch.empty(shape).uniform_(-bound, bound, generator=generator)


class QNetworks(nn.Module):
    """``n_q`` soft Q-functions ``Q_i(s, a)``; ``forward`` returns ``(n_q, B)``."""

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden_sizes: Sequence[int],
        n_q: int,
        generator: torch.Generator,
        hidden_dtype: torch.dtype = torch.float32,
        grad_dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        self.mlp = EnsembleMLP(n_q, obs_dim + act_dim, hidden_sizes, 1, generator, hidden_dtype, grad_dtype)

    def forward(self, obs: Tensor, action: Tensor, frozen: bool = False) -> Tensor:
        return self.mlp(torch.cat([obs, action], dim=-1), frozen=frozen).squeeze(-1)


class ValueNetwork(nn.Module):
    """The state-value function ``V(s)`` of SAC v1; ``forward`` returns ``(B,)``."""

    def __init__(
        self,
        obs_dim: int,
        hidden_sizes: Sequence[int],
        generator: torch.Generator,
        hidden_dtype: torch.dtype = torch.float32,
        grad_dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        self.mlp = EnsembleMLP(1, obs_dim, hidden_sizes, 1, generator, hidden_dtype, grad_dtype)

    def forward(self, obs: Tensor) -> Tensor:
        return self.mlp(obs)[0, :, 0]


class TanhGaussianPolicy(nn.Module):
    """``a = tanh(u)``, ``u ~ N(mu(s), sigma(s)^2)``: actions in ``[-1, 1]^act_dim``.

    ``log sigma`` is clamped to ``[log_std_min, log_std_max]`` (Haarnoja et al. 2018 code: [-20, 2]) so
    the Gaussian never collapses to a point or explodes early in training.
    """

    def __init__(
        self,
        obs_dim: int,
        act_dim: int,
        hidden_sizes: Sequence[int],
        log_std_min: float,
        log_std_max: float,
        generator: torch.Generator,
        hidden_dtype: torch.dtype = torch.float32,
        grad_dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__()
        self.mlp = EnsembleMLP(1, obs_dim, hidden_sizes, 2 * act_dim, generator, hidden_dtype, grad_dtype)
        self.act_dim = act_dim
        self.log_std_min = log_std_min
        self.log_std_max = log_std_max

    def distribution(self, obs: Tensor) -> tuple[Tensor, Tensor]:
        """Mean and clamped log-std of the pre-squash Gaussian, each ``(B, act_dim)``."""
        out = self.mlp(obs)[0]
        mean, log_std = out[:, : self.act_dim], out[:, self.act_dim :]
        return mean, log_std.clamp(self.log_std_min, self.log_std_max)

    def sample(self, obs: Tensor, generator: torch.Generator) -> tuple[Tensor, Tensor]:
        """Reparameterised sample ``a (B, act_dim)`` in ``[-1, 1]`` and its log-density ``log pi(a|s) (B,)``."""
        mean, log_std = self.distribution(obs)
        noise = torch.randn(mean.shape, generator=generator, dtype=mean.dtype)
        pre_tanh = mean + log_std.exp() * noise
        return torch.tanh(pre_tanh), squashed_gaussian_log_prob(noise, log_std, pre_tanh)

    def deterministic(self, obs: Tensor) -> Tensor:
        """The mean action ``tanh(mu(s))`` ``(B, act_dim)`` used for evaluation."""
        return torch.tanh(self.distribution(obs)[0])

    def log_prob(self, obs: Tensor, actions: Tensor) -> Tensor:
        """``log pi(a|s)`` ``(B,)`` of given actions ``(B, act_dim)`` (a demonstrator's), each component clipped to
        ``+-ACTION_LIMIT``: an action on the box's edge (a move at full scale) has no finite pre-squash value."""
        mean, log_std = self.distribution(obs)
        pre_tanh = torch.atanh(actions.clamp(-ACTION_LIMIT, ACTION_LIMIT))
        return squashed_gaussian_log_prob((pre_tanh - mean) / log_std.exp(), log_std, pre_tanh)


# |a| <= tanh(3.8): the pre-squash value of an action on the box's edge as a cloned policy's mean can reach it
ACTION_LIMIT = 0.999


def squashed_gaussian_log_prob(noise: Tensor, log_std: Tensor, pre_tanh: Tensor) -> Tensor:
    """``log pi(tanh(u))`` for ``u = mu + sigma * noise``, summed over the last axis: ``(B, D) -> (B,)``.

    Change of variables (Haarnoja et al. 2018, appendix C):
    ``log pi(a) = log N(u; mu, sigma) - sum log(1 - tanh(u)^2)``, with the Jacobian term in the
    overflow-free form ``log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u))``.
    """
    gaussian = -0.5 * noise.square() - log_std - LOG_SQRT_2PI
    log_det_jacobian = 2.0 * (LOG_2 - pre_tanh - F.softplus(-2.0 * pre_tanh))
    return (gaussian - log_det_jacobian).sum(-1)
