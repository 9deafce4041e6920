"""The settings of search on the replay buffer: frozen dataclasses, one per part, and named presets.

A :class:`SearchConfig` holds every setting of a :class:`~agents.search.policy.SearchPolicy`, in
four parts and a budget:

- :class:`GraphConfig`: which edges a problem keeps (cut-offs, endpoints, guards), proximity and
  the time model; read by :class:`~agents.search.planner.BufferPlanner`;
- :class:`~agents.search.mapf.registry.SolverConfig`: the multi-agent solver and its budgets; read
  by the planner through :func:`~agents.search.mapf.registry.solve`;
- :class:`ControllerConfig`: how agents follow their waypoints (advance, the plan's order or
  clock, yield, unstick, fallback legs); read by
  :class:`~agents.search.execution.controller.WaypointController`;
- :class:`ReplanConfig`: what a stuck agent's new plan keeps clear of; read by
  :mod:`agents.search.execution.replanning`.

Every config validates itself on construction (a bad value raises ``ValueError`` naming the
field) and is varied with :func:`dataclasses.replace`, or by option name with
:meth:`SearchConfig.updated`: each field of each part has one name in :data:`OPTIONS` (the field's
own, except three solver fields that keep the planner's names: ``solver``, ``repair_seed``,
``spread_routes``), so ``config.updated(c_max=0.25, hold="order")`` changes the graph's cut-off and
the controller's hold::

    from agents.search.config import preset

    config = preset("panorama").updated(c_max=0.25, sidestep_after=None)
    policy = SearchPolicy.from_models(critic, driver, config=config)

The presets (:data:`PRESETS`, :func:`preset_for` picks one by a model's observations) are the
settings that earned their place on validation problems: ``"vector"`` for agents of vector
observations, ``"panorama"`` for agents of rendered panoramas (see the planning docs for the
measurements behind each).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Tuple

from .mapf.registry import SolverConfig

#: default ``d_max`` (predicted steps): edges of the graph are shorter
DEFAULT_D_MAX = 7.0

HOLDS = ("order", "waits", "all")
ESCAPES = ("random", "sidestep")
RETREATS = (None, "goal", "any")
TIME_MODELS = ("durative", "unit")


def _real(x: Any) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _check(ok: bool, name: str, want: str, value: Any) -> None:
    if not ok:
        raise ValueError(f"{name} must be {want}, got {value!r}")


def _integer(x: Any, low: int) -> bool:
    """Whether ``x`` is an integer (numpy's included, not a bool) of at least ``low``."""
    return isinstance(x, numbers.Integral) and not isinstance(x, bool) and int(x) >= low


def _optional(name: str, value: Any, test, want: str) -> None:
    """``value`` is ``None`` or a real number passing ``test``."""
    _check(value is None or (_real(value) and bool(test(value))), name, f"{want} or None", value)


def _to_float(cfg: Any, *names: str) -> None:
    """Store the named fields of ``cfg`` that are numbers as floats (``None`` stays)."""
    for name in names:
        v = getattr(cfg, name)
        if v is not None:
            object.__setattr__(cfg, name, float(v))


@dataclass(frozen=True)
class GraphConfig:
    """The planner's graph: which edges a problem keeps, when agents conflict, how long an edge takes.

    Attributes:
        d_max: keep edges with predicted distance below this (steps; the paper's 7).
        c_max: keep edges with predicted cost below this (``inf``: distance pruning only, as in SoRB).
        endpoint_edges: every start keeps at least this many cheapest outgoing edges and every goal
            its cheapest incoming ones, whatever ``c_max``.
        proximity_radius: agents conflict at nodes closer than this (predicted steps, either
            direction); ``None``: only same-node conflicts.
        time_model: ``"durative"`` (an edge takes ``ceil(D)`` steps) or ``"unit"`` (one step per
            edge, the paper's).
        relax_cost: where ``c_max`` leaves an agent no path, relax it around that agent's start and
            goal until it has one (:func:`~agents.search.graph.pruning.relax_cost_locally`); ``False``:
            the plan is ``"infeasible"``.
        budget_labels: label limit of the exact risk-bounded search of a plan's ``budget``; past it,
            a Lagrangian path within the budget.
        max_edges: keep at most this many edges out of each buffer node to other buffer nodes (its
            shortest; ``None``: every edge under the cut-offs).
        cost_guard: where ``c_max`` leaves an agent only a detour predicted more than this many
            times as costly as its shortest route without the cut-off, that route is admitted too
            (:func:`~agents.search.graph.pruning.admit_cheaper_routes`; ``None``: off).
        detour: where ``c_max`` leaves an agent only a route more than this many times as long as
            its shortest route without the cut-off, and costlier at all, that route is admitted too
            (``None``: off). A test of the cost guard's admission: it acts only with ``cost_guard``.
        max_leg: no edge the planner's ``second_opinion`` reads beyond this many steps is planned,
            nor admitted past the cost cut-off (:func:`~agents.search.graph.pruning.long_legs`; needs a
            second opinion; ``None`` or ``inf``: off).
    """

    d_max: float = DEFAULT_D_MAX
    c_max: float = math.inf
    endpoint_edges: int = 3
    proximity_radius: Optional[float] = 1.5
    time_model: str = "durative"
    relax_cost: bool = True
    budget_labels: int = 2_000
    max_edges: Optional[int] = None
    cost_guard: Optional[float] = 2.0
    detour: Optional[float] = None
    max_leg: Optional[float] = None

    def __post_init__(self) -> None:
        for name in ("d_max", "c_max"):
            v = getattr(self, name)
            _check(_real(v) and v > 0, name, "> 0", v)
        _check(_integer(self.endpoint_edges, 1), "endpoint_edges", "an integer >= 1", self.endpoint_edges)
        _optional("proximity_radius", self.proximity_radius, lambda v: v >= 0, ">= 0")
        _check(self.time_model in TIME_MODELS, "time_model", " or ".join(map(repr, TIME_MODELS)), self.time_model)
        _check(isinstance(self.relax_cost, bool), "relax_cost", "True or False", self.relax_cost)
        _check(_integer(self.budget_labels, 1), "budget_labels", "an integer >= 1", self.budget_labels)
        _check(self.max_edges is None or _integer(self.max_edges, 1), "max_edges", "an integer >= 1 or None",
               self.max_edges)
        for name in ("cost_guard", "detour"):
            _optional(name, getattr(self, name), lambda v: v >= 1.0, ">= 1")
        _optional("max_leg", self.max_leg, lambda v: v > 0, "> 0")
        _to_float(self, "d_max", "c_max", "proximity_radius", "cost_guard", "detour", "max_leg")
        for name in ("endpoint_edges", "budget_labels", "max_edges"):
            v = getattr(self, name)
            if v is not None:
                object.__setattr__(self, name, int(v))


@dataclass(frozen=True)
class ControllerConfig:
    """How the agents follow their waypoints (:class:`~agents.search.execution.controller.WaypointController`;
    its module docstring describes each rule).

    Attributes:
        hold: how the agents keep to the plan: ``"order"`` (the plan's order at shared places,
            however late an agent is; :mod:`agents.search.execution.dependencies`), ``"waits"`` (an early agent
            waits for its planned departure time where the plan waits) or ``"all"`` (at every
            waypoint: on the clock).
        park_clearance: with ``hold="order"``, agents also park only after those their goal would
            shut out (:func:`~agents.search.execution.dependencies.shut_out`, predicted steps; ``None``: off).
        reach_threshold: a waypoint is reached at a predicted distance below this (steps).
        self_margin: also reached below the waypoint's predicted distance to itself plus this
            (``None``: the threshold only).
        settle_patience: also reached once the agent is within ``settle_slack`` steps of the
            threshold and has not come closer for this many steps (``None``: off).
        settle_slack: see ``settle_patience``.
        advance_slack: a waypoint counts as reached only where the agent is also within this many
            steps of the waypoint's own predicted distance to the next target, or comes no closer
            (:mod:`agents.search.execution.advance`; ``None``: off).
        safety_radius: two moving agents closer than this (predicted steps) yield to each other
            (``None``: no yielding).
        push_margin: of two agents that yield, one held still that the other pushes away from its
            target goes first (predicted steps; ``None``: off).
        goal_clearance: an agent near its goal stands still while another free to leave stands
            within this of that goal (:mod:`agents.search.execution.clearance`; ``None``: off).
        order_patience: steps an agent waits on one that makes no progress before it stops
            waiting on it (plan and goal order).
        stuck_window: steps over which an agent whose observation changed by less than
            ``stuck_tolerance`` counts as stuck (``None``: no unsticking).
        stuck_tolerance: mean absolute change of the observation over ``stuck_window`` (images
            divided by 255) below which an agent is stuck.
        progress_patience: an agent that comes no closer to its target for this many steps counts
            as stuck too (``None``: off).
        escape_steps: escape actions of a stuck agent (doubled for every further time on the way
            to one target, up to 8 times as many).
        escape: ``"random"`` actions or ``"sidestep"`` (the policy's action turned by a right
            angle, left and right in turn).
        sidestep_after: with ``escape="random"``, an agent found stuck more than this many times
            in the episode sidesteps from then on (``None``: never).
        skip_after: times an agent may be stuck on the way to one target before it replans (or,
            without replanning, heads for the next waypoint); with a fallback policy, the leg goes
            to it the first of those times.
        replan_lag: an agent more than this many steps behind its plan replans (``None``: only
            when stuck).
        retreat: an agent whose leg goes to the fallback policy goes back to the waypoint it set
            off from first: ``"goal"`` on its leg to the goal, ``"any"`` on every leg but the first
            (``None``: never).
        fallback_beyond: a leg whose target the driver's critic puts beyond this many steps at the
            leg's start goes to the fallback policy at once (``None``: off).
    """

    hold: str = "waits"
    park_clearance: Optional[float] = None
    reach_threshold: float = 2.0
    self_margin: Optional[float] = None
    settle_patience: Optional[int] = None
    settle_slack: float = 1.5
    advance_slack: Optional[float] = None
    safety_radius: Optional[float] = 2.0
    push_margin: Optional[float] = None
    goal_clearance: Optional[float] = None
    order_patience: int = 40
    stuck_window: Optional[int] = 4
    stuck_tolerance: float = 0.01
    progress_patience: Optional[int] = None
    escape_steps: int = 3
    escape: str = "random"
    sidestep_after: Optional[int] = None
    skip_after: int = 2
    replan_lag: Optional[int] = None
    retreat: Optional[str] = None
    fallback_beyond: Optional[float] = None

    def __post_init__(self) -> None:
        _check(self.hold in HOLDS, "hold", "'order', 'waits' or 'all'", self.hold)
        _check(self.escape in ESCAPES, "escape", "'random' or 'sidestep'", self.escape)
        _check(self.retreat in RETREATS, "retreat", "None, 'goal' or 'any'", self.retreat)
        _check(_real(self.reach_threshold) and self.reach_threshold > 0, "reach_threshold", "> 0",
               self.reach_threshold)
        for name in ("park_clearance", "goal_clearance", "push_margin", "fallback_beyond"):
            _optional(name, getattr(self, name), lambda v: v > 0, "> 0")
        for name in ("self_margin", "advance_slack", "safety_radius"):
            _optional(name, getattr(self, name), lambda v: v >= 0, ">= 0")
        for name in ("settle_slack", "stuck_tolerance"):
            _check(_real(getattr(self, name)) and getattr(self, name) >= 0, name, ">= 0", getattr(self, name))
        for name, low in (("escape_steps", 1), ("skip_after", 1), ("order_patience", 0)):
            _check(_integer(getattr(self, name), low), name, f"an integer >= {low}", getattr(self, name))
        for name, low in (("stuck_window", 1), ("progress_patience", 1), ("settle_patience", 0),
                          ("sidestep_after", 0), ("replan_lag", 0)):
            v = getattr(self, name)
            _check(v is None or _integer(v, low), name, f"an integer >= {low} or None", v)
        _to_float(self, "park_clearance", "reach_threshold", "self_margin", "settle_slack", "advance_slack",
                  "safety_radius", "push_margin", "goal_clearance", "stuck_tolerance", "fallback_beyond")


@dataclass(frozen=True)
class ReplanConfig:
    """What a stuck agent's new plan keeps clear of (:mod:`agents.search.execution.replanning`).

    Attributes:
        replan_when_stuck: an agent stuck ``skip_after`` times on the way to one waypoint gets a
            new single-agent plan from where it stands, clear of that waypoint and its look-alikes,
            of agents parked at their goals, or localised; the edge it failed on is recorded in the
            policy's edge memory (``False``: it gives the waypoint up instead).
        ban_radius: the replan keeps clear of the nodes within this many predicted steps of the
            failed waypoint (a buffer graph has many nodes at almost the same place, and a critic
            that misjudged one edge misjudges their edges too).
        ban_detour: where keeping clear of that neighbourhood makes the new route more than this
            many predicted steps longer than keeping clear of the waypoint alone, the replan keeps
            clear of the waypoint alone (``inf``: never).
        repair_routes: an agent about to set off along an edge another agent failed on in this
            episode (or that the edge memory removed meanwhile) plans anew from where it stands.
        detach_radius: where an agent set off for a node as one edge away and the critic now puts
            it far, the nodes within this many predicted steps of that node are no longer linked
            to its start (its goal) in its replans of the episode (``None``: never).
    """

    replan_when_stuck: bool = True
    ban_radius: float = 3.0
    ban_detour: float = math.inf
    repair_routes: bool = False
    detach_radius: Optional[float] = 3.0

    def __post_init__(self) -> None:
        for name in ("replan_when_stuck", "repair_routes"):
            _check(isinstance(getattr(self, name), bool), name, "True or False", getattr(self, name))
        _check(_real(self.ban_radius) and self.ban_radius >= 0, "ban_radius", ">= 0", self.ban_radius)
        _check(_real(self.ban_detour) and self.ban_detour >= 0, "ban_detour", ">= 0 (inf: never)", self.ban_detour)
        _optional("detach_radius", self.detach_radius, lambda v: v >= 0, ">= 0")
        _to_float(self, "ban_radius", "ban_detour", "detach_radius")


class UnknownOptionError(ValueError, TypeError):
    """Option names that no part of a :class:`SearchConfig` has (a ``ValueError``, and a
    ``TypeError`` as for an unknown keyword argument)."""


#: the parts of a :class:`SearchConfig`, by attribute
PARTS: Dict[str, type] = {"graph": GraphConfig, "solver": SolverConfig, "controller": ControllerConfig,
                          "replanning": ReplanConfig}
#: option names that differ from their field's name: option -> (part, field)
_RENAMED: Dict[str, Tuple[str, str]] = {"solver": ("solver", "name"), "repair_seed": ("solver", "seed"),
                                        "spread_routes": ("solver", "spread")}


def _option_table() -> Dict[str, Tuple[str, str]]:
    fields_named = {v: k for k, v in _RENAMED.items()}
    table: Dict[str, Tuple[str, str]] = {}
    for part, cls in PARTS.items():
        for f in dataclasses.fields(cls):
            name = fields_named.get((part, f.name), f.name)
            if name in table:
                raise AssertionError(f"option {name!r} names fields of both {table[name][0]} and {part}")
            table[name] = (part, f.name)
    table["budget"] = ("", "budget")
    return table


@dataclass(frozen=True)
class SearchConfig:
    """Every setting of a :class:`~agents.search.policy.SearchPolicy`: the four parts and a budget.

    Attributes:
        graph: the planner's graph (:class:`GraphConfig`).
        solver: the multi-agent solver (:class:`~agents.search.mapf.registry.SolverConfig`).
        controller: how agents follow their plans (:class:`ControllerConfig`).
        replanning: what stuck agents' new plans keep clear of (:class:`ReplanConfig`).
        budget: optional bound on each agent's total predicted route cost (a risk budget, see
            :meth:`~agents.search.planner.BufferPlanner.plan`; ``None``: none).
    """

    graph: GraphConfig = field(default_factory=GraphConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    replanning: ReplanConfig = field(default_factory=ReplanConfig)
    budget: Optional[float] = None

    def __post_init__(self) -> None:
        for part, cls in PARTS.items():
            _check(isinstance(getattr(self, part), cls), part, f"a {cls.__name__}", getattr(self, part))
        _optional("budget", self.budget, lambda v: v > 0, "> 0")
        _to_float(self, "budget")

    def updated(self, **changes: Any) -> "SearchConfig":
        """This config with the options named in :data:`OPTIONS` changed, e.g.
        ``updated(c_max=0.25, hold="order")``; an unknown name raises ``ValueError`` listing them."""
        unknown = sorted(set(changes) - set(OPTIONS))
        if unknown:
            raise UnknownOptionError(f"unknown options {unknown}; the options are {sorted(OPTIONS)}")
        by_part: Dict[str, Dict[str, Any]] = {}
        for name, value in changes.items():
            part, fname = OPTIONS[name]
            by_part.setdefault(part, {})[fname] = value
        top = by_part.pop("", {})
        parts = {}
        for part, kw in by_part.items():
            try:
                parts[part] = dataclasses.replace(getattr(self, part), **kw)
            except ValueError as e:
                renamed = [k for k in changes if k in _RENAMED and OPTIONS[k][0] == part]
                raise ValueError(f"{e}" + (f" (options {renamed} set the {part}'s "
                                           f"{[OPTIONS[k][1] for k in renamed]})" if renamed else "")) from None
        return dataclasses.replace(self, **parts, **top)

    def option(self, name: str) -> Any:
        """The value of the option ``name`` (a name of :data:`OPTIONS`)."""
        if name not in OPTIONS:
            raise UnknownOptionError(f"unknown option {name!r}; the options are {sorted(OPTIONS)}")
        part, fname = OPTIONS[name]
        return getattr(getattr(self, part) if part else self, fname)

    def to_dict(self) -> Dict[str, Any]:
        """The config as JSON-ready nested dicts (``inf`` stays a float; :meth:`from_dict` reads it back)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str = "the config") -> "SearchConfig":
        """A config from :meth:`to_dict`'s dicts; unknown parts or fields raise ``ValueError``
        naming them (and ``where`` the dicts came from). Parts left out keep their defaults."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{where}: a search config must be a JSON object, got {type(data).__name__}")
        unknown = sorted(set(data) - set(PARTS) - {"budget"})
        if unknown:
            raise ValueError(f"{where}: unknown parts {unknown}; the parts are {sorted(PARTS)} and 'budget'")
        parts: Dict[str, Any] = {}
        for part, cls_ in PARTS.items():
            if part not in data:
                continue
            values = data[part]
            if not isinstance(values, Mapping):
                raise ValueError(f"{where}: {part} must be a JSON object, got {type(values).__name__}")
            known = {f.name for f in dataclasses.fields(cls_)}
            bad = sorted(set(values) - known)
            if bad:
                raise ValueError(f"{where}: {part} has unknown fields {bad}; its fields are {sorted(known)}")
            try:
                parts[part] = cls_(**values)
            except (TypeError, ValueError) as e:
                raise ValueError(f"{where}: {part}: {e}") from None
        try:
            return cls(**parts, budget=data.get("budget"))
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None


#: option name -> (part, field) for every field of every part (``""``: :class:`SearchConfig` itself)
OPTIONS: Dict[str, Tuple[str, str]] = _option_table()

#: :class:`GraphConfig`'s ``detour`` for agents of panoramas: on panoramas the cost cut-off sends
#: agents on detours longer and costlier than their plain routes
PANORAMA_DETOUR = 1.5
#: default reach threshold (predicted steps) of critics of panoramas: their predicted distance to
#: a goal within the env's goal radius is below 2 in only 66-94% of cases
PANORAMA_REACH_THRESHOLD = 3.0

#: the named presets (see the planning docs for the measurements behind them)
PRESETS: Dict[str, SearchConfig] = {
    "vector": SearchConfig(),
    "panorama": SearchConfig(
        graph=GraphConfig(detour=PANORAMA_DETOUR),
        controller=ControllerConfig(hold="order", reach_threshold=PANORAMA_REACH_THRESHOLD, self_margin=0.5,
                                    settle_patience=6, progress_patience=20, skip_after=1, sidestep_after=4,
                                    advance_slack=3.0, retreat="goal", fallback_beyond=14.0)),
}


def preset(name: str) -> SearchConfig:
    """The preset ``name`` of :data:`PRESETS` (``"vector"`` or ``"panorama"``)."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; the presets are {sorted(PRESETS)}")
    return PRESETS[name]


def reads_images(model: Any) -> bool:
    """Whether ``model`` observes images (its observation space, or that space's ``observation`` entry)."""
    from gymnasium import spaces

    from ..encoders import is_image_space

    space = getattr(model, "observation_space", None)
    if isinstance(space, spaces.Dict) and "observation" in space.spaces:
        space = space["observation"]
    return space is not None and is_image_space(space)


def preset_for(model: Any) -> SearchConfig:
    """The ``"panorama"`` preset for a model of image observations, else ``"vector"``."""
    return PRESETS["panorama" if reads_images(model) else "vector"]


__all__ = ["ControllerConfig", "DEFAULT_D_MAX", "GraphConfig", "OPTIONS", "PANORAMA_DETOUR",
           "PANORAMA_REACH_THRESHOLD", "PARTS", "PRESETS", "ReplanConfig", "SearchConfig", "SolverConfig",
           "UnknownOptionError", "preset", "preset_for", "reads_images"]
