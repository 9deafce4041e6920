"""Failure anatomy: why an agent of an evaluation run did not arrive.

Every agent that is not at its goal when a run ends gets one reason, read from what the run did
(ground-truth positions are used here, for evaluation only, never by the planner or the agents):

=====================  ===============================================================================
reason                 meaning
=====================  ===============================================================================
``never_planned``      the search found no plan for it (infeasible or out of time): it drove straight
``deadlock``           it stood still for another agent (a yield or a planned wait) for most of the
                       last ``window`` steps, or pushed against a live agent for most of them
``blocked_by_parked``  it made no progress beside an agent parked on its goal (an immovable obstacle)
``out_of_time``        it was still closing in on its goal when the step limit came
``stuck_on_leg``       none of the above: it made no progress on the way to its current waypoint (or
                       goal); the edge, its predicted length and its true length are recorded
=====================  ===============================================================================

:class:`FailureTracker` collects the per-step evidence during an execution and
:meth:`FailureTracker.diagnose` turns it into :class:`AgentFailure` records;
:func:`failure_summary` counts reasons per evaluation cell from the rows' ``failures`` field,
:func:`anatomy_table` and :func:`anatomy_figure` show them.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Deque, Dict, Iterable, List, Optional, Sequence

import numpy as np

from .output import in_cell_order

#: the reasons, in the order they are tested
REASONS = ("never_planned", "deadlock", "out_of_time", "blocked_by_parked", "stuck_on_leg")

#: steps at the end of a run that the reasons are read from
WINDOW = 30
#: an agent whose geodesic distance to its goal fell by at least this share of what full speed
#: covers in the window was still moving
MOVING_SHARE = 0.2
#: an agent held (or in contact with a live agent) for at least this share of the window waited on others
HELD_SHARE = 0.5


@dataclass
class AgentFailure:
    """Why one agent did not arrive.

    Attributes:
        agent: its name.
        reason: one of :data:`REASONS`.
        edge_source, edge_target: buffer node ids of the leg it was on (``-1``: its start or the
            place it replanned from / its goal; both ``-1`` without a planned route).
        predicted_length: the critic's predicted steps of that leg (``nan`` without one).
        true_length: the leg's ground-truth geodesic length in steps (``nan`` without one).
        to_target: ground-truth geodesic steps from where it ended to the leg's target.
        to_goal: ground-truth geodesic steps from where it ended to its goal.
        held_share: share of the last ``window`` steps it stood still for another agent.
        progress: geodesic steps it came closer to its goal over the window.
        escapes: times it was found stuck on the way to its last target.
        blocker: the agent it waited for or the parked agent beside it (``"wait"``: its planned departure
            time; ``""`` if none).
    """

    agent: str
    reason: str
    edge_source: int = -1
    edge_target: int = -1
    predicted_length: float = math.nan
    true_length: float = math.nan
    to_target: float = math.nan
    to_goal: float = math.nan
    held_share: float = 0.0
    progress: float = 0.0
    escapes: int = 0
    blocker: str = ""


def classify(planned: bool, held_share: float, progress: float, step_length: float, window: int,
             near_parked: bool) -> str:
    """The reason of one agent that did not arrive (see the module's table), from the evidence of the last
    ``window`` steps: ``held_share`` of them it stood for (or pushed against) another live agent,
    ``progress`` world units it came closer to its goal, ``near_parked`` whether a parked agent was
    within touching distance while it made no progress."""
    if not planned:
        return "never_planned"
    if held_share >= HELD_SHARE:
        return "deadlock"
    if progress >= MOVING_SHARE * window * step_length:
        return "out_of_time"
    if near_parked:
        return "blocked_by_parked"
    return "stuck_on_leg"


class FailureTracker:
    """Collects the evidence of :func:`classify` during one execution.

    Args:
        names: agent names, in the env's order.
        step_length: the largest displacement of one step along an axis (world units).
        touch: distance between agent centres at which two agents touch (world units), plus a margin.
        window: steps at the end of the run the reasons are read from.
    """

    def __init__(self, names: Sequence[str], step_length: float, touch: float, window: int = WINDOW) -> None:
        self.names = list(names)
        self.step_length = float(step_length)
        self.touch = float(touch)
        self.window = int(window)
        #: per step of the last ``window``: name -> why it stood (``"yield:<agent>"``, ``"wait:<agent>"``,
        #: ``"wait"``: its planned departure time) or None
        self.holds: Deque[Dict[str, Optional[str]]] = deque(maxlen=self.window)
        #: per step of the last ``window``: name -> the live agents it touched
        self.contacts: Deque[Dict[str, List[str]]] = deque(maxlen=self.window)

    def step(self, holding: Dict[str, Optional[str]], infos: Dict[str, Dict[str, Any]], live: Sequence[str]) -> None:
        """Record one step: why each agent held (the controller's ``stats.holding``) and whom it touched."""
        live_set = set(live)
        self.holds.append(dict(holding))
        self.contacts.append({a: [b for b in info.get("collided_with", ()) if b in live_set]
                              for a, info in infos.items()})

    def diagnose(
        self,
        positions: np.ndarray,
        goals: np.ndarray,
        reached: np.ndarray,
        parked_at: np.ndarray,
        geodesic: Callable[[np.ndarray, np.ndarray], float],
        planned: bool = True,
        legs: Optional[Dict[str, Any]] = None,
        escapes: Optional[Dict[str, int]] = None,
        node_positions: Optional[np.ndarray] = None,
    ) -> List[AgentFailure]:
        """One :class:`AgentFailure` per agent that did not arrive.

        Args:
            positions: ground-truth positions ``(T + 1, K, 2)`` of the run.
            goals: goal positions ``(K, 2)``.
            reached: per agent, whether it arrived.
            parked_at: per agent, the step at which it parked (``-1``: never).
            geodesic: ``geodesic(a[2], b[2]) -> world units``, ground truth (``nan`` where undefined).
            planned: whether the search found a plan (``False``: every agent drove straight).
            legs: per agent, its :class:`~agents.search.execution.episode.Leg` at the end (or ``None``).
            escapes: per agent, times it was found stuck on the way to its last target.
            node_positions: ground-truth positions of the buffer nodes (for the legs' true lengths).
        """
        positions = np.asarray(positions, dtype=np.float64)
        steps = len(positions) - 1
        w = max(1, min(self.window, steps))
        out = []
        for i, a in enumerate(self.names):
            if reached[i]:
                continue
            end, before = positions[-1, i], positions[-1 - w, i]
            to_goal = geodesic(end, goals[i])
            progress = geodesic(before, goals[i]) - to_goal
            progress = 0.0 if not math.isfinite(progress) else progress
            held = [h.get(a) for h in list(self.holds)[-w:]]
            touched = [c.get(a, []) for c in list(self.contacts)[-w:]]
            stood = [h is not None or bool(t) for h, t in zip(held, touched)]
            held_share = float(np.mean(stood)) if stood else 0.0
            blockers = [h for h in held if h is not None] + [b for t in touched for b in t]
            blocker = max(set(blockers), key=blockers.count) if blockers else ""
            parked = (parked_at >= 0) & (parked_at <= steps - w)
            gaps = np.linalg.norm(positions[-w:, parked] - positions[-w:, i:i + 1], axis=-1)
            near = bool(parked.any()) and float(gaps.min()) <= self.touch
            if near and not blocker:
                blocker = self.names[int(np.flatnonzero(parked)[int(np.argmin(gaps.min(axis=0)))])]
            reason = classify(planned, held_share, progress, self.step_length, w, near)
            f = AgentFailure(a, reason, to_goal=to_goal / self.step_length, held_share=held_share,
                             progress=progress / self.step_length, escapes=int((escapes or {}).get(a, 0)),
                             blocker=blocker.split(":", 1)[1] if ":" in blocker else blocker)
            leg = (legs or {}).get(a)
            if leg is not None:
                if leg.source is None:  # its start, or where it replanned from
                    src = positions[min(leg.started, steps), i]
                else:
                    src = None if node_positions is None else node_positions[leg.source]
                tgt = goals[i] if leg.target is None else (None if node_positions is None
                                                          else node_positions[leg.target])
                f.edge_source = -1 if leg.source is None else int(leg.source)
                f.edge_target = -1 if leg.target is None else int(leg.target)
                f.predicted_length = float(leg.predicted)
                if src is not None and tgt is not None:
                    f.true_length = geodesic(src, tgt) / self.step_length
                    f.to_target = geodesic(end, tgt) / self.step_length
            out.append(f)
        return out


def failures_field(failures: Sequence[AgentFailure]) -> str:
    """The compact form kept in a run's row: ``agent:reason`` joined by ``;`` (empty when all arrived)."""
    return ";".join(f"{f.agent}:{f.reason}" for f in failures)


def parse_failures_field(text: Any) -> List[str]:
    """The reasons of a row's ``failures`` field (see :func:`failures_field`)."""
    if not isinstance(text, str) or not text:
        return []
    return [part.rsplit(":", 1)[1] for part in text.split(";") if ":" in part]


#: the run a failure record belongs to (the first fields of ``failures.csv``)
RUN_KEYS = ("method", "agents", "difficulty", "problem")
#: the fields of ``failures.csv``: the run, then :class:`AgentFailure`'s
FAILURE_FIELDS = (*RUN_KEYS, *AgentFailure.__dataclass_fields__)


def failure_records(row: Dict[str, Any], failures: Sequence[AgentFailure]) -> List[Dict[str, Any]]:
    """One flat record per failed agent, keyed by the run's cell (for ``failures.csv``)."""
    return [{**{k: row[k] for k in RUN_KEYS}, **asdict(f)} for f in failures]


def failure_summary(rows: Iterable[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per (method, agents, difficulty): runs, failed runs, failed agents and the count of each reason."""
    cells: Dict[tuple, Dict[str, Any]] = {}
    for r in rows:
        key = (r["method"], int(r["agents"]), r["difficulty"])
        c = cells.setdefault(key, {"method": key[0], "agents": key[1], "difficulty": key[2], "runs": 0,
                                   "failed_runs": 0, "failed_agents": 0, **{k: 0 for k in REASONS}})
        reasons = parse_failures_field(r.get("failures", ""))
        c["runs"] += 1
        c["failed_runs"] += int(bool(reasons))
        c["failed_agents"] += len(reasons)
        for reason in reasons:
            c[reason] += 1
    return in_cell_order(cells)


def anatomy_table(summary: Sequence[Dict[str, Any]]) -> str:
    """A Markdown table of :func:`failure_summary`: per cell, failed runs and agents and each reason's share."""
    lines = ["| Method | Problem | Agents | failed runs | failed agents | " + " | ".join(REASONS) + " |",
             "|---|---|---|---|---|" + "---|" * len(REASONS)]
    for c in summary:
        n = c["failed_agents"]
        shares = [f"{c[k]} ({100 * c[k] / n:.0f}%)" if n and c[k] else "0" for k in REASONS]
        lines.append(f"| {c['method']} | {c['difficulty'].capitalize()} | {c['agents']} | "
                     f"{c['failed_runs']}/{c['runs']} | {n} | " + " | ".join(shares) + " |")
    return "\n".join(lines)


#: bar colours of the reasons (colour-blind safe, from Okabe and Ito)
REASON_COLOURS = {"never_planned": "#999999", "deadlock": "#E69F00", "out_of_time": "#56B4E9",
                  "blocked_by_parked": "#CC79A7", "stuck_on_leg": "#D55E00"}


def draw_anatomy(summary: Sequence[Dict[str, Any]], title: str = "") -> Any:
    """The :func:`anatomy_figure` as a matplotlib ``Figure`` (not saved, not closed).

    One panel per method with stacked bars of the reasons per cell (failed agents per run); the
    legend, in its own column right of the panels, lists every reason in the order of the stack.
    A panel without a failed agent says so and keeps a y-axis from 0.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    if not summary:
        raise ValueError("no evaluation cells to draw")
    methods = list(dict.fromkeys(c["method"] for c in summary))
    width = max(6.0, 0.55 * len(summary) / len(methods) + 2) + 1.8  # + the legend column
    fig, axes = plt.subplots(len(methods), 1, figsize=(width, 2.6 * len(methods)), squeeze=False,
                             layout="constrained")
    for ax, m in zip(axes[:, 0], methods):
        cells = [c for c in summary if c["method"] == m]
        x = np.arange(len(cells))
        bottom = np.zeros(len(cells))
        for reason in REASONS:
            h = np.array([c[reason] / c["runs"] if c["runs"] else 0.0 for c in cells])
            ax.bar(x, h, bottom=bottom, color=REASON_COLOURS[reason], width=0.75)
            bottom += h
        ax.set_xticks(x, [f"{c['difficulty'][0].upper()}{c['agents']}" for c in cells])
        ax.set_ylabel("failed agents / run")
        ax.set_title(f"{m}" + (f" ({title})" if title else ""), fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        if bottom.max(initial=0.0) > 0:
            ax.set_ylim(bottom=0)
        else:
            ax.set_ylim(0, 1)
            ax.text(0.5, 0.5, "no failures", transform=ax.transAxes, ha="center", va="center", fontsize=10,
                    color="#555555")
    handles = [Patch(color=REASON_COLOURS[r], label=r.replace("_", " ")) for r in reversed(REASONS)]
    fig.legend(handles=handles, loc="outside right upper", fontsize=8, title="reason", title_fontsize=8,
               frameon=False)
    axes[-1, 0].set_xlabel("cell: difficulty (E/M/H) and agent count")
    return fig


def anatomy_figure(summary: Sequence[Dict[str, Any]], path: Any, title: str = "") -> Path:
    """Stacked bars of the reasons per cell (failed agents per run), one panel per method, saved to
    ``path`` (see :func:`draw_anatomy`)."""
    import matplotlib.pyplot as plt

    fig = draw_anatomy(summary, title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


__all__ = ["AgentFailure", "FAILURE_FIELDS", "FailureTracker", "HELD_SHARE", "MOVING_SHARE", "REASONS", "RUN_KEYS",
           "WINDOW", "anatomy_figure", "anatomy_table", "classify", "draw_anatomy", "failure_records",
           "failure_summary", "failures_field", "parse_failures_field"]
