"""The *clear goal* rules of :class:`~agents.search.execution.controller.WaypointController` (its
``goal_clearance``, in predicted steps). A mixin: the controller keeps the state these methods
read and write.

- An agent on its way to its goal and within ``2 * goal_clearance`` of it stands still while
  another live agent is within ``goal_clearance`` of that goal (the routes may say that one has
  passed the goal, but it still stands there): parked, it would shut that one in. It waits only
  on an agent free to leave (not one held for a third agent, its departure time, or to clear its
  own goal) and whose goal it does not stand nearer itself (then it moves on to clear that goal),
  until ``order_patience`` steps after it first held for that agent. It begins to hold only while
  the two are further apart than ``safety_radius`` (closer, it would stand in the other's way and
  be pushed along). An agent it holds this way no longer waits for it by the plan's order or the
  goal order.
- Of two agents close enough to yield, where one stands within ``goal_clearance`` of the goal the
  other is on its way to, the one nearer the other's goal goes first; the pair keeps that order
  while close (two agents pushing each other would hand it back and forth).
- (``push_margin``) An agent held still for another that is pushed by it (its predicted distance
  to its target grows by more than ``push_margin`` steps while it yields for the same target: the
  panorama policies, trained alone, push a standing agent ahead of them, e.g. back into the door
  or the dead end it was leaving) goes first from then on; the pair keeps that order while close.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Dict, List, Optional, Set, Tuple

import numpy as np

from ..config import ControllerConfig


def pair_proximity(distance: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   proximity: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]],
                   obs_a: np.ndarray, obs_b: np.ndarray) -> np.ndarray:
    """How close agents are, pair by pair (the controller's yield rule): ``proximity`` where given, else
    ``distance`` taken the shorter way."""
    if proximity is not None:
        return np.asarray(proximity(obs_a, obs_b), dtype=np.float64)
    return np.minimum(np.asarray(distance(obs_a, obs_b)), np.asarray(distance(obs_b, obs_a)))


class GoalClearance:
    """The controller's *clear goal* rules (see :class:`~agents.search.execution.controller.WaypointController`)."""

    config: ControllerConfig
    t: int
    index: Dict[str, int]
    plans: Dict[str, Any]
    distance: Callable[[np.ndarray, np.ndarray], np.ndarray]
    proximity: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]]
    bound: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]]
    stats: Any
    _clearing: Dict[str, str]
    _clear_since: Dict[Tuple[str, str], int]
    _clear_gave_up: Dict[str, Set[str]]
    #: per agent held for another: (that agent, its own target index, its distance to the target then)
    _yielding: Dict[str, Tuple[str, int, float]]
    #: close pairs whose order the push rule decided, and the agent that goes first
    _pushed: Dict[Tuple[str, str], str]

    def _clear_goals(self, live: List[str], obs: np.ndarray, hold: np.ndarray, reason: List[Optional[str]],
                     to_target: Dict[str, float]) -> None:
        """Hold (``reason`` ``"clear:<agent>"``) the agents near their goal while another live agent
        stands within ``goal_clearance`` of it (see *clear goal* in the module's docstring)."""
        assert self.config.goal_clearance is not None  # checked by the caller
        r = self.config.goal_clearance
        before, self._clearing = self._clearing, {}
        for i, a in enumerate(live):
            if hold[i] or self.index[a] < len(self.plans[a].waypoints) or not to_target.get(a, math.inf) < 2 * r:
                continue
            # only agents free to leave (or waiting for this one to go first): one held for another
            # reason would keep it waiting for nothing
            others = [j for j, b in enumerate(live) if j != i and b not in self._clear_gave_up[a]
                      and self._clearing.get(b) != a and before.get(b) != a and reason[j] in (None, f"wait:{a}")]
            if others and self.bound is not None:  # the critic reads only agents that may stand by the goal
                near = self._lower_bound(obs[others], np.asarray(self.plans[a].goal)[None])[:, 0] < r
                others = [j for j, k in zip(others, near) if k]
            if not others:
                continue
            n = len(others)
            # how far each other agent is from this one's goal, and this one from each other's goal
            pairs_obs = np.concatenate([obs[others], np.repeat(obs[i:i + 1], n, axis=0)])
            pairs_goal = np.stack([np.asarray(self.plans[a].goal)] * n + [np.asarray(self.plans[live[j]].goal)
                                                                          for j in others])
            both = np.asarray(self.distance(pairs_obs, pairs_goal), dtype=np.float64).reshape(2 * n)
            d, mine = both[:n], both[n:]
            for j in np.argsort(d):
                if not d[j] < r:
                    break
                b = live[others[j]]
                # it stands closer to that one's goal than that one to its own (it moves on to clear it),
                # or they already touch (the yield rule settles which goes first); once it holds, it
                # holds until that one has left
                if before.get(a) != b and (mine[j] < d[j] or self._touching(obs[i], obs[others[j]])):
                    continue
                since = self._clear_since.setdefault((a, b), self.t)
                if self.t - since >= self.config.order_patience:  # it does not leave: park after all
                    self._clear_gave_up[a].add(b)
                    continue
                hold[i] = True
                reason[i] = f"clear:{b}"
                self._clearing[a] = b
                self.stats.waits += 1
                break

    def _lower_bound(self, obs_a: np.ndarray, obs_b: np.ndarray) -> np.ndarray:
        """``bound(obs_a, obs_b)``, checked: ``(len(obs_a), len(obs_b))`` lower bounds of the steps."""
        assert self.bound is not None  # checked by the caller
        out = np.asarray(self.bound(obs_a, obs_b), dtype=np.float64)
        if out.shape != (len(obs_a), len(obs_b)):
            raise ValueError(f"bound returned shape {out.shape}, expected {(len(obs_a), len(obs_b))}")
        return out

    def _touching(self, x: np.ndarray, y: np.ndarray) -> bool:
        """Whether two agents' observations are within ``safety_radius`` (under ``proximity``): the
        yield rule settles which of them goes."""
        radius = self.config.safety_radius
        if radius is None:
            return False
        return bool(pair_proximity(self.distance, self.proximity, x[None], y[None]).reshape(-1)[0] < radius)

    def _goal_first(self, live: List[str], obs: np.ndarray, ii: np.ndarray, jj: np.ndarray, close: np.ndarray,
                    i_first: np.ndarray, before: Dict[Tuple[str, str], str]) -> np.ndarray:
        """The yield rule's priorities (``i_first`` per pair ``ii[k], jj[k]``) where one of two close
        agents stands within ``goal_clearance`` of the goal the other is on its way to: the one
        standing nearer the other's goal goes first (it has to clear it, or the other parks in front of
        it). ``before``: the pairs so decided on the last step (they keep their order while close)."""
        assert self.config.goal_clearance is not None  # checked by the caller
        last = np.array([self.index[a] >= len(self.plans[a].waypoints) for a in live])
        sel = np.flatnonzero(close & (last[ii] | last[jj]))
        if len(sel) == 0:
            return i_first
        n = len(sel)
        goals = np.stack([np.asarray(self.plans[a].goal) for a in live])
        d = np.asarray(self.distance(np.concatenate([obs[ii[sel]], obs[jj[sel]]]),
                                     np.concatenate([goals[jj[sel]], goals[ii[sel]]])), dtype=np.float64).reshape(2 * n)
        by_j = np.where(last[jj[sel]], d[:n], np.inf)  # agent ii stands by jj's goal
        by_i = np.where(last[ii[sel]], d[n:], np.inf)
        decide = (np.minimum(by_j, by_i) < self.config.goal_clearance) & (by_j != by_i)
        out = i_first.copy()
        kept = {}
        for k, q in enumerate(sel.tolist()):
            pair = (live[ii[q]], live[jj[q]])
            # decided once for a pair while it stays close: pushing each other, the two distances
            # would hand the priority back and forth every step
            first = before.get(pair)
            if first is None and decide[k]:
                first = pair[0] if by_j[k] < by_i[k] else pair[1]
            if first is not None:
                kept[pair] = first
                out[q] = first == pair[0]
        self._goal_priority = kept
        return out

    def _push_first(self, live: List[str], ii: np.ndarray, jj: np.ndarray, close: np.ndarray, i_first: np.ndarray,
                    to_target: Dict[str, float], before: Dict[Tuple[str, str], str],
                    yielding: Dict[str, Tuple[str, int, float]]) -> np.ndarray:
        """The yield rule's priorities (``i_first`` per pair ``ii[k], jj[k]``) where an agent held for the
        other one of a close pair is pushed by it (see ``push_margin`` in the module's docstring).
        ``before``: the pairs so decided on the last step; ``yielding``: as :meth:`_note_yields` left it."""
        assert self.config.push_margin is not None  # checked by the caller
        out, kept = i_first.copy(), {}
        for q in np.flatnonzero(close).tolist():
            pair = (live[ii[q]], live[jj[q]])
            first = before.get(pair)
            for y, w in (pair, pair[::-1]):
                held = yielding.get(y)
                if first is None and held is not None and held[:2] == (w, self.index[y]) \
                        and to_target.get(y, -math.inf) > held[2] + self.config.push_margin:
                    first = y
                    self.stats.pushed += 1
            if first is not None:
                kept[pair] = first
                out[q] = first == pair[0]
        self._pushed = kept
        return out

    def _note_yields(self, live: List[str], hold: Dict[int, int], to_target: Dict[str, float],
                     before: Dict[str, Tuple[str, int, float]]) -> None:
        """Remember, per agent held for another (``hold``: indices into ``live``), that one, its own target
        index and its distance to its target when it began to yield for them (``before``: the last step's)."""
        now: Dict[str, Tuple[str, int, float]] = {}
        for y, w in hold.items():
            a, b = live[y], live[w]
            held = before.get(a)
            # kept while it yields to the same agent for the same target; an agent that only set off for
            # its target on this step has no distance to it yet (inf), and takes the next step's
            if held is None or held[:2] != (b, self.index[a]) or not math.isfinite(held[2]):
                held = (b, self.index[a], to_target.get(a, math.inf))
            now[a] = held
        self._yielding = now


__all__ = ["GoalClearance", "pair_proximity"]
