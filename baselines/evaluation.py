"""The 2D evaluation of "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe Reinforcement Learning".

Protocol (the paper's section Experiments, on ``SafeCentralObstacle-v0``):

- a buffer graph of ``n_nodes`` observations of random free states, annotated by the
  unconstrained agent's critics and pruned at ``d_max``;
- problems from the unconstrained critic's predicted distances: each agent's start and goal
  are graph nodes whose shortest-path distance on the graph is within 20% of a target, the
  largest finite shortest-path distance divided by 8 (easy), 4 (medium) or 2 (hard), as the
  paper's code does; starts are pairwise apart (and goals too), so that agents can be placed;
- every method runs the same problems (fixed seeds); a run succeeds when every agent reaches
  its goal within ``max_cycles`` (300) steps;
- per run: success, cumulative cost (largest over agents, as in the paper, and the mean),
  inter-agent collisions, steps, planning time; aggregated as mean +- std over successful
  runs and the success rate.

:func:`evaluate` runs a grid of (method, agent count, difficulty) cells and returns per-run
rows; :func:`~baselines.metrics.aggregate` and :func:`markdown_table` turn them into the paper's Table I.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.sparse.csgraph import dijkstra

from agents.search.config import GraphConfig, SolverConfig, preset_for
from agents.search.execution.repair import EdgeMemory
from agents.search.graph.build import NodePairwise
from agents.search.graph.sparsify import two_way_consistent
from agents.search.models import default_second_opinion
from agents.search.planner import BufferPlanner

from .anatomy import failures_field
from .contact_anatomy import contact_reasons_field
from .cost_anatomy import cost_split_field
from .harness import run_tasks
from .methods import METHODS, Method, execute
from .metrics import DIFFICULTY_ORDER, mapf_metrics

DIFFICULTIES = dict(zip(DIFFICULTY_ORDER, (8.0, 4.0, 2.0)))


@dataclass
class Problem:
    """Start and goal positions (world units) of ``K`` agents, chosen from graph nodes."""

    difficulty: str
    index: int
    target: float
    start_nodes: np.ndarray
    goal_nodes: np.ndarray
    starts: np.ndarray
    goals: np.ndarray
    graph_distance: np.ndarray

    @property
    def n_agents(self) -> int:
        return len(self.starts)


@dataclass
class EvaluationSetup:
    """Everything the methods share: the env id, both agents, the graph nodes and their matrices.

    Build it with :meth:`build`; ``models`` maps ``"unconstrained"``/``"constrained"`` to a
    :class:`~agents.algorithm.SafeGoalTD3`. ``graph`` and ``solver`` configure the planner every
    search method starts from (default: the graph of
    :func:`~agents.search.config.preset_for` the unconstrained agent, the default solver); a
    method changes them with its options. ``bound``: a lower bound of the steps between
    observations (:meth:`build` sets the env's :meth:`~safe_mapf_envs.base.NavigationEnvBase.step_bound`
    for vector observations): the critics read only the start and goal pairs it puts within
    ``d_max`` (:class:`~agents.search.graph.build.NodePairwise`).
    """

    env_id: str
    models: Dict[str, Any]
    states: np.ndarray
    observations: np.ndarray
    D: np.ndarray
    C: np.ndarray
    min_separation: float = 2.5
    graph: Optional[GraphConfig] = None
    solver: Optional[SolverConfig] = None
    bound: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None
    shortest: np.ndarray = field(init=False, repr=False)
    planner: BufferPlanner = field(init=False, repr=False)

    def __post_init__(self) -> None:
        unc = self.models["unconstrained"]
        self.planner = BufferPlanner(
            self.observations, self.D, self.C, NodePairwise(unc, self.observations, "max", bound=self.bound),
            self.graph if self.graph is not None else preset_for(unc).graph, self.solver,
            second_opinion=default_second_opinion(unc, self.models.get("constrained")))
        # problem difficulty: shortest predicted distances on the planner's own buffer graph
        self.shortest = dijkstra(self.planner.buffer_graph.distance, directed=True)

    @classmethod
    def build(cls, env_id: str = "SafeCentralObstacle-v0", n_nodes: int = 1000, seed: int = 0,
              models: Optional[Dict[str, Any]] = None, sparsify: Optional[float] = None,
              **kwargs) -> "EvaluationSetup":
        """Load the shipped checkpoints (unless ``models`` is given) and build the graph's nodes
        (``sparsify``: then keep those that two-way consistency merging at that many steps keeps,
        :func:`~agents.search.graph.sparsify.two_way_consistent`)."""
        import gymnasium as gym

        import safe_mapf_envs  # noqa: F401 (registers the ids)
        from agents import load_pretrained

        if models is None:
            models = {k: load_pretrained(env_id, kind=k) for k in ("unconstrained", "constrained")}
        env = gym.make(env_id)
        rng = np.random.default_rng(seed)
        states = env.unwrapped.sample_states(n_nodes, rng)
        obs = np.asarray(env.unwrapped.observations_at(states))
        env.close()
        if env.unwrapped.obs_type == "vector":
            kwargs.setdefault("bound", env.unwrapped.step_bound())
        if "min_separation" not in kwargs:
            kwargs["min_separation"] = default_min_separation(env_id)
        D, C = models["unconstrained"].pairwise(obs, obs, aggregate="max")
        D, C = np.asarray(D, np.float64), np.asarray(C, np.float64)
        if sparsify is not None:
            kept = two_way_consistent(D, sparsify)
            states, obs, D, C = states[kept], obs[kept], D[np.ix_(kept, kept)], C[np.ix_(kept, kept)]
        return cls(env_id, models, states, obs, D, C, **kwargs)

    @property
    def max_finite_distance(self) -> float:
        """The largest finite shortest-path distance on the graph (the difficulty scale)."""
        s = self.shortest
        return float(s[np.isfinite(s)].max())

    def target(self, difficulty: str) -> float:
        if difficulty not in DIFFICULTIES:
            raise ValueError(f"unknown difficulty {difficulty!r}; choose from {', '.join(DIFFICULTIES)}")
        return self.max_finite_distance / DIFFICULTIES[difficulty]


def make_problems(setup: EvaluationSetup, difficulty: str, n_agents: int, n_problems: int, seed: int = 0,
                  tolerance: float = 0.2, min_separation: Optional[float] = None) -> List[Problem]:
    """``n_problems`` problems of ``n_agents`` agents at a difficulty, reproducible from ``seed``.

    Starts are at least ``min_separation`` world units apart (default: the setup's) and not
    near each other under the planner's proximity radius (goals likewise), so every agent can
    be placed and parked.
    """
    if min_separation is None:
        min_separation = setup.min_separation
    if n_agents < 1 or n_problems < 1:
        raise ValueError(f"need n_agents >= 1 and n_problems >= 1, got {n_agents}, {n_problems}")
    target = setup.target(difficulty)
    lo, hi = (1 - tolerance) * target, (1 + tolerance) * target
    sp = setup.shortest
    ok_pair = (sp >= lo) & (sp <= hi)
    pos = setup.states
    radius = setup.planner.graph.proximity_radius or 0.0
    near = (setup.D < radius) | (setup.D.T < radius)
    far = (np.linalg.norm(pos[:, None] - pos[None], axis=-1) >= min_separation) & ~near
    n = len(pos)
    rng = np.random.default_rng([seed, n_agents, list(DIFFICULTIES).index(difficulty)])
    problems = []
    for p in range(n_problems):
        for _attempt in range(200):
            free_s = np.ones(n, dtype=bool)
            free_g = np.ones(n, dtype=bool)
            s_ids, g_ids = [], []
            for _ in range(n_agents):
                cand_s = np.flatnonzero(free_s & ok_pair[:, free_g].any(axis=1))
                if not len(cand_s):
                    break
                s = int(rng.choice(cand_s))
                cand_g = np.flatnonzero(ok_pair[s] & free_g)
                g = int(rng.choice(cand_g))
                s_ids.append(s)
                g_ids.append(g)
                free_s &= far[s]
                free_g &= far[g]
            if len(s_ids) == n_agents:
                break
        else:
            article = "an" if difficulty[:1] in "aeiou" else "a"
            raise ValueError(f"could not place {n_agents} agent{'s' if n_agents != 1 else ''} for {article} "
                             f"{difficulty} problem "
                               f"(target {target:.1f}); use fewer agents or more graph nodes")
        s_ids, g_ids = np.array(s_ids), np.array(g_ids)
        problems.append(Problem(difficulty, p, target, s_ids, g_ids, pos[s_ids].copy(), pos[g_ids].copy(),
                                sp[s_ids, g_ids]))
    return problems


def default_min_separation(env_id: str) -> float:
    """How far apart the starts (and the goals) of a problem are by default: a quarter more than
    the multi-agent env's own spacing (2.5 units on the 2D maps, 1.125 m on the apartments)."""
    import safe_mapf_envs

    penv = safe_mapf_envs.parallel_env(env_id, n_agents=1)
    try:
        return 1.25 * float(penv.min_separation)
    finally:
        penv.close()


def placeable_agents(env_id: str, n_agents: int, n_nodes: int = 1000, seed: int = 0,
                     min_separation: Optional[float] = None, attempts: int = 200) -> Tuple[int, float]:
    """How many agents' starts a placement like :func:`make_problems`' puts on the graph nodes
    :meth:`EvaluationSetup.build` draws with ``seed``, ``min_separation`` apart (the setup's
    default), read from the nodes' positions alone, before any critic query: the most of up to
    ``attempts`` random greedy placements, stopping at ``n_agents``. The problems keep more
    constraints (difficulty, proximity), so a count this placement does not reach is out of
    reach for them too. Returns ``(count, min_separation)``."""
    import gymnasium as gym

    import safe_mapf_envs  # noqa: F401 (registers the ids)

    if min_separation is None:
        min_separation = default_min_separation(env_id)
    env = gym.make(env_id)
    pos = np.asarray(env.unwrapped.sample_states(n_nodes, np.random.default_rng(seed)))[:, :2]
    env.close()
    far = np.linalg.norm(pos[:, None] - pos[None], axis=-1) >= float(min_separation)
    rng = np.random.default_rng([seed, n_agents])
    best = 0
    for _ in range(attempts):
        free = np.ones(len(pos), dtype=bool)
        placed = 0
        while placed < n_agents and free.any():
            free &= far[int(rng.choice(np.flatnonzero(free)))]
            placed += 1
        best = max(best, placed)
        if best >= n_agents:
            break
    return best, float(min_separation)


ROW_FIELDS = ("method", "agents", "difficulty", "problem", "success", "cost_max", "cost_mean", "collisions",
              "safety_rate", "steps", "planning_time", "plan_status", "reached", "isr", "soc", "makespan", "c_max",
              "failures", "cost_split", "contact_reasons")

#: ``select_c_max`` draws its validation problems with the test seed plus this offset by default
VALIDATION_SEED_OFFSET = 10_000
#: :func:`learn_edge_memory` draws its problems with the test seed plus this offset by default
REPAIR_SEED_OFFSET = 20_000
#: quantiles of the graph's predicted edge costs that make the default c_max grid
C_MAX_QUANTILES = (0.25, 0.5, 0.75)


def _methods_for(methods: Sequence[Method], k: int, policy_agents: Optional[Sequence[int]],
                 c_max_by_agents: Optional[Dict[int, float]]) -> List[Method]:
    """The methods of a cell with ``k`` agents: policy-only ones only at ``policy_agents``
    (``None``: everywhere), constrained searches with the cell's chosen ``c_max``."""
    out = []
    for m in methods:
        if not m.search and policy_agents is not None and k not in policy_agents:
            continue
        if c_max_by_agents is not None and m.search and math.isfinite(m.c_max) and k in c_max_by_agents:
            m = m.with_options(c_max=float(c_max_by_agents[k]))
        out.append(m)
    return out


def run_row(setup: EvaluationSetup, env, method: Method, problem: Problem, seed: int,
            memory: Optional[EdgeMemory] = None):
    """Run ``method`` on ``problem`` in ``env``; returns ``(row, execution)``. The run is seeded with
    ``seed + problem.index``, wherever it runs; a search method plans with ``memory`` (its graph's
    :class:`~agents.search.execution.repair.EdgeMemory`; default: a new one)."""
    ex = execute(env, method, setup.models, setup.planner, problem.starts, problem.goals, seed=seed + problem.index,
                 node_positions=setup.states, memory=memory)
    row = {
        "method": method.name, "agents": problem.n_agents, "difficulty": problem.difficulty,
        "problem": problem.index, "success": ex.success, "cost_max": float(ex.cost.max()),
        "cost_mean": float(ex.cost.mean()), "collisions": ex.collisions, "safety_rate": ex.safety_rate,
        "steps": ex.steps,
        "planning_time": ex.planning_time, "plan_status": ex.plan_status, "reached": int(ex.reached.sum()),
        **mapf_metrics(ex.arrival, ex.steps),
        "c_max": method.c_max if method.search else math.inf, "failures": failures_field(ex.failures),
        "cost_split": cost_split_field(ex.cost_split, ex.cost),
        "contact_reasons": contact_reasons_field(ex.contact_reasons),
    }
    return row, ex


def evaluate(
    setup: EvaluationSetup,
    methods: Sequence[Method],
    agent_counts: Sequence[int] = (1, 5, 10, 20),
    difficulties: Sequence[str] = tuple(DIFFICULTIES),
    n_problems: int = 50,
    seed: int = 0,
    max_cycles: int = 300,
    progress: bool = True,
    on_run=None,
    policy_agents: Optional[Sequence[int]] = None,
    c_max_by_agents: Optional[Dict[int, float]] = None,
    desc: str = "evaluate",
    ray: Optional[str] = None,
    memories: Optional[Dict[str, EdgeMemory]] = None,
    kept: Sequence[Dict[str, Any]] = (),
) -> List[Dict[str, Any]]:
    """Run every method on the same problems; one row per (method, agents, difficulty, problem).

    ``policy_agents`` restricts the methods without search to these agent counts (the paper's
    Table II runs them on single agents only); ``c_max_by_agents`` sets the cost cut-off of the
    constrained searches per agent count (e.g. chosen by :func:`select_c_max`). Rows carry the
    ``c_max`` a method used (``inf`` for distance pruning only). ``on_run(row, problem,
    execution)`` is called after each run, in the order of the rows (e.g. to keep trajectories).

    ``ray`` runs the runs as Ray tasks (see :mod:`baselines.distributed`): ``"local"`` on this
    machine's cores, ``"auto"`` on the cluster this machine belongs to, or a cluster address.
    The rows are those of the serial evaluation, in the same order (timing fields aside).

    ``memories`` gives search methods (by name) the edge memory their graph learned before
    (:func:`learn_edge_memory`); every run plans with a frozen copy of it, so that no run learns
    from the test problems and the rows do not depend on the order of the runs.

    ``kept``: rows of an interrupted evaluation with the same arguments (the first rows, in order,
    as :class:`~baselines.output.RowWriter` wrote them); their runs are not run again, and they
    open the returned rows (``on_run`` is called for the new runs only).
    """
    if ray is not None:
        from .distributed import require_ray

        require_ray()  # fail before any work if Ray is missing
    tasks = []
    for k in agent_counts:
        for d in difficulties:
            problems = make_problems(setup, d, k, n_problems, seed=seed)
            tasks += [(m, prob) for m in _methods_for(methods, k, policy_agents, c_max_by_agents) for prob in problems]
    check_kept_rows(kept, tasks)
    frozen = {name: m.frozen_copy() for name, m in (memories or {}).items()}
    return run_tasks(setup, tasks, run_row, seed=seed, max_cycles=max_cycles, kept=kept, memories=frozen,
                     on_run=on_run, progress=progress, desc=desc, ray=ray)


def check_kept_rows(kept: Sequence[Dict[str, Any]], tasks: Sequence[Tuple[Method, Problem]],
                    with_c_max: bool = False) -> int:
    """How many of ``tasks`` (``(method, problem)``, in order) the ``kept`` rows of an interrupted
    evaluation already ran; ``ValueError`` unless they are the rows of the first tasks, in order
    (``with_c_max``: the methods' ``c_max`` tells their rows apart too)."""
    def key(m: Method, p: Problem) -> tuple:
        c_max = float(m.c_max) if m.search else math.inf  # as the rows have it
        return (m.name, p.n_agents, p.difficulty, p.index) + ((c_max,) if with_c_max else ())

    for j, row in enumerate(kept):
        try:
            got = (row["method"], int(row["agents"]), row["difficulty"], int(row["problem"])) + (
                (float(row["c_max"]),) if with_c_max else ())
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"kept row {j + 1} lacks method, agents, difficulty, problem or c_max: {row}") from None
        if j >= len(tasks) or got != key(*tasks[j]):
            want = key(*tasks[j]) if j < len(tasks) else "no run"
            raise ValueError(f"kept row {j + 1} is the run {got}, where this evaluation's run {j + 1} is {want}: the "
                             "rows come from an evaluation with other settings")
    return len(kept)


