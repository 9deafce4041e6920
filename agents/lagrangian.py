"""The Lagrange multiplier of the constrained (safe) fine-tuning stage.

The constrained problem "reach the goal, keeping the episode cost ``J_C`` at most ``delta``"
becomes the saddle point of ``distance + lambda * (J_C - delta)``. The actor minimises
``(distance + lambda * cost) / (1 + lambda)`` for the current ``lambda`` (the division keeps the
actor's gradient scale bounded as ``lambda`` grows); ``lambda`` follows projected gradient ascent
on the measured episode costs: it grows while episodes cost more than the limit and shrinks,
never below zero, while they cost less (the Lagrangian actor-critic of Ray et al., 2019, used by
the paper "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe Reinforcement Learning",
with initial value 0 and learning rate 0.035).
"""
from __future__ import annotations

import math
from typing import Iterable, cast

import numpy as np


class LagrangeMultiplier:
    """A non-negative multiplier updated from episode costs.

    Args:
        cost_limit: the limit ``delta`` on the episode cost.
        learning_rate: step size of the ascent on ``lambda``.
        initial_value: starting ``lambda`` (>= 0).
        max_value: optional upper bound (``None``: unbounded).
    """

    def __init__(
        self,
        cost_limit: float = 10.0,
        learning_rate: float = 0.035,
        initial_value: float = 0.0,
        max_value: float | None = None,
    ) -> None:
        for name, v in (("cost_limit", cost_limit), ("learning_rate", learning_rate), ("initial_value", initial_value)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if max_value is not None and not (math.isfinite(max_value) and max_value >= initial_value):
            raise ValueError(f"max_value must be >= initial_value={initial_value}, got {max_value!r}")
        self.cost_limit = float(cost_limit)
        self.learning_rate = float(learning_rate)
        self.max_value = None if max_value is None else float(max_value)
        self.value = float(initial_value)
        self.n_updates = 0

    def update(self, episode_costs: float | Iterable[float]) -> float:
        """One ascent step from the mean of ``episode_costs``; return the new ``lambda``.

        ``lambda <- max(0, lambda + lr * (mean_cost - cost_limit))``, capped at ``max_value``.
        """
        if np.isscalar(episode_costs):
            costs = np.array([episode_costs], dtype=np.float64)
        else:
            costs = np.asarray(list(cast(Iterable[float], episode_costs)), dtype=np.float64).ravel()
        if costs.size == 0:
            raise ValueError("update() needs at least one episode cost")
        if not np.all(np.isfinite(costs)):
            raise ValueError(f"episode costs must be finite, got {costs.tolist()!r}")
        violation = float(costs.mean()) - self.cost_limit
        value = max(0.0, self.value + self.learning_rate * violation)
        if self.max_value is not None:
            value = min(value, self.max_value)
        self.value = value
        self.n_updates += 1
        return value

    def penalized(self, objective, cost):
        """``(objective + lambda * cost) / (1 + lambda)``: the quantity the actor minimises."""
        lam = self.value
        return (objective + lam * cost) / (1.0 + lam)

    def __float__(self) -> float:
        return self.value

    def __repr__(self) -> str:
        return (f"LagrangeMultiplier(value={self.value:.4g}, cost_limit={self.cost_limit:g}, "
                f"learning_rate={self.learning_rate:g})")


__all__ = ["LagrangeMultiplier"]
