"""Solvers by name: a solver is a function of an instance and a :class:`SolverConfig`.

:func:`register_solver` adds a solver to :data:`SOLVERS` under its name; :func:`solve` runs the
solver a configuration names. ``"auto"`` is a cascade declared as data (:data:`AUTO_CASCADE`):
CBS / ECBS for up to :data:`AUTO_SEARCH_AGENTS` agents, then the large-neighbourhood repair if
CBS / ECBS runs out of its budget; prioritised planning above, then the priority inheritance
stepper if prioritised planning gives up. Every solver returns a
:class:`~agents.search.mapf.result.MapfResult` whose ``solver`` names it.

Budgets are counted in work, not seconds: per agent for prioritised planning, the repair, the
stepper and the configuration search, per call for CBS / ECBS, or one total for any solver
(``work_limit``). A call may scale them for the graph it runs on (:class:`SolveCall`).
"""
from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Callable, Dict, FrozenSet, Iterable, Mapping, Optional, Tuple

from numpy.typing import ArrayLike

from .instance import MapfInstance
from .lacam import solve_lacam
from .lns import solve_lns
from .paths import spread_mode
from .pibt import solve_pibt
from .prioritized import solve_prioritized
from .result import MapfResult
from .solver import DEFAULT_MEMORY_LIMIT_MB, HEURISTICS, CBSSolver

#: ``"auto"``: CBS / ECBS for up to this many agents, prioritised planning above
AUTO_SEARCH_AGENTS = 20
#: default ``suboptimality``: ECBS within 1.1 x optimal
DEFAULT_SUBOPTIMALITY = 1.1
#: default ``fallback_suboptimality``: the bound of the second CBS / ECBS try after a timeout
DEFAULT_FALLBACK_SUBOPTIMALITY = 2.0
#: default ``expansion_limit``: low-level expansions of one CBS / ECBS call
DEFAULT_CBS_EXPANSION_LIMIT = 50_000
#: default ``prioritized_expansions_per_agent``: safe-interval expansions per agent
DEFAULT_PRIORITIZED_EXPANSIONS_PER_AGENT = 2_500
#: default ``repair_expansions_per_agent``: search expansions of the repair per agent
DEFAULT_REPAIR_EXPANSIONS_PER_AGENT = 3_000
#: default ``stepper_expansions_per_agent``: candidate moves of the stepper per agent
DEFAULT_STEPPER_EXPANSIONS_PER_AGENT = 10_000
#: default ``lacam_expansions_per_agent``: work of the configuration search per agent
DEFAULT_LACAM_EXPANSIONS_PER_AGENT = 20_000

#: the configuration fields that hold work budgets (integers >= 1, or ``None`` for no limit)
BUDGET_FIELDS = ("expansion_limit", "prioritized_expansions_per_agent", "repair_expansions_per_agent",
                 "stepper_expansions_per_agent", "lacam_expansions_per_agent", "work_limit")


def _is_int(x: Any) -> bool:
    """Whether ``x`` is an integer (numpy's included), not a bool."""
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


def _is_real(x: Any) -> bool:
    """Whether ``x`` is a real number (numpy's included), not a bool."""
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


