"""Whom an agent of :class:`~agents.search.execution.controller.WaypointController` waits for before it sets
off for its next target (the controller's *plan order* and *goal order* rules). A mixin: the
controller keeps the state these methods read and write.

- **Plan order**: the agents the plan sends through the target's place earlier must first have got
  far enough along their own routes (:mod:`agents.search.execution.dependencies`).
- **Goal order** (``goal_order``): before the leg to its goal, the agents that still have to pass
  the goal (parked, the agent would be an immovable obstacle there).
- **Patience**: an agent waits on another for at most ``order_patience`` steps in which that one
  reaches no new target.
- **Waits that close a cycle** are broken at once, not after the patience. The plan's own order has
  no cycle, but an agent that falls behind can meet others in another order, and the goal order
  and the clear-goal rule (:mod:`agents.search.execution.clearance`) add holds the plan does not know. Where
  the holds of the last step lead from the agent an agent waits on back to the agent itself, the
  agent stops waiting when the hold that closes the cycle is one for its sake: the agent before it
  in the cycle holds its parking for it (goal order) or stands still to clear its goal for it;
  where no hold of the cycle is of these kinds, the first agent of the cycle by name stops
  waiting; an agent that holds its parking stops only for the reason before (parked, it could
  shut the others in). Two agents waiting on each other are the shortest such cycle. (Apartment3:
  three agents at a doorway waited on each other for 33 steps, one held by the plan order for a
  second one, that one for a third, and the third holding its parking for the first, until the
  patience ran out.)
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Set, Tuple

from ..config import ControllerConfig


def hold_cycle(agent: str, first: str, holds: Callable[[str], Optional[str]], limit: int) -> Optional[List[str]]:
    """The agents from ``first`` on whose holds (``holds(x)``: the agent ``x`` stands still for, or
    ``None``) lead back to ``agent``: ``[first, ..., last]`` with ``holds(last) == agent``; ``None``
    where they end elsewhere or no cycle back to ``agent`` shows within ``limit`` holds."""
    chain: List[str] = []
    x: Optional[str] = first
    while x is not None and x != agent and len(chain) < limit:
        if x in chain:
            return None  # a cycle that does not pass through agent
        chain.append(x)
        x = holds(x)
    return chain if x == agent else None


class OrderRules:
    """The controller's plan-order and goal-order waits (see the module's docstring)."""

    plans: Dict[str, Any]
    index: Dict[str, int]
    t: int
    config: ControllerConfig
    goal_order: Optional[Callable[[str], List[Tuple[str, int]]]]
    _after: Dict[str, Dict[int, List[Tuple[str, int]]]]
    _blocked: Dict[str, Tuple[int, str, int, int]]
    _gave_up: Dict[str, Set[str]]
    _parks_after: Dict[str, str]
    _clearing: Dict[str, str]
    _live: Set[str]
    #: per agent: the agent it waited on at the last step (plan or goal order)
    _waiting: Dict[str, str]
    stats: Any

    def _waits_on(self, agent: str, q: int) -> Optional[str]:
        """The agent ``agent`` must wait for before setting off for its target ``q`` (``None``: it may go)."""
        self._parks_after.pop(agent, None)
        deps = self._after[agent].get(q, [])
        for b, r in list(deps):
            if b not in self._live or self.index.get(b, 0) > r:
                deps.remove((b, r))  # reached (or arrived): satisfied for good
                continue
            if self._patience_over(agent, q, b) or self._goes_first(agent, b):
                deps.remove((b, r))
                continue
            return b
        if self.goal_order is None or q != len(self.plans[agent].waypoints):
            return None
        for b, r in self.goal_order(agent):
            if b == agent or b not in self._live or self.index.get(b, 0) > r or b in self._gave_up[agent]:
                continue
            if self._clearing.get(b) == agent:  # b will not park while this one stands by b's goal
                continue
            if self._patience_over(agent, q, b) or self._goes_first(agent, b, parking=True):
                self._gave_up[agent].add(b)
                continue
            self._parks_after[agent] = b
            return b
        return None

    def _patience_over(self, agent: str, q: int, b: str) -> bool:
        """Whether ``agent``, held at target ``q`` by ``b``, has waited ``order_patience`` steps in which
        ``b`` reached no new target (then it stops waiting on ``b``)."""
        seen = self._blocked.get(agent)
        if seen is None or seen[:2] != (q, b) or self.index[b] != seen[3]:
            self._blocked[agent] = (q, b, self.t, self.index[b])
            return False
        if self.t - seen[2] >= self.config.order_patience:  # it does not progress: stop waiting on it
            self._blocked.pop(agent, None)
            return True
        return False

    def _holds(self, x: str) -> Optional[str]:
        """The agent ``x`` stood still for at the last step by the plan, goal or clear-goal order."""
        return self._waiting.get(x) or self._clearing.get(x)

    def _for_its_sake(self, x: str, agent: str) -> bool:
        """Whether ``x`` holds for ``agent``'s sake: it parks after it, or clears its goal for it."""
        return agent in (self._parks_after.get(x), self._clearing.get(x))

    def _goes_first(self, agent: str, b: str, parking: bool = False) -> bool:
        """Whether ``agent`` stops waiting on ``b`` because the holds close a cycle (module docstring);
        ``parking``: it waits on ``b`` by the goal order (it holds its parking for ``b``'s sake)."""
        if not parking and self._for_its_sake(b, agent):
            return True
        cycle = hold_cycle(agent, b, self._holds, len(self._live))
        if cycle is None:
            return False
        if self._for_its_sake(cycle[-1], agent):
            self.stats.cycles += 1
            return True
        links = zip(cycle, cycle[1:] + [agent])
        if parking or any(self._for_its_sake(x, y) for x, y in links):
            return False  # the cycle is broken at the agent a parking or clearing one holds for
        if agent == min([agent, *cycle]):
            self.stats.cycles += 1
            return True
        return False


__all__ = ["OrderRules", "hold_cycle"]
