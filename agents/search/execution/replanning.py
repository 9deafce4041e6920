"""What :class:`~agents.search.policy.SearchPolicy` does for an agent its controller finds stuck
(``replan_when_stuck``): :class:`Replanner`, which reads and writes the episode's
:class:`~agents.search.execution.episode.AgentState` records and the edge memory.

- The edge the agent was on is recorded: in its failed edges for this episode, with the edges
  between the nodes right by its two ends (:func:`~agents.search.execution.repair.edges_near`: a critic that
  took two far places for near ones misjudges their neighbours too), and in the ``memory``.
- The node it failed to reach and the nodes within ``ban_radius`` of it (either way) are banned.
- Where the critic now puts the leg's target beyond two edges' reach (``2 * d_max``), though the
  agent set off for it as one edge away, the critic took one place for another (two panoramas
  alike: a wormhole). With ``detach_radius``, for the rest of the episode: a target node and the
  nodes within ``detach_radius`` of it are no longer linked to the agent's start (from where it
  stands now the critic may well take it for a place beside them again); on the last leg, the
  node it set off from and the nodes within ``detach_radius`` of it are no longer linked to its
  goal (the critic takes them for places beside the goal). Routes may still pass them.
- Then it plans alone from where it stands, trying in turn: around the failed waypoints and their
  neighbourhoods (but around the failed waypoints alone where that route is more than ``ban_detour``
  predicted steps shorter: the neighbourhood held the short way, a doorway's other nodes); around
  the failed waypoints only (the neighbourhood held the only doorway);
  localised (its start attached to the nodes the critic puts nearest), with a berth of 1, 0.85 or
  0.7 ban radii around the goals of parked agents, then with no berth but no edge that passes a
  parked agent (in a crowd the berths leave no way through), then past them. It tries these first without
  the detached links, then with them back (where it stands right by the node it failed to reach,
  they may be all it can link to); then over the edges it failed on itself, less those the memory
  removed (without the detached links, then with them); and at last over every edge (it was not
  where its route said when it failed, or another agent was in the way). Only if none is solved
  it gives the waypoint up.
- A waypoint it failed on twice that the new route cannot avoid, it heads past
  (:func:`~agents.search.execution.repair.past_failed_waypoints`, with the critic's distance where the
  problem graph holds only a bound: beyond ``d_max``).

With ``repair_routes``, what one agent learns the others use at once: an agent about to set off
along an edge that another agent failed on in the episode (one of the edges recorded with it), or
that the memory removed meanwhile, plans anew from where it stands. It tries in turn the replans
above but the last (over every edge), leaving out the edges every agent failed on; its start
(where it stands: the leg's source) links to none of the nodes those edges lead to from there. It
keeps its route where none is solved, or where the new one is predicted more than
``REPAIR_STRETCH`` (2) times as long as the rest of its route (a long way round leads through
other agents' places, and the failed edge may have been failed for another reason).
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from ..config import SearchConfig
from .controller import AgentPlan
from .dependencies import nodes_near
from .episode import AgentState, Episode
from .repair import edges_near, near_either_way, past_failed_waypoints

#: a route repair (``repair_routes``) is taken only where its predicted length is at most this many
#: times that of the rest of the route it replaces
REPAIR_STRETCH = 2.0


class Replanner:
    """Replans for stuck agents, and before legs along edges others failed on (``repair_routes``).

    Args:
        planner: the policy's :class:`~agents.search.planner.BufferPlanner`.
        config: the policy's :class:`~agents.search.config.SearchConfig` (its ``replanning`` part and
            ``budget``).
        memory: the graph's :class:`~agents.search.execution.repair.EdgeMemory` (failures are recorded in it).
        distance: ``distance(obs[B], goal[B]) -> [B]`` of the critic that judges waypoints.
        episode: the policy's current :class:`~agents.search.execution.episode.Episode`.
    """

    def __init__(self, planner: Any, config: SearchConfig, memory: Any,
                 distance: Callable[[np.ndarray, np.ndarray], np.ndarray], episode: Episode) -> None:
        self.planner = planner
        self.rules = config.replanning
        self.budget = config.budget
        self.memory = memory
        self.distance = distance
        self.episode = episode

    def exclude_edges(self, agent: str, shared: bool = False) -> np.ndarray:
        """The edges ``agent``'s replans leave out: those the memory removed and those it failed on
        (``shared``: those any agent failed on this episode)."""
        ep = self.episode
        own = [e for b in (ep.agents if shared else [agent]) for e in ep.states[b].failed_edges]
        own_arr = np.asarray(own, dtype=np.int64).reshape(-1, 2)
        return np.unique(np.concatenate([self.memory.removed(), own_arr]), axis=0)

    def parked_nodes(self, agent: str, share: float = 1.0) -> List[int]:
        """Buffer nodes within ``share * ban_radius`` predicted steps of the goals of the agents that have
        arrived (they are parked there, immovable): a replan for ``agent`` keeps clear of them."""
        states = self.episode.states
        parked = [(states[b].problem, states[b].goal_id) for b in self.episode.parked(agent)
                  if states[b].problem is not None]
        r = share * self.rules.ban_radius
        return [int(i) for problem, goal in parked for i in np.flatnonzero(nodes_near(problem, goal, r))]

    def _straight(self, problem: Any) -> Callable[[int, int], float]:
        """The critic's distance between two nodes of ``problem``: exact where its ``D`` holds only a bound."""
        d_max = self.planner.graph.d_max

        def straight(u: int, w: int) -> float:
            d = float(problem.D[u, w])
            if d < d_max:
                return d
            return float(self.distance(problem.observations[[u]], problem.observations[[w]])[0])

        return straight

    def _detach(self, state: AgentState, ob: np.ndarray, source: Optional[int], target: Optional[int]) -> None:
        """Detach the nodes beside the ends of the leg ``source -> target`` (buffer ids; ``None``: the
        agent's start or goal) where the critic now puts the target beyond two edges' reach."""
        p = self.planner
        to = p.observations[[target]] if target is not None else state.goal[None]
        if source is None and target is None or float(self.distance(ob[None], to)[0]) < 2 * p.graph.d_max:
            return
        radius = self.rules.detach_radius
        assert radius is not None  # checked by the caller
        if target is not None:  # no more from its start to the target or the nodes beside it
            state.detached.extend(np.flatnonzero(near_either_way(p.D, target, radius)).tolist() + [target])
        else:  # no more to its goal from the source or the nodes beside it
            assert source is not None
            state.goal_detached.extend(np.flatnonzero(near_either_way(p.D, source, radius)).tolist() + [source])

    def stuck(self, controller: Any, agent: str, ob: np.ndarray, current: AgentPlan) -> AgentPlan:
        """The controller's ``replan`` callback for a stuck agent (see the module's docstring)."""
        t1 = time.perf_counter()
        p = self.planner
        state = self.episode.states[agent]
        n_nodes = len(p.observations)
        k = controller.index[agent]
        route = state.route
        leg = state.leg(k)
        if leg is not None and leg.source is not None and leg.target is not None and leg.source != leg.target:
            state.failed_edges.extend(edges_near(p.D, leg.source, leg.target, self.rules.ban_radius))
            self.memory.record_failure(leg.source, leg.target)
        if leg is not None and self.rules.detach_radius is not None:
            self._detach(state, ob, leg.source, leg.target)
        # the failed waypoint (on the last leg: the waypoint the goal was approached from) and the
        # nodes right by it
        f = route[k] if k < len(route) else (route[-1] if route else n_nodes)
        if f < n_nodes:
            near = near_either_way(p.D, f, self.rules.ban_radius)
            state.failed.append(f)
            state.banned.extend(np.flatnonzero(near).tolist() + [f])
        attempts, plans = self._attempts(agent)
        sub, banned = self._first_solved(agent, ob, attempts, narrow=(0, plans))
        if sub.solved:
            state.banned = banned
            new = self._install(controller, agent, sub)
        else:  # no other way on the graph: give the waypoint up
            new = AgentPlan(current.waypoints[k + 1:], current.goal)
            state.route = route[k + 1:]
            if state.problem is not None:  # the rest of the route, from here
                state.planned_at = controller.t
            state.seen_index = 0
        self.episode.replan_time += time.perf_counter() - t1
        return new

    def _attempts(self, agent: str, shared: bool = False) -> Tuple[List[Tuple[Any, ...]], int]:
        """The replans to try for ``agent`` in turn (see the module's docstring; ``shared``: leaving out
        the edges every agent failed on this episode, not only its own), each
        ``(nodes banned from now on, nodes left out of this plan, edges left out, whether no edge may
        pass a parked agent, (nodes not linked to the start, nodes not linked to the goal))``, and how
        many of them leave out the detached links (the same number follow without them, then the
        attempts over more edges)."""
        state = self.episode.states[agent]
        edges = self.exclude_edges(agent, shared)
        parked = self.parked_nodes(agent)
        plans: List[Tuple[Any, ...]] = [
            (state.banned, state.banned + parked, edges, True),
            (list(state.failed), state.failed + parked, edges, True), ([], parked, edges, True),
            *[([], self.parked_nodes(agent, share), edges, True) for share in (0.85, 0.7)],
            ([], [], edges, True), ([], parked, edges, False)]
        none: Tuple[List[int], List[int]] = ([], [])
        detached = (sorted(set(state.detached)), sorted(set(state.goal_detached)))
        learned = edges if shared else self.memory.removed()
        attempts = [(*a, detached) for a in plans] + [(*a, none) for a in plans] + [
            ([], [], learned, False, detached), ([], [], learned, False, none), ([], [], None, False, none)]
        return attempts, len(plans)

    def _first_solved(self, agent: str, ob: np.ndarray, attempts: List[Tuple[Any, ...]],
                      narrow: Tuple[int, ...] = ()) -> Tuple[Any, List[int]]:
        """The first solved plan of ``attempts`` (:meth:`_attempts`) for ``agent`` standing at ``ob``
        (else the last one tried), with the nodes it bans from now on. An attempt of index in
        ``narrow`` that is solved gives way to the next one where that is ``ban_detour`` shorter."""
        p, ep = self.planner, self.episode
        goal = ep.states[agent].goal
        # where the agents that arrived stand (last seen), parked
        at = [o for o in (ep.states[b].last_obs for b in ep.parked(agent)) if o is not None]

        def attempt(exclude, exclude_edges, avoid, detach) -> Any:
            return p.plan(ob[None], goal[None], budget=self.budget, exclude=exclude,
                          exclude_edges=exclude_edges, avoid=np.stack(at) if avoid and at else None,
                          detached=detach[0], goal_detached=detach[1])

        tried = []
        sub: Any = None
        banned: List[int] = []
        detour = self.rules.ban_detour
        for j, (banned, exclude, exclude_edges, avoid, detach) in enumerate(attempts):
            key = (sorted(exclude), None if exclude_edges is None else exclude_edges.tolist(), avoid and bool(at),
                   detach)
            if key in tried:
                continue
            tried.append(key)
            sub = attempt(exclude, exclude_edges, avoid, detach)
            if sub.solved:
                # around the neighbourhood, unless around the failed waypoints alone (the next attempt) is
                # much shorter
                if math.isfinite(detour) and j in narrow:
                    alt = attempt(*attempts[j + 1][1:])
                    if alt.solved and alt.soc is not None and sub.soc is not None and alt.soc + detour < sub.soc:
                        sub, banned = alt, attempts[j + 1][0]
                        ep.narrow_replans += 1
                break
        return sub, banned

    def _install(self, controller: Any, agent: str, sub: Any) -> AgentPlan:
        """The controller's plan for ``agent`` from the solved single-agent plan ``sub``; its route,
        heading past the waypoints it failed on twice that the route cannot avoid."""
        assert sub.problem is not None  # a solved plan keeps its problem graph
        state = self.episode.states[agent]
        new = sub.agent_plans([agent], hold="waits")[agent]
        keep = past_failed_waypoints(sub.nodes[0], sub.problem.goal_ids[0], sub.problem.D, state.failed,
                                     straight=self._straight(sub.problem))
        # kept as long as the route: its matrices as the buffer's and a border, not a copy of them
        state.set_route([sub.nodes[0][i] for i in keep], sub.problem.compact(self.planner.D, self.planner.C),
                        sub.problem.goal_ids[0], controller.t)
        return AgentPlan(new.waypoints[keep], new.goal, np.asarray(new.depart_times)[keep].tolist(), True)

    def repair_routes(self, controller: Any, current: Dict[str, np.ndarray]) -> None:
        """Plan anew for each agent in ``current`` that is about to set off along an edge another agent
        failed on in this episode (or right beside it: :func:`~agents.search.execution.repair.edges_near`), or
        that the memory removed since its route was made; around those edges. Where no such route
        exists, or it is more than ``REPAIR_STRETCH`` times as long, it keeps its own."""
        ep = self.episode
        if not any(ep.states[b].failed_edges for b in ep.agents) and not len(self.memory.removed()):
            return  # nothing failed yet: legs are checked from the first failure on
        holding = controller.stats.holding
        fresh = []  # the agents on a leg not checked yet
        for agent in current:
            state = ep.states[agent]
            if state.problem is None or holding.get(agent):
                continue  # a held agent waits for others in the plan's order: checked when it sets off
            plan, k = controller.plans[agent], controller.index[agent]
            seen = state.leg_checked
            if seen is None or seen[0] is not plan or seen[1] != k:
                state.leg_checked = (plan, k)
                fresh.append(agent)
        if not fresh:
            return
        failed = {b: {(int(u), int(v)) for u, v in ep.states[b].failed_edges} for b in ep.agents}
        removed = {(int(u), int(v)) for u, v in self.memory.removed()}
        for agent in fresh:
            state = ep.states[agent]
            leg = state.leg(controller.index[agent])
            if leg is None or leg.source is None or leg.target is None:
                continue
            edge = (leg.source, leg.target)
            others = removed.union(*[f for b, f in failed.items() if b != agent])
            if edge in failed[agent] or edge not in others:
                continue  # its own failed edges are left out of its replans already
            t1 = time.perf_counter()
            # all but the attempt over every edge; standing at the leg's source, its start links to none
            # of the nodes those edges lead to from there
            beyond = {v for u, v in others if u == leg.source}
            attempts = [(*a[:4], (sorted(beyond.union(a[4][0])), a[4][1]))
                        for a in self._attempts(agent, shared=True)[0][:-1]]
            sub, _ = self._first_solved(agent, current[agent], attempts)
            if sub is not None and sub.solved and sub.soc is not None \
                    and sub.soc <= REPAIR_STRETCH * state.rest_of_route(controller.index[agent]):
                controller.set_plan(agent, self._install(controller, agent, sub))
                state.leg_checked = (controller.plans[agent], 0)
                ep.route_repairs += 1
            ep.replan_time += time.perf_counter() - t1


__all__ = ["REPAIR_STRETCH", "Replanner"]