def learn_edge_memory(
    setup: EvaluationSetup,
    methods: Sequence[Method],
    agent_counts: Sequence[int],
    difficulties: Sequence[str] = tuple(DIFFICULTIES),
    n_problems: int = 10,
    seed: int = REPAIR_SEED_OFFSET,
    test_seed: Optional[int] = None,
    limit: int = 1,
    max_cycles: int = 300,
    progress: bool = True,
    policy_agents: Optional[Sequence[int]] = None,
    c_max_by_agents: Optional[Dict[int, float]] = None,
    ray: Optional[str] = None,
) -> Dict[str, EdgeMemory]:
    """What each search method's graph learns on repair problems: the edges its agents fail on.

    Every search method among ``methods`` runs ``n_problems`` problems per cell drawn with ``seed``
    (never ``test_seed``: the graph must not learn the test problems); each run starts from an
    empty :class:`~agents.search.execution.repair.EdgeMemory` and the runs' memories are added up, so the
    result does not depend on the order of the runs (serial or ``ray``). Returns one frozen memory
    per method name, with removal at ``limit`` failures.
    """
    if test_seed is not None and seed == test_seed:
        raise ValueError(f"the repair seed must differ from the test seed {test_seed}: a graph that learns "
                         "on the test problems would overstate the method")
    search = [m for m in methods if m.search]
    memories = {m.name: EdgeMemory(len(setup.observations), limit) for m in search}

    def learn(row, _problem, ex) -> None:
        memories[row["method"]].update(ex.extra["memory"])

    if search:
        evaluate(setup, search, agent_counts, difficulties, n_problems, seed=seed, max_cycles=max_cycles,
                 progress=progress, on_run=learn, policy_agents=policy_agents, c_max_by_agents=c_max_by_agents,
                 desc="learn repairs", ray=ray)
    for m in memories.values():
        m.frozen = True
    return memories


