"""What :class:`~agents.search.policy.SearchPolicy` does for an agent its controller finds stuck
(``replan_when_stuck``). A mixin: the policy keeps the episode state these methods read and write.

- The edge the agent was on is recorded: in its failed edges for this episode, with the edges
  between the nodes right by its two ends (:func:`~agents.search.repair.edges_near`: a critic that
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
  0.7 ban radii around the goals of parked agents, then past them. It tries these first without
  the detached links, then with them back (where it stands right by the node it failed to reach,
  they may be all it can link to); then over the edges it failed on itself, less those the memory
  removed (without the detached links, then with them); and at last over every edge (it was not
  where its route said when it failed, or another agent was in the way). Only if none is solved
  it gives the waypoint up.
- A waypoint it failed on twice that the new route cannot avoid, it heads past
  (:func:`~agents.search.repair.past_failed_waypoints`, with the critic's distance where the
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

from .config import SearchConfig
from .controller import AgentPlan
from .dependencies import nodes_near
from .repair import edges_near, near_either_way, past_failed_waypoints

#: a route repair (``repair_routes``) is taken only where its predicted length is at most this many
#: times that of the rest of the route it replaces
REPAIR_STRETCH = 2.0


class StuckReplanning:
    """Replans for stuck agents; mixed into :class:`~agents.search.policy.SearchPolicy`."""

    planner: Any
    controller: Any
    memory: Any
    config: SearchConfig
    narrow_replans: int
    route_repairs: int
    _leg_checked: Dict[str, Tuple[AgentPlan, int]]
    agents: List[str]
    routes: Dict[str, List[int]]
    replan_time: float
    _route_graph: Dict[str, Tuple[Any, int, int]]
    _banned: Dict[str, List[int]]
    _failed: Dict[str, List[int]]
    _failed_edges: Dict[str, List[Tuple[int, int]]]
    _detached: Dict[str, List[int]]
    _goal_detached: Dict[str, List[int]]
    _seen_index: Dict[str, int]
    _goals: Dict[str, np.ndarray]
    _last_obs: Dict[str, np.ndarray]
    _last_names: set
    leg: Callable[[str], Any]
    _distance: Callable[[np.ndarray, np.ndarray], np.ndarray]

    def _exclude_edges(self, agent: str, shared: bool = False) -> np.ndarray:
        """The edges ``agent``'s replans leave out: those the memory removed and those it failed on
        (``shared``: those any agent failed on this episode)."""
        own = [e for b in (self.agents if shared else [agent]) for e in self._failed_edges.get(b, [])]
        own_arr = np.asarray(own, dtype=np.int64).reshape(-1, 2)
        return np.unique(np.concatenate([self.memory.removed(), own_arr]), axis=0)

    def _parked_nodes(self, agent: str, share: float = 1.0) -> List[int]:
        """Buffer nodes within ``share * ban_radius`` predicted steps of the goals of the agents that have
        arrived (they are parked there, immovable): a replan for ``agent`` keeps clear of them."""
        parked = [self._route_graph[b][:2] for b in self.agents
                  if b != agent and b not in self._last_names and b in self._route_graph]
        r = share * self.config.replanning.ban_radius
        return [int(i) for problem, goal in parked for i in np.flatnonzero(nodes_near(problem, goal, r))]

    def _straight(self, problem: Any) -> Callable[[int, int], float]:
        """The critic's distance between two nodes of ``problem``: exact where its ``D`` holds only a bound."""
        d_max = self.planner.graph.d_max

        def straight(u: int, w: int) -> float:
            d = float(problem.D[u, w])
            if d < d_max:
                return d
            return float(self._distance(problem.observations[[u]], problem.observations[[w]])[0])

        return straight

    def _detach(self, agent: str, ob: np.ndarray, source: Optional[int], target: Optional[int]) -> None:
        """Detach the nodes beside the ends of the leg ``source -> target`` (buffer ids; ``None``: the
        agent's start or goal) where the critic now puts the target beyond two edges' reach."""
        p = self.planner
        goal = self._goals[agent]
        to = p.observations[[target]] if target is not None else goal[None]
        if source is None and target is None or float(self._distance(ob[None], to)[0]) < 2 * p.graph.d_max:
            return
        assert self.config.replanning.detach_radius is not None  # checked by the caller
        if target is not None:  # no more from its start to the target or the nodes beside it
            near = near_either_way(p.D, target, self.config.replanning.detach_radius)
            self._detached.setdefault(agent, []).extend(np.flatnonzero(near).tolist() + [target])
        else:  # no more to its goal from the source or the nodes beside it
            assert source is not None
            near = near_either_way(p.D, source, self.config.replanning.detach_radius)
            self._goal_detached.setdefault(agent, []).extend(np.flatnonzero(near).tolist() + [source])

    def _replan_stuck(self, agent: str, ob: np.ndarray, current: AgentPlan) -> AgentPlan:
        """The controller's callback for a stuck agent (see the module's docstring)."""
        assert self.planner is not None and self.controller is not None
        t1 = time.perf_counter()
        p = self.planner
        n_nodes = len(p.observations)
        k = self.controller.index[agent]
        route = self.routes[agent]
        leg = self.leg(agent)
        if leg is not None and leg.source is not None and leg.target is not None and leg.source != leg.target:
            radius = self.config.replanning.ban_radius
            self._failed_edges.setdefault(agent, []).extend(edges_near(p.D, leg.source, leg.target, radius))
            self.memory.record_failure(leg.source, leg.target)
        if leg is not None and self.config.replanning.detach_radius is not None:
            self._detach(agent, ob, leg.source, leg.target)
        # the failed waypoint (on the last leg: the waypoint the goal was approached from) and the
        # nodes right by it
        f = route[k] if k < len(route) else (route[-1] if route else n_nodes)
        if f < n_nodes:
            near = near_either_way(p.D, f, self.config.replanning.ban_radius)
            self._failed[agent].append(f)
            self._banned[agent].extend(np.flatnonzero(near).tolist() + [f])
        attempts, plans = self._attempts(agent)
        sub, banned = self._first_solved(agent, ob, attempts, narrow=(0, plans))
        if sub.solved:
            self._banned[agent] = banned
            new = self._install(agent, sub)
        else:  # no other way on the graph: give the waypoint up
            new = AgentPlan(current.waypoints[k + 1:], current.goal)
            self.routes[agent] = route[k + 1:]
            if agent in self._route_graph:  # the rest of the route, from here
                self._route_graph[agent] = (*self._route_graph[agent][:2], self.controller.t)
            self._seen_index[agent] = 0
        self.replan_time += time.perf_counter() - t1
        return new

    def _attempts(self, agent: str, shared: bool = False) -> Tuple[List[Tuple[Any, ...]], int]:
        """The replans to try for ``agent`` in turn (see the module's docstring; ``shared``: leaving out
        the edges every agent failed on this episode, not only its own), each
        ``(nodes banned from now on, nodes left out of this plan, edges left out, whether no edge may
        pass a parked agent, (nodes not linked to the start, nodes not linked to the goal))``, and how
        many of them leave out the detached links (the same number follow without them, then the
        attempts over more edges)."""
        edges = self._exclude_edges(agent, shared)
        parked = self._parked_nodes(agent)
        plans: List[Tuple[Any, ...]] = [
            (self._banned[agent], self._banned[agent] + parked, edges, True),
            (list(self._failed[agent]), self._failed[agent] + parked, edges, True), ([], parked, edges, True),
            *[([], self._parked_nodes(agent, share), edges, True) for share in (0.85, 0.7)],
            ([], parked, edges, False)]
        none: Tuple[List[int], List[int]] = ([], [])
        detached = (sorted(set(self._detached.get(agent, []))), sorted(set(self._goal_detached.get(agent, []))))
        learned = edges if shared else self.memory.removed()
        attempts = [(*a, detached) for a in plans] + [(*a, none) for a in plans] + [
            ([], [], learned, False, detached), ([], [], learned, False, none), ([], [], None, False, none)]
        return attempts, len(plans)

    def _first_solved(self, agent: str, ob: np.ndarray, attempts: List[Tuple[Any, ...]],
                      narrow: Tuple[int, ...] = ()) -> Tuple[Any, List[int]]:
        """The first solved plan of ``attempts`` (:meth:`_attempts`) for ``agent`` standing at ``ob``
        (else the last one tried), with the nodes it bans from now on. An attempt of index in
        ``narrow`` that is solved gives way to the next one where that is ``ban_detour`` shorter."""
        p = self.planner
        # where the agents that arrived stand (last seen), parked
        at = [self._last_obs[b] for b in self.agents if b != agent and b not in self._last_names]

        def attempt(exclude, exclude_edges, avoid, detach) -> Any:
            return p.plan(ob[None], self._goals[agent][None], budget=self.config.budget, exclude=exclude,
                          exclude_edges=exclude_edges, avoid=np.stack(at) if avoid and at else None,
                          detached=detach[0], goal_detached=detach[1])

        tried = []
        sub: Any = None
        banned: List[int] = []
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
                if math.isfinite(self.config.replanning.ban_detour) and j in narrow:
                    alt = attempt(*attempts[j + 1][1:])
                    if alt.solved and alt.soc is not None and sub.soc is not None \
                            and alt.soc + self.config.replanning.ban_detour < sub.soc:
                        sub, banned = alt, attempts[j + 1][0]
                        self.narrow_replans += 1
                break
        return sub, banned

    def _install(self, agent: str, sub: Any) -> AgentPlan:
        """The controller's plan for ``agent`` from the solved single-agent plan ``sub``; its route,
        heading past the waypoints it failed on twice that the route cannot avoid."""
        assert sub.problem is not None  # a solved plan keeps its problem graph
        new = sub.agent_plans([agent], hold="waits")[agent]
        keep = past_failed_waypoints(sub.nodes[0], sub.problem.goal_ids[0], sub.problem.D, self._failed[agent],
                                     straight=self._straight(sub.problem))
        self.routes[agent] = [sub.nodes[0][i] for i in keep]
        # kept as long as the route: its matrices as the buffer's and a border, not a copy of them
        self._route_graph[agent] = (sub.problem.compact(self.planner.D, self.planner.C), sub.problem.goal_ids[0],
                                    self.controller.t)
        self._seen_index[agent] = 0
        return AgentPlan(new.waypoints[keep], new.goal, np.asarray(new.depart_times)[keep].tolist(), True)

    def _rest_of_route(self, agent: str, k: int) -> float:
        """The predicted length of ``agent``'s route from the start of its leg ``k`` to its goal."""
        problem, goal, _ = self._route_graph[agent]
        nodes = [*self.routes[agent][max(k - 1, 0):], goal]
        return float(sum(problem.D[u, v] for u, v in zip(nodes[:-1], nodes[1:])))

    def _repair_routes(self, current: Dict[str, np.ndarray]) -> None:
        """Plan anew for each agent in ``current`` that is about to set off along an edge another agent
        failed on in this episode (or right beside it: :func:`~agents.search.repair.edges_near`), or
        that the memory removed since its route was made; around those edges. Where no such route
        exists, or it is more than ``REPAIR_STRETCH`` times as long, it keeps its own."""
        if not any(self._failed_edges.values()) and not len(self.memory.removed()):
            return  # nothing failed yet: legs are checked from the first failure on
        holding = self.controller.stats.holding
        fresh = []  # the agents on a leg not checked yet
        for agent in current:
            if agent not in self._route_graph or holding.get(agent):
                continue  # a held agent waits for others in the plan's order: checked when it sets off
            plan, k = self.controller.plans[agent], self.controller.index[agent]
            seen = self._leg_checked.get(agent)
            if seen is None or seen[0] is not plan or seen[1] != k:
                self._leg_checked[agent] = (plan, k)
                fresh.append(agent)
        if not fresh:
            return
        failed = {b: {(int(u), int(v)) for u, v in self._failed_edges.get(b, [])} for b in self.agents}
        removed = {(int(u), int(v)) for u, v in self.memory.removed()}
        for agent in fresh:
            leg = self.leg(agent)
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
                    and sub.soc <= REPAIR_STRETCH * self._rest_of_route(agent, self.controller.index[agent]):
                self.controller.set_plan(agent, self._install(agent, sub))
                self._leg_checked[agent] = (self.controller.plans[agent], 0)
                self.route_repairs += 1
            self.replan_time += time.perf_counter() - t1


__all__ = ["StuckReplanning"]