@dataclass(frozen=True)
class SolverConfig:
    """Which solver runs and with what options; vary one with :func:`dataclasses.replace`.

    The defaults are those of :class:`~agents.search.planner.BufferPlanner`. A bad value raises
    ``ValueError`` naming the field.

    Attributes:
        name: the solver, a name of :data:`SOLVERS` (``"auto"``, ``"cbs"``, ``"prioritized"``,
            ``"lns"``, ``"pibt"``, ``"lacam"``).
        suboptimality: CBS: 1 for optimal CBS, ``w > 1`` for ECBS within ``w`` x optimal.
        fallback_suboptimality: CBS: where the first call times out, one more with this larger bound
            (``None``, or not above ``suboptimality``: no second call).
        expansion_limit: CBS: low-level expansions of one call (``None``: no limit).
        node_limit: CBS: high-level expansions of one call (``None``: no limit).
        prioritized_expansions_per_agent: prioritised planning: safe-interval expansions per agent,
            over all restarts (``None``: no limit).
        repair_expansions_per_agent: the large-neighbourhood repair: search expansions per agent, its
            initial plan included (``None``: no limit).
        stepper_expansions_per_agent: the priority inheritance stepper: candidate moves examined per
            agent (``None``: no limit).
        lacam_expansions_per_agent: the configuration search: its work per agent (``None``: no
            limit; then it runs until its plan is proven optimal).
        work_limit: one total budget for every solver call in its own unit, in place of
            ``expansion_limit`` and the per-agent budgets (``None``: those hold).
        time_limit: wall-clock seconds of one solver call (``None``: none; the budgets in work alone
            end a call, so that plans do not depend on the machine's load).
        seed: seeds the repair's neighbourhoods and the configuration search's tie-breaks (the
            stepper keeps its own seed, 0).
        spread: CBS: the tie-break of routes equal in cost and conflicts, ``"off"``, ``"routes"``
            or ``"near"`` (durative time only; see :class:`~agents.search.mapf.CBSSolver`).
        heuristic: optimal CBS's high-level heuristic, one of
            :data:`~agents.search.mapf.solver.HEURISTICS`.
        vanilla: CBS: plain CBS, no conflict prioritisation, bypass, target or symmetry reasoning,
            merging or heuristic.
        memory_limit_mb: CBS: how much a call may grow the process, in MiB (``None``: no guard).
        anytime: the configuration search improves its first plan until its budget ends (``False``:
            it returns the first plan).
    """

    name: str = "auto"
    suboptimality: float = DEFAULT_SUBOPTIMALITY
    fallback_suboptimality: Optional[float] = DEFAULT_FALLBACK_SUBOPTIMALITY
    expansion_limit: Optional[int] = DEFAULT_CBS_EXPANSION_LIMIT
    node_limit: Optional[int] = None
    prioritized_expansions_per_agent: Optional[int] = DEFAULT_PRIORITIZED_EXPANSIONS_PER_AGENT
    repair_expansions_per_agent: Optional[int] = DEFAULT_REPAIR_EXPANSIONS_PER_AGENT
    stepper_expansions_per_agent: Optional[int] = DEFAULT_STEPPER_EXPANSIONS_PER_AGENT
    lacam_expansions_per_agent: Optional[int] = DEFAULT_LACAM_EXPANSIONS_PER_AGENT
    work_limit: Optional[int] = None
    time_limit: Optional[float] = None
    seed: int = 0
    spread: str = "off"
    heuristic: str = "wdg"
    vanilla: bool = False
    memory_limit_mb: Optional[float] = DEFAULT_MEMORY_LIMIT_MB
    anytime: bool = True

    def __post_init__(self) -> None:
        def put(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        if self.name not in SOLVERS:
            raise ValueError(f"unknown solver {self.name!r}: the solvers are {', '.join(SOLVERS)}")
        if not (_is_real(self.suboptimality) and self.suboptimality >= 1.0):
            raise ValueError(f"suboptimality must be >= 1, got {self.suboptimality!r}")
        put("suboptimality", float(self.suboptimality))
        fb = self.fallback_suboptimality
        if fb is not None:
            if not (_is_real(fb) and fb >= 1.0):
                raise ValueError(f"fallback_suboptimality must be >= 1 or None, got {fb!r}")
            put("fallback_suboptimality", float(fb))
        for name in BUDGET_FIELDS:
            value = getattr(self, name)
            if value is None:
                continue
            if not (_is_int(value) and value >= 1):
                raise ValueError(f"{name} must be an integer >= 1 or None, got {value!r}")
            put(name, int(value))
        if self.node_limit is not None:
            if not (_is_int(self.node_limit) and self.node_limit >= 0):
                raise ValueError(f"node_limit must be an integer >= 0 or None, got {self.node_limit!r}")
            put("node_limit", int(self.node_limit))
        if self.time_limit is not None:
            if not (_is_real(self.time_limit) and self.time_limit > 0):
                raise ValueError(f"time_limit must be > 0 seconds or None, got {self.time_limit!r}")
            put("time_limit", float(self.time_limit))
        if not _is_int(self.seed):
            raise ValueError(f"seed must be an integer, got {self.seed!r}")
        put("seed", int(self.seed))
        put("spread", spread_mode(self.spread))
        if self.heuristic not in HEURISTICS:
            raise ValueError(f"heuristic must be one of {HEURISTICS}, got {self.heuristic!r}")
        if self.memory_limit_mb is not None:
            if not (_is_real(self.memory_limit_mb) and self.memory_limit_mb > 0):
                raise ValueError(f"memory_limit_mb must be > 0 (or None for no limit), got {self.memory_limit_mb!r}")
            put("memory_limit_mb", float(self.memory_limit_mb))
        for name in ("vanilla", "anytime"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")

    def budget(self, per_agent: Optional[int], n_agents: int) -> Optional[int]:
        """The budget of one call of a solver whose per-agent budget is ``per_agent``, for
        ``n_agents`` agents: ``work_limit`` if set, else ``per_agent`` times them (``None``: none)."""
        if self.work_limit is not None:
            return self.work_limit
        return None if per_agent is None else per_agent * n_agents


@dataclass(frozen=True)
class SolveCall:
    """What one call adds to a configuration: factors of its budgets for the graph it runs on, and
    the graph's grid geometry.

    Attributes:
        scale: every budget times this where it is below 1 (at least 1 expansion left), e.g. on a
            graph denser than the budgets were sized for.
        size_scale: prioritised planning's budget times this, before ``scale`` (e.g. on a graph of
            more nodes than the per-agent budget was sized for).
        grid_coords: CBS: ``(N, 2)`` integer (row, col) of the nodes of a 4-connected grid, which
            switches rectangle reasoning on (``None``: no grid).
    """

    scale: float = 1.0
    size_scale: float = 1.0
    grid_coords: Optional[ArrayLike] = dataclasses.field(default=None, compare=False)

    def __post_init__(self) -> None:
        if not self.scale > 0 or not self.size_scale > 0:
            raise ValueError(f"scale and size_scale must be > 0, got {self.scale!r}, {self.size_scale!r}")

    def scaled(self, limit: Optional[int]) -> Optional[int]:
        """A budget times ``scale`` where it is below 1 (at least 1; ``None``: none)."""
        return None if limit is None else (limit if self.scale >= 1.0 else max(1, int(limit * self.scale)))


#: ``(instance, config, call) -> result``: what a registered solver is
SolverFunction = Callable[[MapfInstance, SolverConfig, SolveCall], MapfResult]


@dataclass(frozen=True)
class RegisteredSolver:
    """A solver of :data:`SOLVERS`.

    Attributes:
        name: its name.
        run: ``run(instance, config, call)``, the solve.
        reads: the :class:`SolverConfig` fields it reads (the others do not change what it does).
    """

    name: str
    run: SolverFunction
    reads: FrozenSet[str]


_SOLVERS: Dict[str, RegisteredSolver] = {}
#: the solvers by name, in the order they were registered (read-only; add one with :func:`register_solver`)
SOLVERS: Mapping[str, RegisteredSolver] = MappingProxyType(_SOLVERS)
_FIELDS = frozenset(f.name for f in dataclasses.fields(SolverConfig))


def register_solver(name: str, reads: Iterable[str] = ()) -> Callable[[SolverFunction], SolverFunction]:
    """A decorator that registers ``run(instance, config, call) -> MapfResult`` as solver ``name``.

    Args:
        name: the name :attr:`SolverConfig.name` selects it by (not registered yet).
        reads: the :class:`SolverConfig` fields it reads besides ``name``.
    """
    fields = frozenset(reads)
    unknown = sorted(fields - _FIELDS)
    if unknown:
        raise ValueError(f"solver {name!r} reads fields SolverConfig does not have: {unknown}")

    def add(run: SolverFunction) -> SolverFunction:
        if name in _SOLVERS:
            raise ValueError(f"a solver named {name!r} is registered already")
        _SOLVERS[name] = RegisteredSolver(name, run, fields)
        return run

    return add


def solve(instance: MapfInstance, config: Optional[SolverConfig] = None, *, scale: float = 1.0,
          size_scale: float = 1.0, grid_coords: Optional[ArrayLike] = None) -> MapfResult:
    """Solve ``instance`` with the solver ``config`` names; its result says which solver made it.

    Args:
        instance: the instance.
        config: the solver and its options (default: ``SolverConfig()``, the ``"auto"`` cascade).
        scale: every budget times this where it is below 1 (see :class:`SolveCall`).
        size_scale: prioritised planning's budget times this (see :class:`SolveCall`).
        grid_coords: CBS: the nodes' grid coordinates, for rectangle reasoning (see :class:`SolveCall`).
    """
    config = SolverConfig() if config is None else config
    return SOLVERS[config.name].run(instance, config, SolveCall(scale, size_scale, grid_coords))


# ---------------------------------------------------------------------------------- the solvers
_CBS_READS = ("suboptimality", "fallback_suboptimality", "expansion_limit", "node_limit", "work_limit", "time_limit",
              "spread", "heuristic", "vanilla", "memory_limit_mb")


@register_solver("cbs", reads=_CBS_READS)
def _cbs(instance: MapfInstance, config: SolverConfig, call: SolveCall) -> MapfResult:
    """CBS (ECBS with ``suboptimality > 1``); where it times out, once more with
    ``fallback_suboptimality`` if that is larger."""
    limit = call.scaled(config.work_limit if config.work_limit is not None else config.expansion_limit)

    def run(w: float) -> MapfResult:
        return CBSSolver(instance, suboptimality=w, time_limit=config.time_limit, expansion_limit=limit,
                         node_limit=config.node_limit, heuristic=config.heuristic, vanilla=config.vanilla,
                         memory_limit_mb=config.memory_limit_mb, grid_coords=call.grid_coords,
                         spread=config.spread).solve()

    res = run(config.suboptimality)
    fb = config.fallback_suboptimality
    if res.status == "timeout" and fb is not None and fb > config.suboptimality:
        res = run(fb)
    return res


@register_solver("prioritized", reads=("prioritized_expansions_per_agent", "work_limit", "time_limit"))
def _prioritized(instance: MapfInstance, config: SolverConfig, call: SolveCall) -> MapfResult:
    """Prioritised planning with safe intervals (:func:`~agents.search.mapf.prioritized.solve_prioritized`)."""
    budget = config.budget(config.prioritized_expansions_per_agent, instance.n_agents)
    if budget is not None:
        budget = int(budget * call.size_scale)
    return solve_prioritized(instance, expansion_limit=call.scaled(budget), time_limit=config.time_limit)


@register_solver("lns", reads=("repair_expansions_per_agent", "work_limit", "time_limit", "seed"))
def _lns(instance: MapfInstance, config: SolverConfig, call: SolveCall) -> MapfResult:
    """The large-neighbourhood repair (:func:`~agents.search.mapf.lns.solve_lns`)."""
    budget = config.budget(config.repair_expansions_per_agent, instance.n_agents)
    return solve_lns(instance, expansion_limit=call.scaled(budget), time_limit=config.time_limit, seed=config.seed)


@register_solver("pibt", reads=("stepper_expansions_per_agent", "work_limit", "time_limit"))
def _pibt(instance: MapfInstance, config: SolverConfig, call: SolveCall) -> MapfResult:
    """The priority inheritance stepper (:func:`~agents.search.mapf.pibt.solve_pibt`)."""
    budget = config.budget(config.stepper_expansions_per_agent, instance.n_agents)
    return solve_pibt(instance, expansion_limit=call.scaled(budget), time_limit=config.time_limit)


@register_solver("lacam", reads=("lacam_expansions_per_agent", "work_limit", "time_limit", "seed", "anytime"))
def _lacam(instance: MapfInstance, config: SolverConfig, call: SolveCall) -> MapfResult:
    """The configuration search (:func:`~agents.search.mapf.lacam.solve_lacam`)."""
    budget = config.budget(config.lacam_expansions_per_agent, instance.n_agents)
    return solve_lacam(instance, expansion_limit=call.scaled(budget), time_limit=config.time_limit,
                       seed=config.seed, anytime=config.anytime)


# ---------------------------------------------------------------------------------- cascades
@dataclass(frozen=True)
class CascadeStage:
    """One stage of a cascade: the solver it runs, for how many agents, and what runs after a timeout.

    Attributes:
        solver: the name of the solver this stage runs.
        max_agents: the stage serves instances of up to this many agents (``None``: any number).
        then: the solver that runs next where the first one ends with status ``"timeout"``
            (``None``: none); its result says so in its message.
    """

    solver: str
    max_agents: Optional[int] = None
    then: Optional[str] = None


#: ``"auto"``: the first stage that serves the instance's number of agents runs
AUTO_CASCADE: Tuple[CascadeStage, ...] = (
    CascadeStage("cbs", max_agents=AUTO_SEARCH_AGENTS, then="lns"),
    CascadeStage("prioritized", then="pibt"),
)


def run_cascade(stages: Tuple[CascadeStage, ...], instance: MapfInstance, config: SolverConfig,
                call: SolveCall) -> MapfResult:
    """Run the first of ``stages`` that serves ``instance``'s number of agents: its solver, then its
    ``then`` solver where the first times out.

    The result is the last solver's (its ``solver``, ``work`` and ``runtime_s`` are that solver's);
    after a timeout its message ends with ``(after <first solver>: <first message>)``.
    """
    k = instance.n_agents
    stage = next((s for s in stages if s.max_agents is None or k <= s.max_agents), None)
    if stage is None:
        raise ValueError(f"no stage of the cascade serves {k} agents")
    first = SOLVERS[stage.solver].run(instance, config, call)
    if stage.then is None or first.status != "timeout":
        return first
    after = SOLVERS[stage.then].run(instance, config, call)
    after.message = f"{after.message} (after {stage.solver}: {first.message})"
    return after


def _cascade_reads(stages: Tuple[CascadeStage, ...]) -> FrozenSet[str]:
    names = {s.solver for s in stages} | {s.then for s in stages if s.then is not None}
    return frozenset().union(*(SOLVERS[n].reads for n in names))


@register_solver("auto", reads=_cascade_reads(AUTO_CASCADE))
def _auto(instance: MapfInstance, config: SolverConfig, call: SolveCall) -> MapfResult:
    """The ``"auto"`` cascade, :data:`AUTO_CASCADE`."""
    return run_cascade(AUTO_CASCADE, instance, config, call)


__all__ = ["AUTO_CASCADE", "AUTO_SEARCH_AGENTS", "BUDGET_FIELDS", "CascadeStage", "DEFAULT_CBS_EXPANSION_LIMIT",
           "DEFAULT_FALLBACK_SUBOPTIMALITY", "DEFAULT_LACAM_EXPANSIONS_PER_AGENT",
           "DEFAULT_PRIORITIZED_EXPANSIONS_PER_AGENT", "DEFAULT_REPAIR_EXPANSIONS_PER_AGENT",
           "DEFAULT_STEPPER_EXPANSIONS_PER_AGENT", "DEFAULT_SUBOPTIMALITY", "RegisteredSolver", "SOLVERS",
           "SolveCall", "SolverConfig", "SolverFunction", "register_solver", "run_cascade", "solve"]