def c_max_grid(setup: EvaluationSetup, quantiles: Sequence[float] = C_MAX_QUANTILES) -> List[float]:
    """Candidate cost cut-offs: quantiles of the positive predicted costs of the distance-pruned
    graph's edges.

    The scale of edge costs differs between maps (on CentralObstacle most edges lie far from
    the obstacle and cost nothing; on the apartments, where most free space lies within the
    cost radius, the median edge costs about 3), so the grid is taken from the graph rather
    than fixed.
    """
    src, dst, _, _ = setup.planner.buffer_graph.edge_arrays()
    costs = setup.C[src, dst]
    costs = costs[costs > 0]
    if not len(costs):
        raise ValueError(f"the graph has no edge shorter than d_max={setup.planner.graph.d_max:g} with a positive cost")
    return sorted({float(f"{np.quantile(costs, q):.3g}") for q in quantiles})


@dataclass
class CMaxSelection:
    """The outcome of :func:`select_c_max`.

    Attributes:
        chosen: agent count -> the cut-off chosen for it.
        grid: the candidates.
        seed: the seed of the validation problems (never the test seed).
        table: per (agent count, candidate): success rate and mean largest cost over the
            successful validation runs.
        rows: the validation runs, one row each, with their ``c_max``.
    """

    chosen: Dict[int, float]
    grid: List[float]
    seed: int
    table: List[Dict[str, Any]]
    rows: List[Dict[str, Any]]


