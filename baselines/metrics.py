"""The metrics of the evaluation, computed in one place: per run and per cell.

Per run (a row of ``runs.csv``): success, the largest and the mean cumulative cost over the
agents, contacts between agents and the safety rate (:class:`~baselines.execution.Execution`),
and the MAPF learning community's figures (:func:`mapf_metrics`: ISR, sum of costs, makespan).
Per cell (:func:`aggregate`): success rate (CSR), costs over the successful runs, ISR, sum of
costs, makespan and the safety figures over all runs. The failure anatomy, the reasons behind
failed agents and contacts, is in :mod:`baselines.anatomy` and :mod:`baselines.contact_anatomy`.
"""
from __future__ import annotations

import math
from typing import Any, Dict, Iterable, List

import numpy as np

#: the difficulties in the order of the tables
DIFFICULTY_ORDER = ("easy", "medium", "hard")


def mapf_metrics(arrival: np.ndarray, steps: int) -> Dict[str, Any]:
    """A run in the metrics of the MAPF learning community (POGEMA), from each agent's arrival
    step (``-1``: it did not arrive) and the run's length in steps.

    ``isr``: the share of agents that arrived (a run with every agent arrived counts for CSR);
    ``soc``: sum of costs, each agent's steps until it arrived, the run's length for an agent
    that did not; ``makespan``: the step at which the last agent arrived (the run's length when
    some agent did not).
    """
    arrival = np.asarray(arrival)
    if arrival.ndim != 1 or len(arrival) == 0:
        raise ValueError(f"arrival must be a non-empty 1-D array of steps, got shape {arrival.shape}")
    done = arrival >= 0
    per_agent = np.where(done, arrival, steps)
    return {"isr": float(done.mean()), "soc": int(per_agent.sum()),
            "makespan": int(per_agent.max()) if done.all() else int(steps)}


def _mean_std(x: np.ndarray):
    if not len(x):
        return math.nan, math.nan
    return float(np.mean(x)), float(np.std(x))


def aggregate(rows: Iterable[Dict[str, Any]]) -> List[Dict[str, Any]]:
    """Per (method, agents, difficulty): success rate, mean +- std over successful runs, and the
    median of the largest cumulative cost over them (``cost_median``); and, over all runs as the
    MAPF learning community reports them (:func:`mapf_metrics`), ``csr`` (the share of runs in
    which every agent arrived: the success rate), ``isr`` (the mean share of agents arrived),
    ``soc_mean`` and ``makespan_mean``; and the safety figures over all runs, ``safety_rate`` (the
    mean share of agents that never touched another agent) and ``contacts`` (the mean number of
    contacts between agents per run) (``nan`` where the rows lack them)."""
    groups: Dict[tuple, List[Dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["method"], int(r["agents"]), r["difficulty"]), []).append(r)
    out = []
    order = {d: i for i, d in enumerate(DIFFICULTY_ORDER)}
    for (m, k, d), rs in sorted(groups.items(), key=lambda kv: (order.get(kv[0][2], 9), kv[0][1], kv[0][0])):
        ok = [r for r in rs if _truthy(r["success"])]
        agg = {"method": m, "agents": k, "difficulty": d, "runs": len(rs), "success_rate": len(ok) / len(rs)}
        for key in ("cost_max", "cost_mean", "collisions", "steps", "planning_time"):
            mu, sd = _mean_std(np.array([float(r[key]) for r in ok]))
            name = "cost" if key == "cost_max" else key
            agg[f"{name}_mean"], agg[f"{name}_std"] = mu, sd
        agg["mean_cost_mean"] = agg.pop("cost_mean_mean")
        agg["mean_cost_std"] = agg.pop("cost_mean_std")
        # robust to the few runs in which an agent stalls for a long time
        agg["cost_median"] = float(np.median([float(r["cost_max"]) for r in ok])) if ok else math.nan
        agg["csr"] = agg["success_rate"]
        for key, name in (("isr", "isr"), ("soc", "soc_mean"), ("makespan", "makespan_mean"),
                          ("safety_rate", "safety_rate"), ("collisions", "contacts")):
            vals = [float(r[key]) for r in rs if r.get(key) not in (None, "")]
            agg[name] = float(np.mean(vals)) if len(vals) == len(rs) else math.nan
        out.append(agg)
    return out


def _truthy(v) -> bool:
    return v in (True, 1, "True", "true", "1")


__all__ = ["DIFFICULTY_ORDER", "aggregate", "mapf_metrics"]
