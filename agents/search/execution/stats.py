"""What the waypoint controller counts and records while it executes plans.

:class:`ControllerStats` holds the counters of :class:`~agents.search.execution.controller.WaypointController`
and, per agent, why it stood still and what it did on the last step (:data:`ACTIVITIES`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional

#: What an agent does on a step (``ControllerStats.activity``): ``drive`` (its policy drives it to its
#: target), ``fallback`` (the fallback policy drives the leg), ``escape`` (a random or sidestep
#: action of an agent found stuck), ``wait`` (it stands at a waypoint until its plan's departure
#: time), ``order`` (it stands until an agent the plan sends first has passed), ``park`` (it holds
#: its parking until the agents whose routes pass its goal have passed), ``clear`` (it keeps clear
#: of another agent's goal) and ``yield`` (another agent with priority is too close).
ACTIVITIES = ("drive", "fallback", "escape", "wait", "order", "park", "clear", "yield")


@dataclass
class ControllerStats:
    """Counters of a :class:`~agents.search.execution.controller.WaypointController` (each counts events
    since it was made), and per agent what it did on the last step."""

    steps: int = 0
    yields: int = 0
    #: pairs whose yield order flipped because the agent held still was pushed (``push_margin``)
    pushed: int = 0
    waits: int = 0
    replans: int = 0
    escapes: int = 0
    skips: int = 0
    settled: int = 0
    #: advances the on course test held back (``advance_slack``)
    off_course: int = 0
    fallbacks: int = 0
    fallback_steps: int = 0
    #: legs an agent went back to the waypoint it set off from before the fallback drove them (``retreat``)
    retreats: int = 0
    #: legs handed to the fallback policy at their start (``fallback_beyond``)
    handovers: int = 0
    #: times an agent came no closer to its target for ``progress_patience`` steps
    stalls: int = 0
    #: waits given up at once because the agents' holds closed a cycle (:mod:`agents.search.execution.ordering`; not
    #: counted: the two-agent case where the plan order meets a parking or clearing hold)
    cycles: int = 0
    waypoint_index: Dict[str, int] = field(default_factory=dict)
    #: per agent, why it stood still on the last step: ``"wait"`` (its plan's departure time),
    #: ``"yield:<agent>"`` (another agent with priority was too close), ``"wait:<agent>"`` (the plan
    #: sends that one first), ``"clear:<agent>"`` (that one stands by its goal) or ``None`` (it moved)
    holding: Dict[str, Optional[str]] = field(default_factory=dict)
    #: per agent, what it did on the last step, one of :data:`ACTIVITIES`
    activity: Dict[str, str] = field(default_factory=dict)
    #: per agent, times it was found stuck on the way to its current target
    leg_escapes: Dict[str, int] = field(default_factory=dict)


__all__ = ["ACTIVITIES", "ControllerStats"]
