"""Executing plans in the environment: the :class:`~agents.search.execution.controller.WaypointController`
and its rules (advance, plan order, goal clearance, ordering), what a stuck agent's replan does
(:mod:`~agents.search.execution.replanning`), the plan-order dependencies, the edge memory
(:mod:`~agents.search.execution.repair`), the safety layer and the episode's per-agent state."""
from .controller import AgentPlan, WaypointController
from .episode import AgentState, Episode, Leg
from .repair import EdgeMemory
from .replanning import Replanner
from .safety import SafetyLayer, SafetyState, team_positions
from .stats import ControllerStats

__all__ = ["AgentPlan", "AgentState", "ControllerStats", "EdgeMemory", "Episode", "Leg", "Replanner", "SafetyLayer",
           "SafetyState", "WaypointController", "team_positions"]
