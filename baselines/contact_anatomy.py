"""Contact anatomy: why two agents touched.

A contact between two agents is counted once, on the step it begins
(:class:`~baselines.execution.Contacts`). On that step :func:`~baselines.methods.execute` gives it
one reason, read from what the two agents did (tested in this order):

==================  ================================================================================
reason              meaning
==================  ================================================================================
``parked``          one of the two had arrived and stood on its goal: a parked agent in the way
``goals_close``     their goals are closer than touching distance: both cannot park untouched
``off_plan``        one of the two was escaping or driven by the fallback policy, off its plan
``into_holding``    one of the two stood still (the plan's departure time, a yield, the plan's order,
                    another agent's goal) and the other drove into it: a yield or a wait that did
                    not keep them apart
``both_driving``    both were driving along their plans: the plan's timing slipped in execution
==================  ================================================================================

A row of ``safe-mapf evaluate`` keeps the counts in its ``contact_reasons`` field
(:func:`contact_reasons_field`); :func:`contact_summary` adds them up per evaluation cell and
:func:`contact_table` shows them (``anatomy.md``).
"""
from __future__ import annotations

from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence

from .output import in_cell_order, parse_named_values

#: the reasons, in the order they are tested
CONTACT_REASONS = ("parked", "goals_close", "off_plan", "into_holding", "both_driving")
#: controller activities (:data:`~agents.search.execution.stats.ACTIVITIES`) off the plan
OFF_PLAN = frozenset({"escape", "fallback"})


def contact_reason(parked: Sequence[bool], goals_close: bool, activities: Sequence[Optional[str]],
                   holding: Sequence[bool]) -> str:
    """The reason of one contact (see the module's table) from the two agents' state on the step it
    began: whether each was ``parked``, whether their goals are closer than touching distance, what
    each did (its controller activity; ``None`` unknown) and whether each stood still for another
    agent or the plan (``holding``)."""
    if any(parked):
        return "parked"
    if goals_close:
        return "goals_close"
    if any(a in OFF_PLAN for a in activities):
        return "off_plan"
    if any(holding):
        return "into_holding"
    return "both_driving"


def contact_reasons_field(counts: Mapping[str, int]) -> str:
    """The compact form kept in a run's row: ``reason=count`` joined by ``;`` in the order of
    :data:`CONTACT_REASONS` (empty without contacts)."""
    unknown = set(counts) - set(CONTACT_REASONS)
    if unknown:
        raise ValueError(f"unknown contact reasons {sorted(unknown)}; known: {list(CONTACT_REASONS)}")
    return ";".join(f"{r}={int(counts[r])}" for r in CONTACT_REASONS if counts.get(r))


def parse_contact_reasons(text: Any) -> Dict[str, int]:
    """The counts of a row's ``contact_reasons`` field (see :func:`contact_reasons_field`)."""
    return parse_named_values(text, CONTACT_REASONS, int, "contact_reasons")


def contact_summary(rows: Iterable[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per (method, agents, difficulty) of the multi-agent runs that recorded reasons (a run with
    contacts and an empty field, such as a multi-agent RL policy's, did not): ``runs``,
    ``contacts`` (their sum) and the count of each reason."""
    cells: Dict[tuple, Dict[str, Any]] = {}
    for r in rows:
        recorded = bool(r.get("contact_reasons")) or float(r.get("collisions") or 0) == 0
        if int(r["agents"]) < 2 or "contact_reasons" not in r or not recorded:
            continue
        key = (r["method"], int(r["agents"]), r["difficulty"])
        c = cells.setdefault(key, {"method": key[0], "agents": key[1], "difficulty": key[2], "runs": 0,
                                   "contacts": 0, **{k: 0 for k in CONTACT_REASONS}})
        c["runs"] += 1
        for reason, n in parse_contact_reasons(r.get("contact_reasons")).items():
            c[reason] += n
            c["contacts"] += n
    return in_cell_order(cells)


def contact_table(summary: Sequence[Dict[str, Any]]) -> str:
    """A Markdown table of :func:`contact_summary`: per cell, contacts per run and each reason's count."""
    lines = ["| Method | Problem | Agents | runs | contacts per run | " + " | ".join(CONTACT_REASONS) + " |",
             "|---|---|---|---|---|" + "---|" * len(CONTACT_REASONS)]
    for c in summary:
        per_run = c["contacts"] / c["runs"] if c["runs"] else 0.0
        lines.append(f"| {c['method']} | {c['difficulty'].capitalize()} | {c['agents']} | {c['runs']} | "
                     f"{per_run:.2f} | " + " | ".join(str(c[k]) for k in CONTACT_REASONS) + " |")
    return "\n".join(lines)


__all__ = ["CONTACT_REASONS", "OFF_PLAN", "contact_reason", "contact_reasons_field", "contact_summary",
           "contact_table", "parse_contact_reasons"]
