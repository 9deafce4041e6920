"""Search on the replay buffer: the waypoint graph, single-agent search, CBS and the controller.

Depends on numpy and scipy only (no torch): graphs saved as ``.npz`` can be planned on
without a critic.

- :class:`WaypointGraph`: observations as nodes, predicted distance and cost on the edges;
- :func:`shortest_path`, :func:`risk_bounded_path`: single-agent search (SoRB, constrained,
  weighted, risk-bounded);
- :func:`solve_cbs`, :class:`CBSSolver`, :func:`validate`: CBS / ECBS on any directed graph and
  an independent solution checker;
- :class:`SearchConfig` and its parts (:mod:`agents.search.config`): every setting, the presets;
- :class:`BufferPlanner`: CBS waypoints for many agents on the buffer graph, with learned
  proximity and durative edges;
- :class:`WaypointController`: executes the plans in the PettingZoo environment (closed-loop
  advance, planned departure times, yield rule);
- :class:`SearchPolicy`: all of the above as one object with an SB3-style ``predict`` for a
  Gymnasium goal-conditioned observation or a PettingZoo parallel env's observations;
- :class:`SafetyLayer`: the filter between the controller and the env that keeps agents from
  touching each other, from the team's shared positions (:func:`team_positions`);
- :func:`build_problem_graph`: the one pipeline from critic matrices to a problem's pruned graph
  (endpoint attachment, cost cut-off, local relaxation), used by the planner.
"""
from .config import ControllerConfig, GraphConfig, ReplanConfig, SearchConfig, preset, preset_for
from .execution.controller import AgentPlan, WaypointController
from .execution.safety import SafetyLayer, SafetyState, team_positions
from .graph.build import ProblemGraph, WaypointGraph, build_problem_graph
from .graph.single import Plan, risk_bounded_path, shortest_path
from .mapf import (
    CBSResult,
    CBSSolver,
    MapfInstance,
    MapfResult,
    Proximity,
    SolverConfig,
    integer_durations,
    solve_cbs,
    validate,
)
from .models import distance_fn, policy_fn
from .planner import BufferPlanner, MultiAgentPlan
from .policy import SearchPolicy
from .waypoints import direct_plans

__all__ = [
    "AgentPlan", "BufferPlanner", "CBSResult", "CBSSolver", "ControllerConfig", "GraphConfig", "MapfInstance",
    "MapfResult", "MultiAgentPlan", "Plan", "ProblemGraph", "Proximity", "ReplanConfig", "SafetyLayer", "SafetyState",
    "SearchConfig", "SearchPolicy", "SolverConfig", "WaypointController", "WaypointGraph",
    "preset", "preset_for",
    "build_problem_graph", "direct_plans", "distance_fn", "integer_durations", "policy_fn", "risk_bounded_path",
    "shortest_path", "solve_cbs", "team_positions", "validate",
]
