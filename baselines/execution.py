"""What one run of a method on a problem produced, and the per-step bookkeeping every runner shares.

Below :mod:`baselines.methods` (the search methods) and :mod:`baselines.marl_rows` (the
multi-agent RL policies), which both fill an :class:`Execution`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional

import numpy as np

from agents.search.execution.stats import ACTIVITIES

from .anatomy import AgentFailure


@dataclass
class Execution:
    """What happened when a method ran one problem (all arrays per agent)."""

    success: bool
    reached: np.ndarray
    cost: np.ndarray
    steps: int
    collisions: int  # contacts between two agents, each counted when it begins
    planning_time: float
    plan_status: str
    trajectories: np.ndarray  # (T + 1, K, 2) positions, for figures
    extra: Dict[str, Any] = field(default_factory=dict)
    #: why each agent that did not arrive failed (see :mod:`baselines.anatomy`)
    failures: List[AgentFailure] = field(default_factory=list)
    #: per agent, the step at which it arrived (``-1``: it did not)
    arrival: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: per agent and activity (:data:`~agents.search.execution.stats.ACTIVITIES`), the cost it took
    #: doing that (rows sum to ``cost``; empty where the runner does not record it)
    cost_split: np.ndarray = field(default_factory=lambda: np.zeros((0, len(ACTIVITIES))))
    #: per agent, whether it touched another agent during the run (empty where agents pass
    #: through each other)
    touched: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: contacts per reason (:data:`~baselines.contact_anatomy.CONTACT_REASONS`; empty where not recorded)
    contact_reasons: Dict[str, int] = field(default_factory=dict)

    @property
    def safety_rate(self) -> float:
        """The share of agents that never touched another agent (``nan`` where not recorded)."""
        return float(1.0 - self.touched.mean()) if len(self.touched) else math.nan


def tally_step(infos, term, index: Dict[str, int], cost: np.ndarray, reached: np.ndarray, parked_at: np.ndarray,
               steps: int, activity: Optional[Dict[str, str]] = None, split: Optional[np.ndarray] = None) -> set:
    """Add one step's obstacle costs and arrivals (at step ``steps``) to the per-agent arrays; returns
    the contacts under way, as pairs of agent names. With ``split`` (agents x :data:`ACTIVITIES`),
    each agent's cost also goes to the column of what it did (``activity``; default ``drive``)."""
    now: set = set()
    for a, info in infos.items():
        i = index[a]
        c = float(info.get("obstacle_cost", info["cost"]))
        cost[i] += c
        if split is not None:
            split[i, ACTIVITIES.index((activity or {}).get(a, "drive"))] += c
        now.update(frozenset((a, b)) for b in info.get("collided_with", ()))
        if term.get(a, False):
            reached[i] = True
            parked_at[i] = steps
    return now


class Contacts:
    """Contacts between agents over a run: each counted once, when it begins (:attr:`count`), per
    agent whether it touched another (:attr:`touched`), and how many began for each reason
    (:attr:`reasons`, with a ``reason`` function given to :meth:`update`)."""

    def __init__(self, index: Dict[str, int]) -> None:
        self.index = index
        self.count = 0
        self.touched = np.zeros(len(index), dtype=bool)
        self.reasons: Dict[str, int] = {}
        self._under_way: set = set()

    def update(self, now: set, reason: Optional[Callable[[str, str], str]] = None) -> None:
        """Take one step's contacts under way (pairs of agent names, as :func:`tally_step` returns);
        ``reason(a, b)`` names why a contact that begins on this step began
        (:func:`~baselines.contact_anatomy.contact_reason`)."""
        new = now - self._under_way
        self.count += len(new)
        if reason is not None:
            for pair in new:
                why = reason(*sorted(pair))
                self.reasons[why] = self.reasons.get(why, 0) + 1
        self._under_way = now
        for pair in now:
            for a in pair:
                self.touched[self.index[a]] = True


def geodesic_of(env) -> Any:
    """``geodesic(a, b) -> float`` on ``env``'s map (ground truth; ``nan`` where a point is not free)."""

    def geodesic(a: np.ndarray, b: np.ndarray) -> float:
        try:
            return float(np.asarray(env.geodesic_distance(np.asarray(a, np.float64), np.asarray(b, np.float64))))
        except ValueError:
            return math.nan

    return geodesic


__all__ = ["Contacts", "Execution", "geodesic_of", "tally_step"]
