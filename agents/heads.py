"""Ensembles of small MLPs evaluated as one batched product, and their pairwise shortcut.

Every head of the agent (actor and critics) is an :class:`EnsembleHead` whose first layer is
linear in ``[code(obs), code(goal), action]``. That makes the ``N x M`` matrices a planner needs
cheap: the codes of the ``N + M`` observations and their first-layer products are computed once
(:func:`first_layer_products`), and a pair only costs a broadcast sum plus the remaining small
layers (:func:`pair_head`).
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple, Type, cast

import torch as th
from torch import nn

#: Ways to combine the members of an ensemble: pessimistic (max), mean, optimistic (min), or
#: ``"none"`` to return every member (ensemble axis first).
AGGREGATES = ("max", "mean", "min", "none")


class EnsembleLinear(nn.Module):
    """``E`` independent linear layers applied as one batched matmul: ``(E, B, in) -> (E, B, out)``."""

    def __init__(self, n_members: int, in_features: int, out_features: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(th.empty(n_members, in_features, out_features))
        self.bias = nn.Parameter(th.empty(n_members, 1, out_features))
        bound = 1.0 / math.sqrt(in_features)  # the default initialisation of nn.Linear
        nn.init.uniform_(self.weight, -bound, bound)
        nn.init.uniform_(self.bias, -bound, bound)

    def forward(self, x: th.Tensor) -> th.Tensor:
        return th.baddbmm(self.bias, x, self.weight)


class EnsembleHead(nn.Module):
    """``E`` MLPs ``in_dim -> hidden... -> out_dim`` evaluated together."""

    def __init__(self, n_members: int, in_dim: int, net_arch: Sequence[int], out_dim: int,
                 activation_fn: Type[nn.Module] = nn.ReLU) -> None:
        super().__init__()
        if n_members < 1:
            raise ValueError(f"an ensemble needs at least one member, got {n_members}")
        if not net_arch:
            raise ValueError("a head needs at least one hidden layer, got net_arch=[]")
        dims = [in_dim, *[int(w) for w in net_arch], out_dim]
        self.n_members = n_members
        self.layers = nn.ModuleList(EnsembleLinear(n_members, dims[i], dims[i + 1]) for i in range(len(dims) - 1))
        self.act = activation_fn()

    def forward(self, x: th.Tensor) -> th.Tensor:
        """``(B, in)`` (shared by every member) or ``(E, B, in)`` -> ``(E, B, out)``."""
        if x.dim() == 2:
            x = x.unsqueeze(0).expand(self.n_members, -1, -1)
        return self.from_first_preactivation(self.layers[0](x))

    def from_first_preactivation(self, h: th.Tensor) -> th.Tensor:
        """Finish the forward pass from the first layer's pre-activation ``(E, B, hidden0)``."""
        for layer in self.layers[1:]:
            h = layer(self.act(h))
        return h

    def linear(self, i: int) -> EnsembleLinear:
        """The ``i``-th layer (typed)."""
        return cast(EnsembleLinear, self.layers[i])

    def first_layer_parts(self, sizes: Sequence[int]) -> Tuple[List[th.Tensor], th.Tensor]:
        """The first layer's weight split into row blocks of ``sizes`` (``(E, size, hidden0)`` each) and its bias."""
        first = self.linear(0)
        return list(first.weight.split(list(sizes), dim=1)), first.bias


def aggregate_ensemble(values: th.Tensor, aggregate: str) -> th.Tensor:
    """Combine ensemble members (axis 0)."""
    if aggregate == "max":
        return values.max(0).values
    if aggregate == "mean":
        return values.mean(0)
    if aggregate == "min":
        return values.min(0).values
    if aggregate == "none":
        return values
    raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")


def first_layer_products(codes: Tuple[th.Tensor, th.Tensor], head: EnsembleHead):
    """First-layer pre-activations of the codes ``a`` as observations ``(E, N, H)`` and ``b`` as
    goals ``(E, M, H)`` (bias included), plus the action block of the weight (``None`` for the actor)."""
    code_a, code_b = codes
    d = code_a.shape[1]
    in_dim = head.linear(0).weight.shape[1]
    sizes = [d, d] + ([in_dim - 2 * d] if in_dim > 2 * d else [])
    (w_obs, w_goal, *w_act), bias = head.first_layer_parts(sizes)
    pre_a = th.matmul(code_a.unsqueeze(0), w_obs).contiguous()
    pre_b = th.baddbmm(bias, code_b.unsqueeze(0).expand(head.n_members, -1, -1), w_goal).contiguous()
    return pre_a, pre_b, (w_act[0] if w_act else None)


def pair_head(head: EnsembleHead, parts, i0: int, i1: int, j0: int, j1: int,
              actions: Optional[th.Tensor] = None, members: Optional[slice] = None) -> th.Tensor:
    """Outputs ``(E, P, out)`` of ``head`` for the pairs ``[i0, i1) x [j0, j1)`` (row-major);
    ``members`` (a slice) evaluates only those ensemble members."""
    pre_a, pre_b, _ = parts
    m = slice(None) if members is None else members
    h = th.add(pre_a[m, i0:i1, None, :], pre_b[m, None, j0:j1, :]).flatten(1, 2)
    return _finish_pairs(head, parts, h, actions, m)


def pair_head_at(head: EnsembleHead, parts, rows: th.Tensor, cols: th.Tensor,
                 actions: Optional[th.Tensor] = None, members: Optional[slice] = None) -> th.Tensor:
    """Outputs ``(E, P, out)`` of ``head`` for the pairs ``(rows[p], cols[p])`` (index tensors);
    ``members`` (a slice) evaluates only those ensemble members."""
    pre_a, pre_b, _ = parts
    m = slice(None) if members is None else members
    h = th.add(pre_a[m, rows, :], pre_b[m, cols, :])
    return _finish_pairs(head, parts, h, actions, m)


def _finish_pairs(head: EnsembleHead, parts, h: th.Tensor, actions: Optional[th.Tensor], m: slice) -> th.Tensor:
    """The layers of ``head`` (members ``m``) after the sum of the first-layer products ``h``."""
    w_act = parts[2]
    e = h.shape[0]
    if w_act is not None:
        assert actions is not None, "the critics' heads need the actions"
        h.baddbmm_(actions.expand(e, -1, -1), w_act[m])
    h = _activate_(h, head.act)
    n_layers = len(head.layers)
    for k in range(1, n_layers):
        layer = head.linear(k)
        h = th.baddbmm(layer.bias[m], h, layer.weight[m])
        if k < n_layers - 1:
            h = _activate_(h, head.act)
    return h


def _activate_(h: th.Tensor, act: nn.Module) -> th.Tensor:
    """Apply ``act`` in place where it is a ReLU (no extra buffer), out of place otherwise."""
    return h.relu_() if isinstance(act, nn.ReLU) else act(h)


__all__ = ["AGGREGATES", "EnsembleHead", "EnsembleLinear", "aggregate_ensemble", "first_layer_products", "pair_head",
           "pair_head_at"]