def select_c_max(
    setup: EvaluationSetup,
    method: Method,
    agent_counts: Sequence[int],
    difficulties: Sequence[str] = tuple(DIFFICULTIES),
    grid: Optional[Sequence[float]] = None,
    n_problems: int = 10,
    seed: int = VALIDATION_SEED_OFFSET,
    test_seed: Optional[int] = None,
    success_slack: float = 0.05,
    max_cycles: int = 300,
    progress: bool = True,
    ray: Optional[str] = None,
) -> CMaxSelection:
    """Choose the cost cut-off of a constrained search per agent count on validation problems.

    Each candidate of ``grid`` (default :func:`c_max_grid`) runs ``method`` on ``n_problems``
    problems per difficulty drawn with ``seed``, which must differ from ``test_seed`` (the seed
    the reported table is made with; problems are drawn from ``[seed, agents, difficulty]``, so
    another seed gives other problems). Per agent count, among the candidates whose success
    rate is within ``success_slack`` of the best one, the one with the lowest mean largest
    cumulative cost over its successful runs wins (ties: the larger cut-off, the denser graph).
    ``ray`` runs the validation runs on Ray (see :func:`evaluate`).
    """
    if not method.search or not math.isfinite(method.c_max):
        raise ValueError(f"method {method.name!r} has no cost cut-off to choose")
    if test_seed is not None and seed == test_seed:
        raise ValueError(f"the validation seed must differ from the test seed {test_seed}: "
                         "choosing c_max on the test problems would overstate the method")
    grid = c_max_grid(setup) if grid is None else sorted(float(c) for c in grid)
    if not grid or any(not c > 0 for c in grid):
        raise ValueError(f"the c_max grid needs positive values, got {grid!r}")
    rows: List[Dict[str, Any]] = []
    for c in grid:
        rows += evaluate(setup, [method.with_options(c_max=c)], agent_counts, difficulties, n_problems, seed=seed,
                         max_cycles=max_cycles, progress=progress, desc=f"validate c_max={c:g}", ray=ray)
    table, chosen = [], {}
    for k in agent_counts:
        stats = []
        for c in grid:
            rs = [r for r in rows if r["agents"] == k and r["c_max"] == c]
            ok = [r["cost_max"] for r in rs if r["success"]]
            stats.append((c, len(ok) / len(rs), float(np.mean(ok)) if ok else math.inf))
            table.append({"agents": k, "c_max": c, "success_rate": stats[-1][1], "cost_mean": stats[-1][2]})
        best = max(s for _, s, _ in stats)
        eligible = [(cost, -c) for c, s, cost in stats if s >= best - success_slack]
        chosen[k] = -min(eligible)[1]
    return CMaxSelection(chosen, list(grid), int(seed), table, rows)


