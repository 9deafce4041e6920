"""Multi-agent path finding (MAPF) with Conflict-Based Search (CBS) on any directed graph.

This is the multi-agent planner of "Safe Multi-Agent Navigation guided by Goal-Conditioned
Safe Reinforcement Learning": waypoints on the replay-buffer graph are planned for several
agents at once so that their timed paths never collide. The solver is general, depends on
numpy/scipy only and imports nothing from the rest of the project.

Problem
    A directed graph with integer edge durations (a scipy sparse matrix, a dense matrix or an
    adjacency list), one start and one goal node per agent. Waiting in place is always allowed
    and takes one step. An agent stays at its goal forever after its final arrival. The cost of
    a solution is the sum over agents of their final arrival times (sum of costs, SOC).

Time models
    ``"unit"``: every move takes one step (the MAPF benchmark semantics and the paper's
    unit-time mode). ``"durative"``: a move takes its integer duration, so plan time is
    environment time. In the durative model an agent traversing ``u -> v`` during
    ``[t, t + d)`` is taken to occupy *both* ``u`` and ``v`` (and their neighbourhoods under
    proximity) for the whole traversal; this is conservative: it also forbids entering a node
    during the step in which another agent leaves it.

Conflicts
    vertex, edge (swap; unit time), target (an agent runs into another one parked at its goal)
    and proximity (two agents at distinct nodes closer than a radius under a user-given
    node-distance function, e.g. a distance critic's predictions).

Algorithm
    Optimal CBS with prioritised conflicts (cardinal / semi-cardinal, classified with MDDs),
    bypass, target reasoning and an admissible high-level heuristic (``"cg"``: cardinal
    conflict graph, ``"dg"``: dependency graph, ``"wdg"``: weighted dependency graph, solved as
    an edge-weighted minimum vertex cover). With a heuristic, the conflict to split is chosen
    f-aware: first the splits whose children get larger lower bounds (the raised agent's edges
    of the weighted conflict graph lowered by its cost increase, the cover recomputed), and a
    child that must raise its agent's cost is planned only when it is popped. Results that
    depend only on constraints (MDDs, pair sub-problems) are cached by constraint content.
    Target conflicts are split disjointly ("the parked agent arrives later" | "it arrives by
    then and nobody is at its goal from then on", ``disjoint_target``). Unit time, meta-agent
    CBS (``merge_threshold``): two (meta-)agents whose conflicts have been split more than the
    threshold merge into one meta-agent, planned by an optimal coupled search (A* with
    operator decomposition, :mod:`agents.search.mapf.coupled`), which solves tightly coupled
    tiny instances and proves infeasibility where no pair of agents alone can; by default only
    meta-agents with few joint configurations are formed (``merge_space_limit``).
    Unit time, pairwise symmetry reasoning (``symmetry``): corridor, pseudo-corridor (head-on
    conflicts the agents' MDDs force anywhere, ``pseudo_corridors``) and rectangle splits.
    ``suboptimality=w > 1`` switches to ECBS (focal search at both levels; the returned cost is
    at most ``w`` times the optimum). ``vanilla=True`` turns prioritisation, bypass, target and
    symmetry reasoning, merging and the heuristic off.

Many agents
    :func:`solve_prioritized`: prioritised planning, each agent on its earliest path around
    the earlier ones by safe-interval path planning (SIPP, :mod:`agents.search.mapf.sipp`),
    restarted with the failed agent first where it gets stuck; fast with hundreds of agents,
    its cost is not bounded and it can fail where a plan exists. :func:`solve_lns`:
    large-neighbourhood repair (:mod:`agents.search.mapf.lns`), a prioritised plan in which an
    agent that finds no conflict-free path takes the one with the fewest conflicts, then small
    groups of agents re-planned until no conflict is left; it solves crowds where prioritised
    planning gives up. :func:`solve_pibt`: a joint stepper by priority inheritance with
    backtracking (:mod:`agents.search.mapf.pibt`): all agents advance together, and an agent in
    the way of a more urgent one is pushed off its node; it untangles crowds that one-at-a-time
    planning cannot, with long makespans. :func:`solve_lacam`: a complete, anytime search over
    the agents' joint configurations with that stepping as its successor generator
    (:mod:`agents.search.mapf.lacam`, in the manner of LaCAM*): it solves hundreds of agents on
    crowded grids, reports ``"infeasible"`` where it exhausts the configurations, and improves
    its plan towards the optimum with more budget. Budgets of every solver can be counted in expansions
    (``expansion_limit``), so a result does not depend on the machine's load.

Solvers by name
    :func:`solve` runs the solver a :class:`SolverConfig` names (``"cbs"``, ``"prioritized"``,
    ``"lns"``, ``"pibt"``, ``"lacam"``, or ``"auto"``: the cascade :data:`AUTO_CASCADE`) with the
    options and budgets it holds; :func:`register_solver` adds one to :data:`SOLVERS`. Every solver
    returns a :class:`MapfResult` (status, paths, costs, a lower bound where known, the work it
    counted, its seconds and name), with its own statistics beside (:class:`CBSStats` for CBS / ECBS).

Feasibility
    :func:`joint_feasible`: an exhaustive search over the agents' joint configurations that
    decides whether any plan exists on small instances; :class:`CBSSolver` runs it before
    searching where there are at most ``joint_check_states`` configurations, so a small
    impossible instance is reported ``"infeasible"`` at once.

Public API
    :func:`solve`, :class:`SolverConfig`, :func:`register_solver`, :data:`SOLVERS`,
    :func:`solve_cbs`, :class:`CBSSolver`, :class:`MapfResult` (also under its former name
    ``CBSResult``), :class:`CBSStats`,
    :class:`CTNode`, :class:`Proximity`, :class:`MapfInstance`, :func:`integer_durations`,
    :func:`validate` to check any solution independently, :func:`solve_prioritized`,
    :func:`solve_lns`, :func:`solve_pibt`, :func:`solve_lacam`,
    :func:`joint_feasible`, the constraint and conflict types,
    and the MovingAI benchmark loaders :func:`load_map`, :func:`load_scen`,
    :func:`load_instance`, :func:`grid_graph`.

Modules, one concept each
    ``registry`` (solvers by name, their configuration and the ``"auto"`` cascade), ``solver`` (the
    CBS entry: options, pre-checks, limits), ``result`` (what a solve returns),
    ``cbs`` (the optimal high-level search and its conflict choice), ``ecbs`` (bounded
    suboptimal), ``heuristics`` (conflict graphs and their vertex covers), ``ctnode`` (the
    constraint-tree node), ``context`` (caches and limits of one solve), ``mdd``, ``paths``
    (timed paths and reservations), ``conflicts`` (conflict types and detection),
    ``lowlevel`` (space-time A*, focal search, earliest arrival), ``coupled`` (the joint
    search of a meta-agent), ``successors`` (what the low-level searches share),
    ``constraints``, ``symmetry`` (corridor, pseudo-corridor and rectangle reasoning), ``instance``, ``validate``,
    ``movingai`` (benchmark files), ``sipp`` (safe intervals and the single-agent search over
    them), ``prioritized`` (prioritised planning), ``lns`` (the large-neighbourhood repair),
    ``pibt`` (the priority inheritance stepper), ``lacam`` (the search over joint configurations),
    ``conflict_table`` (planning with conflicts allowed, its low level) and ``feasibility`` (the
    exhaustive check).
"""
from .conflicts import CARDINAL, EDGE, NON_CARDINAL, PROXIMITY, SEMI_CARDINAL, TARGET, VERTEX, Conflict
from .constraints import (
    EMPTY,
    FOREVER,
    CompiledConstraints,
    Constraint,
    ConstraintSet,
    DeadlineConstraint,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
)
from .ctnode import CTNode
from .feasibility import joint_feasible
from .instance import TIME_MODELS, UNREACHABLE, MapfInstance, Proximity, integer_durations
from .lacam import ConfigurationStats, solve_lacam
from .lns import RepairStats, solve_lns
from .movingai import GridInstance, GridMap, ScenAgent, grid_graph, load_instance, load_map, load_scen
from .paths import SPREAD_MODES
from .pibt import StepperStats, solve_pibt
from .prioritized import PrioritizedStats, solve_prioritized
from .registry import AUTO_CASCADE, AUTO_SEARCH_AGENTS, SOLVERS, CascadeStage, SolverConfig, register_solver, solve
from .result import STATUSES, CBSResult, CBSStats, MapfResult
from .solver import DEFAULT_MEMORY_LIMIT_MB, DEFAULT_MERGE_THRESHOLD, HEURISTICS, CBSSolver, solve_cbs
from .validate import validate

