"""The conventions of the paper's published evaluation code (``safe-mapf evaluate --protocol paper``).

The paper's Table I was produced by its authors' code with conventions its text does not
state. This module follows them where they are conventions, so that our agents can be put
next to the paper's numbers on the same setting (``SafeCenterDot-v0``):

- **problems**: for each draw, ``candidates`` random free starts and as many random free
  goals; the ``per_draw`` (start, goal) pairs whose direct predicted distance (unconstrained
  critic, ensemble mean) is nearest to the target are kept. Targets are the map's largest
  8-connected grid distance (hops on the resized occupancy grid) floor-divided by 8 / 4 / 2
  (easy / medium / hard: 2, 4 and 8 on CenterDot); on the apartments, which have no occupancy
  grid, the diameter is the largest geodesic distance in steps (:func:`step_diameter`; our
  analogue for the paper's Table II, whose scenes ran in Habitat). A problem of ``K`` agents
  takes ``K`` consecutive pairs;
- **graph**: ``n_nodes`` random free states, pessimistic (max) ensemble aggregation,
  ``d_max = 7``. SoRB's graph uses the unconstrained critic's distances; ours uses the
  constrained critic's distances and the unconstrained critic's costs; an edge is kept where
  the distance is below ``d_max`` (and, for ours, the cost below ``c_max``);
- **search** by hop count (unweighted shortest paths), each agent on its own: the agents pass
  through each other (the env's ``agent_collisions=False``), so nobody waits or yields and
  joint planning has nothing to resolve. Start and goal attach only to buffer nodes (by the
  same edge rule), so every plan has at least one waypoint;
- **execution**: waypoints followed open loop, advancing to the next one (at most one per
  step) when the executing agent's own critic predicts less than ``advance_distance`` (2)
  steps to the current one; a search that finds no path for some agent is replaced by the
  plain policy's run on the same problem (``plan_status = "fallback"``);
- **cost**: each agent's cumulative cost until it arrives (the start state's cost included
  for single-agent runs); the table value is the largest over agents, averaged over the runs
  in which every agent arrived; 300 steps;
- **c_max** = the constrained agent's training cost limit x {0.1, 0.25, 0.5, 0.75, 1.0}; each
  cell reports the best of the five (:func:`choose_best_c_max`), chosen **on the test problems
  themselves**: an optimistic choice, labelled as such wherever it is reported.

The published code's CBS checks conflicts only at time 0; with agents that pass through each
other that is moot, and it is not reproduced.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from agents.run_folder import write_atomic

from .evaluation import DIFFICULTIES, Problem, check_kept_rows, markdown_table, write_csv
from .harness import run_tasks
from .methods import MARL_METHODS, Method
from .metrics import aggregate

#: the published code's c_max grid, as factors of the trained cost limit
PAPER_C_MAX_FACTORS = (0.1, 0.25, 0.5, 0.75, 1.0)
#: the methods the paper's conventions define (``ours_budget`` is ours alone)
PAPER_PROTOCOL_METHODS = ("unconstrained_policy", "sorb", "constrained_policy", "ours")


def grid_diameter(layout: Any) -> int:
    """The largest finite hop distance between free cells of the map's occupancy grid resized by
    its (integer) resize factor, with 8-connected moves (diagonals between any two free cells),
    as the published code measures a map's size."""
    from safe_mapf_envs.maps import get_map

    m = get_map(layout) if isinstance(layout, str) else layout
    f = int(round(m.resize_factor))
    grid = np.kron(m.grid.astype(np.uint8), np.ones((f, f), np.uint8)).astype(bool)
    h, w = grid.shape
    ids = np.arange(h * w).reshape(h, w)
    rows, cols = [], []
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if not (di or dj):
                continue
            a = ids[max(0, -di):h - max(0, di), max(0, -dj):w - max(0, dj)]
            b = ids[max(0, di):h + min(0, di) or None, max(0, dj):w + min(0, dj) or None]
            ok = ~grid.ravel()[a] & ~grid.ravel()[b]
            rows.append(a[ok])
            cols.append(b[ok])
    r, c = np.concatenate(rows), np.concatenate(cols)
    adj = sparse.csr_matrix((np.ones(len(r)), (r, c)), shape=(h * w, h * w))
    free = np.flatnonzero(~grid.ravel())
    hops = dijkstra(adj, directed=False, indices=free, unweighted=True)[:, free]
    return int(hops[np.isfinite(hops)].max())


