"""Categorical (distributional) Bellman targets for the distance and cost critics.

Two critics predict a categorical distribution instead of a scalar:

- the **distance critic** (Search on the Replay Buffer): with reward -1 per step and no
  discount, the return is minus the number of steps to the goal. Bin ``k`` holds the
  probability that the goal is reached in ``k + 1`` steps; the last bin holds "``K`` steps or
  more". The Bellman target is the next state's distribution shifted by one bin;
- the **cost critic** (the paper "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe
  Reinforcement Learning"): atoms evenly spaced on ``[0, cost_max]``, target by the
  projection of the Categorical Algorithm (C51).

Everything here is a pure function of tensors, so the targets are tested by hand.
"""
from __future__ import annotations

import torch as th


def distance_support(n_bins: int, device: th.device | str | None = None) -> th.Tensor:
    """Number of steps each distance bin stands for: ``[1, 2, ..., n_bins]``."""
    if n_bins < 2:
        raise ValueError(f"a distance distribution needs at least 2 bins, got n_bins={n_bins}")
    return th.arange(1, n_bins + 1, dtype=th.float32, device=device)


def cost_support(n_bins: int, cost_max: float, device: th.device | str | None = None) -> th.Tensor:
    """``n_bins`` atoms evenly spaced on ``[0, cost_max]``."""
    if n_bins < 2:
        raise ValueError(f"a cost distribution needs at least 2 bins, got n_bins={n_bins}")
    if not cost_max > 0:
        raise ValueError(f"cost_max must be > 0, got {cost_max!r}")
    return th.linspace(0.0, float(cost_max), n_bins, dtype=th.float32, device=device)


def shift_distance_target(next_probs: th.Tensor, dones: th.Tensor) -> th.Tensor:
    """Target distance distribution for one step with reward -1 and discount 1.

    Args:
        next_probs: ``(..., K)`` distribution of the next state's distance (bin ``k`` = ``k+1`` steps).
        dones: ``(...)`` whether the step reached the goal (1.0 / True where it did).

    Returns:
        ``(..., K)``: where the step reached the goal, all mass on bin 0 (one step); elsewhere
        the next distribution moved one bin up, bin 0 empty and the last bin absorbing what
        would fall past it.
    """
    k = next_probs.shape[-1]
    if k < 2:
        raise ValueError(f"a distance distribution needs at least 2 bins, got {k}")
    shifted = th.zeros_like(next_probs)
    shifted[..., 1:-1] = next_probs[..., :-2]
    shifted[..., -1] = next_probs[..., -2:].sum(-1)
    terminal = th.zeros_like(next_probs)
    terminal[..., 0] = 1.0
    done = dones.to(next_probs.dtype).reshape(*dones.shape, 1)
    return done * terminal + (1.0 - done) * shifted


def categorical_projection(
    next_probs: th.Tensor,
    rewards: th.Tensor,
    dones: th.Tensor,
    support: th.Tensor,
    gamma: float = 1.0,
) -> th.Tensor:
    """Project ``r + gamma * Z'`` onto a fixed support (the Categorical Algorithm, C51).

    Args:
        next_probs: ``(..., K)`` probabilities of the next state's return over ``support``.
        rewards: ``(...)`` the step's reward (here: the step's cost).
        dones: ``(...)`` episode ends where nothing is bootstrapped (``Z' = 0``).
        support: ``(K,)`` evenly spaced atoms.
        gamma: discount factor.

    Returns:
        ``(..., K)`` target probabilities; the mass of every row is conserved. Values outside
        the support are clipped to its ends; a value between two atoms is split between them
        in proportion to its closeness.
    """
    k = support.shape[0]
    if next_probs.shape[-1] != k:
        raise ValueError(f"next_probs has {next_probs.shape[-1]} bins but the support has {k}")
    v_min, v_max = float(support[0]), float(support[-1])
    delta = (v_max - v_min) / (k - 1)
    not_done = 1.0 - dones.to(next_probs.dtype).unsqueeze(-1)
    tz = rewards.to(next_probs.dtype).unsqueeze(-1) + not_done * gamma * support
    b = ((tz.clamp(v_min, v_max) - v_min) / delta).clamp(0.0, k - 1)
    lower = b.floor()
    w_upper = b - lower
    lower_idx = lower.long()
    upper_idx = (lower_idx + 1).clamp(max=k - 1)
    out = th.zeros_like(next_probs)
    out.scatter_add_(-1, lower_idx, next_probs * (1.0 - w_upper))
    out.scatter_add_(-1, upper_idx, next_probs * w_upper)
    return out


def expected_value(logits: th.Tensor, support: th.Tensor) -> th.Tensor:
    """Mean of the categorical distribution ``softmax(logits)`` over ``support`` (last axis)."""
    return th.softmax(logits, dim=-1) @ support


__all__ = [
    "categorical_projection",
    "cost_support",
    "distance_support",
    "expected_value",
    "shift_distance_target",
]