__all__ = [
    "AUTO_CASCADE", "AUTO_SEARCH_AGENTS", "CARDINAL", "CBSResult", "CBSSolver", "CBSStats", "CTNode", "CascadeStage",
    "CompiledConstraints", "ConfigurationStats", "Conflict", "Constraint",
    "ConstraintSet", "DEFAULT_MEMORY_LIMIT_MB", "DEFAULT_MERGE_THRESHOLD", "DeadlineConstraint", "EDGE", "EMPTY",
    "EdgeConstraint", "FOREVER", "GridInstance",
    "GridMap", "HEURISTICS", "LengthConstraint", "MapfInstance", "MapfResult", "NON_CARDINAL", "PROXIMITY",
    "PrioritizedStats", "Proximity", "RangeConstraint", "RepairStats", "SEMI_CARDINAL", "SOLVERS", "SPREAD_MODES",
    "STATUSES", "ScenAgent", "SolverConfig", "StepperStats", "TARGET", "TIME_MODELS", "UNREACHABLE", "VERTEX",
    "VertexConstraint", "compile_constraints", "grid_graph", "integer_durations", "joint_feasible", "load_instance",
    "load_map", "load_scen", "register_solver", "solve", "solve_cbs", "solve_lacam", "solve_lns", "solve_pibt",
    "solve_prioritized", "validate",
]