def markdown_table(agg: Sequence[Dict[str, Any]], methods: Optional[Sequence[str]] = None,
                   value: str = "cost", bold_min_success: float = 0.9) -> str:
    """The paper's Table I layout: rows (difficulty, agents), one column per method.

    Cells read ``mean ± std (success%; safe rate%)`` of the largest cumulative cost over agents
    (``value="cost"``) or of another aggregated quantity (e.g. ``"mean_cost"``); the safety rate
    (the mean share of agents that never touched another agent) is shown for multi-agent cells
    whose rows record it. In each row
    the lowest mean among the methods with a success rate of at least ``bold_min_success``
    is bold (a method that rarely arrives would otherwise win by its few easy successes).
    """
    methods = list(methods) if methods is not None else list(dict.fromkeys(a["method"] for a in agg))
    cell = {(a["difficulty"], a["agents"], a["method"]): a for a in agg}
    keys = sorted({(a["difficulty"], a["agents"]) for a in agg},
                  key=lambda x: (list(DIFFICULTIES).index(x[0]) if x[0] in DIFFICULTIES else 9, x[1]))
    labels = [METHODS[m].label if m in METHODS else m for m in methods]
    lines = ["| Problem | Agents | " + " | ".join(labels) + " |",
             "|---|---|" + "---|" * len(methods)]
    for d, k in keys:
        vals = [cell.get((d, k, m)) for m in methods]
        means = [v[f"{value}_mean"] if v is not None and not math.isnan(v[f"{value}_mean"]) else math.inf
                 for v in vals]
        eligible = [mu for v, mu in zip(vals, means) if v is not None and v["success_rate"] >= bold_min_success]
        best = min(eligible) if eligible else math.inf
        parts = []
        for v, mu in zip(vals, means):
            if v is None:
                parts.append("n/a")
                continue
            txt = (f"{v[f'{value}_mean']:.2f} ± {v[f'{value}_std']:.2f}" if math.isfinite(mu) else "-")
            txt += f" ({100 * v['success_rate']:.0f}%{safety_note(v)})"
            win = math.isfinite(mu) and mu == best and v["success_rate"] >= bold_min_success
            parts.append(f"**{txt}**" if win and len(methods) > 1 else txt)
        lines.append(f"| {d.capitalize()} | {k} | " + " | ".join(parts) + " |")
    return "\n".join(lines)


def safety_note(cell: Dict[str, Any]) -> str:
    """``"; safe 99.5%"``: an aggregated multi-agent cell's safety rate as a table shows it beside the
    success rate (one decimal below 100%, none at 100%); empty for one agent or where not recorded."""
    safe = cell.get("safety_rate", math.nan)
    if cell.get("agents", 1) <= 1 or not isinstance(safe, float) or not math.isfinite(safe):
        return ""
    return "; safe " + ("100%" if safe >= 1.0 else f"{100 * safe:.1f}%")


def write_csv(rows: Sequence[Dict[str, Any]], path) -> None:
    """Write rows (per run or aggregated) as CSV with a header, whole or not at all."""
    from .output import write_rows_atomic

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_rows_atomic(rows, path)


__all__ = ["C_MAX_QUANTILES", "CMaxSelection", "DIFFICULTIES", "EvaluationSetup", "Problem", "REPAIR_SEED_OFFSET",
           "ROW_FIELDS", "VALIDATION_SEED_OFFSET", "c_max_grid", "evaluate", "learn_edge_memory",
           "make_problems", "markdown_table", "safety_note", "select_c_max", "write_csv"]