def step_diameter(env: Any) -> int:
    """The largest geodesic distance between two free places of ``env``'s map, in steps of an
    agent at full speed (the ground-truth oracle): the map's size on maps without an occupancy
    grid (the apartments), where :func:`grid_diameter` does not apply. On CenterDot it reads 19
    steps against the grid's 17 hops."""
    u = env.unwrapped
    return int(u.scenario.oracle.max_distance / float(u.action_scale))


def paper_targets(layout: Any, diameter: Optional[int] = None) -> Dict[str, int]:
    """Target predicted distances per difficulty: the map's diameter floor-divided by 8 / 4 / 2:
    ``diameter`` where given (e.g. :func:`step_diameter` on the apartments), else
    :func:`grid_diameter` of the grid map ``layout``."""
    d = grid_diameter(layout) if diameter is None else int(diameter)
    return {name: int(d // div) for name, div in DIFFICULTIES.items()}


@dataclass
class PaperSetup:
    """Graph nodes and matrices of the paper's protocol; build it with :meth:`build`.

    ``D_unc``/``C_unc``: the unconstrained critics' distances and costs between nodes (max over
    the ensemble); ``D_con``: the constrained critics' distances.
    """

    env_id: str
    models: Dict[str, Any]
    states: np.ndarray
    observations: np.ndarray
    D_unc: np.ndarray
    C_unc: np.ndarray
    D_con: np.ndarray
    d_max: float = 7.0
    advance_distance: float = 2.0
    targets: Dict[str, int] = field(default_factory=dict)
    _graphs: Dict[Tuple[str, float], sparse.csr_matrix] = field(default_factory=dict, init=False, repr=False)

    @classmethod
    def build(cls, env_id: str, models: Dict[str, Any], n_nodes: int = 1000, seed: int = 0,
              **kwargs) -> "PaperSetup":
        import gymnasium as gym

        import safe_mapf_envs  # noqa: F401  (registers the ids)
        from safe_mapf_envs.maps import MAPS
        from safe_mapf_envs.registration import env_spec

        layout = env_spec(env_id).layout
        env = gym.make(env_id)
        try:
            u: Any = env.unwrapped
            states = u.sample_states(n_nodes, np.random.default_rng(seed))
            obs = np.asarray(u.observations_at(states))
            targets = paper_targets(layout, None if layout in MAPS else step_diameter(env))
        finally:
            env.close()
        D_unc, C_unc = models["unconstrained"].pairwise(obs, obs, aggregate="max")
        D_con = models["constrained"].pairwise_distance(obs, obs, aggregate="max")
        return cls(env_id, models, states, obs, np.asarray(D_unc, np.float64), np.asarray(C_unc, np.float64),
                   np.asarray(D_con, np.float64), targets=targets, **kwargs)

    @property
    def cost_limit(self) -> float:
        """The constrained agent's training cost limit (the scale of the c_max grid)."""
        return float(self.models["constrained"].lagrangian.cost_limit)

    def c_max_grid(self, factors: Sequence[float] = PAPER_C_MAX_FACTORS) -> List[float]:
        return [float(f"{self.cost_limit * f:.6g}") for f in factors]

    def _distance_model(self, method: Method) -> str:
        return "constrained" if math.isfinite(method.c_max) else "unconstrained"

    def buffer_graph(self, method: Method) -> sparse.csr_matrix:
        """The buffer nodes' edges of ``method`` (boolean adjacency, cached per method and c_max)."""
        key = (self._distance_model(method), float(method.c_max))
        if key not in self._graphs:
            D = self.D_con if key[0] == "constrained" else self.D_unc
            keep = (D < self.d_max) & (self.C_unc < method.c_max)
            np.fill_diagonal(keep, False)
            self._graphs[key] = sparse.csr_matrix(keep)
        return self._graphs[key]

    def plan_hops(self, method: Method, start_obs: np.ndarray, goal_obs: np.ndarray) -> List[Optional[np.ndarray]]:
        """Per agent, the buffer node ids of its fewest-hop route (at least one), or ``None``
        where the start or the goal cannot reach the graph or no route exists."""
        unc = self.models["unconstrained"]
        dist_model = self.models[self._distance_model(method)]
        base = self.buffer_graph(method)
        ds = dist_model.pairwise_distance(start_obs, self.observations, aggregate="max", progress=False)
        dg = dist_model.pairwise_distance(self.observations, goal_obs, aggregate="max", progress=False)
        if math.isfinite(method.c_max):  # ours: endpoint edges are cut on the unconstrained costs too
            cs = unc.pairwise_cost(start_obs, self.observations, aggregate="max", progress=False)
            cg = unc.pairwise_cost(self.observations, goal_obs, aggregate="max", progress=False)
        else:  # SoRB: distances only
            cs, cg = np.zeros_like(ds), np.zeros_like(dg)
        routes: List[Optional[np.ndarray]] = []
        for i in range(len(start_obs)):
            first = np.flatnonzero((ds[i] < self.d_max) & (cs[i] < method.c_max))  # start -> node
            last = np.flatnonzero((dg[:, i] < self.d_max) & (cg[:, i] < method.c_max))  # node -> goal
            if not len(first) or not len(last):
                routes.append(None)
                continue
            # hops from the nearest first node (multi-source BFS), then the nearest last node
            hops, pred, _ = dijkstra(base, directed=True, indices=first, unweighted=True, min_only=True,
                                     return_predecessors=True)
            end = last[np.argmin(hops[last])]
            if not np.isfinite(hops[end]):
                routes.append(None)
                continue
            path = [int(end)]
            while pred[path[-1]] >= 0:
                path.append(int(pred[path[-1]]))
            routes.append(np.array(path[::-1], dtype=np.int64))
        return routes


def make_paper_problems(setup: PaperSetup, difficulty: str, n_agents: int, n_problems: int, seed: int = 0,
                        candidates: int = 1000, per_draw: int = 5) -> List[Problem]:
    """``n_problems`` problems of ``n_agents`` agents drawn as the published code does (see the
    module docstring), reproducible from ``seed``. ``Problem.graph_distance`` holds each
    pair's predicted distance; the node ids are ``-1`` (starts and goals are not graph nodes)."""
    import gymnasium as gym

    if difficulty not in setup.targets:
        raise ValueError(f"unknown difficulty {difficulty!r}; choose from {', '.join(setup.targets)}")
    if n_agents < 1 or n_problems < 1 or candidates < 1 or per_draw < 1:
        raise ValueError("n_agents, n_problems, candidates and per_draw must all be >= 1")
    target = float(setup.targets[difficulty])
    unc = setup.models["unconstrained"]
    env = gym.make(setup.env_id)
    u: Any = env.unwrapped
    rng = np.random.default_rng([seed, n_agents, list(DIFFICULTIES).index(difficulty), 7])
    starts, goals, dists = [], [], []
    try:
        while len(starts) < n_problems * n_agents:
            s = u.sample_states(candidates, rng)
            g = u.sample_states(candidates, rng)
            D = unc.pairwise_distance(u.observations_at(s), u.observations_at(g), aggregate="mean", progress=False)
            gap = np.abs(np.asarray(D, np.float64) - target).ravel()
            k = min(per_draw, gap.size)
            best = np.argpartition(gap, k - 1)[:k]
            best = best[np.argsort(gap[best], kind="stable")]
            i, j = np.unravel_index(best, D.shape)
            starts += list(s[i])
            goals += list(g[j])
            dists += list(np.asarray(D)[i, j])
    finally:
        env.close()
    out = []
    none = -np.ones(n_agents, np.int64)
    for p in range(n_problems):
        sl = slice(p * n_agents, (p + 1) * n_agents)
        out.append(Problem(difficulty, p, target, none, none, np.array(starts[sl]), np.array(goals[sl]),
                           np.array(dists[sl], np.float64)))
    return out


@dataclass
class PaperExecution:
    """One run under the paper's conventions (arrays per agent)."""

    success: bool
    reached: np.ndarray
    cost: np.ndarray
    steps: int
    plan_status: str
    waypoints: List[int]
    trajectories: np.ndarray


def execute_paper(env, setup: PaperSetup, method: Method, problem: Problem, seed: int = 0) -> PaperExecution:
    """Run ``method`` on ``problem`` in ``env`` (a parallel env with ``agent_collisions=False``)."""
    from agents.search.models import distance_fn, policy_fn

    if method.policy in MARL_METHODS:  # the MARL policy alone, cost counted as below
        from .marl_rows import execute_marl

        ex = execute_marl(env, setup.models[method.policy], problem.starts, problem.goals, seed=seed,
                          count_start_cost=True)
        return PaperExecution(ex.success, ex.reached, ex.cost, ex.steps, "direct", [0] * len(ex.reached),
                              ex.trajectories)
    model = setup.models[method.policy]
    act, dist = policy_fn(model), distance_fn(model)
    obs, infos = env.reset(seed=seed, options={"starts": problem.starts, "goals": problem.goals})
    names = list(env.agents)
    k = len(names)
    index = {a: i for i, a in enumerate(names)}
    goal_obs = np.stack([obs[a]["desired_goal"] for a in names])
    start_obs = np.stack([obs[a]["observation"] for a in names])
    status = "direct"
    targets: List[np.ndarray] = [goal_obs[i][None] for i in range(k)]
    n_wp = [0] * k
    if method.search:
        routes = setup.plan_hops(method, start_obs, goal_obs)
        if any(r is None for r in routes):
            status = "fallback"  # the plain policy's run on the same problem
        else:
            status = "planned"
            targets = [np.concatenate([setup.observations[r], goal_obs[i][None]]) for i, r in enumerate(routes)]
            n_wp = [len(r) for r in routes]
    pos = [0] * k  # index of each agent's current target
    cost = np.zeros(k)
    if k == 1:  # the published code counts the start state's cost of a lone agent
        cost[0] += float(infos[names[0]].get("obstacle_cost", infos[names[0]]["cost"]))
    reached = np.zeros(k, dtype=bool)
    traj = [env.positions]
    steps = 0
    while env.agents:
        live = [index[a] for a in env.agents]
        o = np.stack([obs[names[i]]["observation"] for i in live])
        cur = np.stack([targets[i][pos[i]] for i in live])
        ahead = [j for j, i in enumerate(live) if pos[i] < len(targets[i]) - 1]
        if ahead:  # open loop: advance at most one waypoint per step
            near = dist(o[ahead], cur[ahead]) < setup.advance_distance
            for j in np.asarray(ahead)[near]:
                pos[live[j]] += 1
                cur[j] = targets[live[j]][pos[live[j]]]
        actions = act(o, cur)
        obs, _, term, _, infos = env.step({names[i]: actions[j] for j, i in enumerate(live)})
        steps += 1
        traj.append(env.positions)
        for a, info in infos.items():
            cost[index[a]] += float(info.get("obstacle_cost", info["cost"]))
            if term.get(a, False):
                reached[index[a]] = True
    return PaperExecution(bool(reached.all()), reached, cost, steps, status, n_wp, np.stack(traj))


def evaluate_paper(
    setup: PaperSetup,
    methods: Sequence[Method],
    agent_counts: Sequence[int] = (1, 5, 10, 20),
    difficulties: Sequence[str] = tuple(DIFFICULTIES),
    n_problems: int = 50,
    seed: int = 0,
    max_cycles: int = 300,
    progress: bool = True,
    policy_agents: Optional[Sequence[int]] = None,
    factors: Sequence[float] = PAPER_C_MAX_FACTORS,
    candidates: int = 1000,
    on_row: Optional[Callable[[Dict[str, Any]], None]] = None,
    ray: Optional[str] = None,
    kept: Sequence[Dict[str, Any]] = (),
) -> List[Dict[str, Any]]:
    """Every method on the same paper-protocol problems; ``ours`` once per c_max of the grid.

    One row per (method, c_max, agents, difficulty, problem), with the fields of
    :data:`~baselines.evaluation.ROW_FIELDS` (``collisions`` is 0: agents pass through each
    other; ``planning_time`` is not measured). ``policy_agents`` restricts the methods without
    search to these agent counts (the paper: 1). ``on_row(row)`` is called after each run, in the
    order of the rows (e.g. to write rows as they come). ``ray`` runs the runs as Ray tasks, as
    :func:`~baselines.evaluation.evaluate` does: the same rows in the same order. ``kept``: the rows
    of an interrupted evaluation with the same arguments, as in :func:`~baselines.evaluation.evaluate`.
    """
    if ray is not None:
        from .distributed import require_ray

        require_ray()  # fail before any work if Ray is missing
    unknown = [m.name for m in methods if m.name not in PAPER_PROTOCOL_METHODS + MARL_METHODS]
    if unknown:
        raise ValueError(f"the paper's protocol defines {', '.join(PAPER_PROTOCOL_METHODS)}; not {unknown}")
    grid = setup.c_max_grid(factors)
    runs: List[Tuple[Method, Problem]] = []
    for k in agent_counts:
        for d in difficulties:
            problems = make_paper_problems(setup, d, k, n_problems, seed=seed, candidates=candidates)
            for m in methods:
                if not m.search and policy_agents is not None and k not in policy_agents:
                    continue
                variants = [m.with_options(c_max=c) for c in grid] if math.isfinite(m.c_max) else [m]
                runs += [(v, p) for v in variants for p in problems]
    check_kept_rows(kept, runs, with_c_max=True)
    return run_tasks(setup, runs, paper_row, seed=seed, max_cycles=max_cycles, kept=kept,
                     env_kwargs={"agent_collisions": False},
                     on_run=None if on_row is None else lambda row, _problem, _ex: on_row(row),
                     progress=progress, desc="evaluate (paper protocol)", ray=ray)


def paper_row(setup: PaperSetup, env, method: Method, problem: Problem, seed: int,
              memory: Any = None) -> Tuple[Dict[str, Any], PaperExecution]:
    """Run ``method`` on ``problem`` in ``env`` under the paper's conventions; returns ``(row, execution)``.
    The run is seeded with ``seed + problem.index`` wherever it runs; ``memory`` is not used (the
    paper's graph learns nothing; the argument keeps the signature of the Ray workers' runs)."""
    ex = execute_paper(env, setup, method, problem, seed=seed + problem.index)
    row = {
        "method": method.name, "agents": problem.n_agents, "difficulty": problem.difficulty, "problem": problem.index,
        "success": ex.success, "cost_max": float(ex.cost.max()), "cost_mean": float(ex.cost.mean()),
        "collisions": 0, "steps": ex.steps, "planning_time": 0.0, "plan_status": ex.plan_status,
        "reached": int(ex.reached.sum()), "c_max": method.c_max if method.search else math.inf,
    }
    return row, ex


def choose_best_c_max(rows: Sequence[Dict[str, Any]], method: str = "ours"
                      ) -> Tuple[List[Dict[str, Any]], Dict[Tuple[int, str], float]]:
    """The published code's per-cell choice, made **on the test runs themselves**: for each
    (agents, difficulty) cell, the c_max of ``method`` with the highest success rate, ties
    broken by the lowest mean largest cumulative cost over the successful runs. Returns the rows
    with only the chosen c_max kept for ``method``, and the choice per cell."""
    by_cell: Dict[Tuple[int, str], Dict[float, List[Dict[str, Any]]]] = {}
    for r in rows:
        if r["method"] == method:
            by_cell.setdefault((int(r["agents"]), r["difficulty"]), {}).setdefault(float(r["c_max"]), []).append(r)
    chosen: Dict[Tuple[int, str], float] = {}
    for cell, groups in by_cell.items():
        def score(item):
            c, rs = item
            ok = [float(r["cost_max"]) for r in rs if r["success"]]
            return (-len(ok) / len(rs), float(np.mean(ok)) if ok else math.inf, -c)

        chosen[cell] = min(groups.items(), key=score)[0]
    kept = [r for r in rows if r["method"] != method
            or float(r["c_max"]) == chosen[(int(r["agents"]), r["difficulty"])]]
    return kept, chosen


def write_paper_outputs(rows: Sequence[Dict[str, Any]], out: Any, methods: Sequence[str], *, env_id: str,
                        n_problems: int, seed: int, wall: float, cost_limit: float, grid: Sequence[float],
                        targets: Dict[str, int]) -> Tuple[List[Dict[str, Any]], str]:
    """Write the tables of paper-protocol ``rows`` into the folder ``out`` (``table.csv``,
    ``table.json``, ``table.md`` and ``c_max.json``: ours' c_max chosen per cell on these runs,
    :func:`choose_best_c_max`); ``runs.csv`` is the caller's. Returns the aggregated rows and the
    Markdown text (header and table) of ``table.md``."""
    out = Path(out)
    kept, chosen = choose_best_c_max(rows)
    agg = aggregate(kept)
    write_csv(agg, out / "table.csv")
    write_atomic(out / "table.json", json.dumps(agg, indent=1))
    write_atomic(out / "c_max.json", json.dumps(
        {"chosen_on": "the test problems (the published code's convention)", "cost_limit": cost_limit,
         "grid": list(grid), "targets": targets,
         "chosen": [{"agents": k, "difficulty": d, "c_max": c} for (k, d), c in sorted(chosen.items())]}, indent=1))
    header = (f"{env_id}, the paper's protocol: largest cumulative cost over agents until arrival, mean ± std over "
              f"successful runs (success rate); {n_problems} problem{'s' if n_problems != 1 else ''} per cell, "
              f"seed {seed}, {wall:.0f} s; targets {targets}\n\n")
    if chosen:
        cells = ", ".join(f"{d} {k}: {c:g}" for (k, d), c in sorted(chosen.items()))
        listed = ", ".join(f"{c:g}" for c in grid)
        header += f"ours: c_max per cell chosen ON THE TEST PROBLEMS from {listed}: {cells}\n\n"
    text = header + markdown_table(agg, list(methods))
    write_atomic(out / "table.md", text + "\n")
    return agg, text


__all__ = ["PAPER_C_MAX_FACTORS", "PAPER_PROTOCOL_METHODS", "PaperExecution", "PaperSetup", "choose_best_c_max",
           "evaluate_paper", "execute_paper", "grid_diameter", "make_paper_problems", "paper_row", "paper_targets",
           "step_diameter", "write_paper_outputs"]
