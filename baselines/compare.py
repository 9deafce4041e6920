"""Two evaluations of the same problems compared run by run: what a change gained and lost.

``safe-mapf evaluate`` is deterministic, so two settings run on the same problems can be paired:
a run that arrived under one and not the other is a gain or a loss, and the largest cumulative
cost of the runs that arrived both ways differs run by run. A rule that changes a few hundred of
a thousand runs (an execution rule, a planning option) changes their costs both ways; the mean of
the paired differences, with a bootstrap interval, says whether it moved them at all, and the
gains and losses whether it moved arrivals beyond the few that any such change flips by chance.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

#: a cell of an evaluation: (method, agents, difficulty)
Cell = Tuple[str, int, str]


@dataclass
class CellComparison:
    """One cell's runs, paired by problem."""

    cell: Cell
    runs: int = 0
    arrived_before: int = 0
    arrived_after: int = 0
    #: problems that arrived before and not after, and the other way round
    lost: List[int] = field(default_factory=list)
    gained: List[int] = field(default_factory=list)
    #: runs with the same outcome, largest cost and steps
    unchanged: int = 0
    #: largest cumulative cost of the runs that arrived both ways, before and after, per problem
    cost_before: List[float] = field(default_factory=list)
    cost_after: List[float] = field(default_factory=list)

    def add(self, before: Mapping[str, Any], after: Mapping[str, Any]) -> None:
        """Pair one problem's row of each evaluation (``runs.csv`` rows as
        :func:`baselines.output.read_rows` reads them)."""
        problem = int(before["problem"])
        a, b = bool(before["success"]), bool(after["success"])
        self.runs += 1
        self.arrived_before += a
        self.arrived_after += b
        if a and not b:
            self.lost.append(problem)
        elif b and not a:
            self.gained.append(problem)
        elif a and b:
            self.cost_before.append(float(before["cost_max"]))
            self.cost_after.append(float(after["cost_max"]))
        self.unchanged += a == b and all(before.get(k) == after.get(k) for k in ("cost_max", "steps"))


def _cell(row: Mapping[str, Any]) -> Cell:
    return row["method"], int(row["agents"]), row["difficulty"]


def pair_runs(before: Iterable[Mapping[str, Any]], after: Iterable[Mapping[str, Any]]) -> List[CellComparison]:
    """Pair the rows of two evaluations (``runs.csv`` rows as :func:`baselines.output.read_rows`
    reads them) by (method, agents, difficulty, problem).

    Only problems present in both count. ``ValueError`` when none is, or when a problem appears
    twice in one evaluation (two folders of the same apartment given as one evaluation, say).
    """
    def index(rows: Iterable[Mapping[str, Any]], what: str) -> Dict[Tuple[Cell, int], Mapping[str, Any]]:
        out: Dict[Tuple[Cell, int], Mapping[str, Any]] = {}
        for r in rows:
            key = (_cell(r), int(r["problem"]))
            if key in out:
                raise ValueError(f"the {what} runs hold {key[0]} problem {key[1]} twice")
            out[key] = r
        return out

    a, b = index(before, "before"), index(after, "after")
    common = sorted(set(a) & set(b), key=lambda k: (k[0][0], k[0][1], k[0][2], k[1]))
    if not common:
        raise ValueError("the two evaluations share no run: they must be of the same problems "
                         "(the same env, seed, agent counts and difficulties)")
    cells: Dict[Cell, CellComparison] = {}
    for key in common:
        cells.setdefault(key[0], CellComparison(key[0])).add(a[key], b[key])
    return list(cells.values())


def pair_methods(rows: Iterable[Mapping[str, Any]], first: str, second: str) -> List[CellComparison]:
    """Pair method ``second``'s runs with method ``first``'s on the same problems of one evaluation
    (``runs.csv`` rows): ``first`` takes the place of "before" and ``second`` of "after", so a
    cell's paired difference is ``second``'s largest cost minus ``first``'s over the problems both
    arrived at (e.g. ``first="sorb", second="ours"``: below zero where ours is cheaper). Each cell
    is named ``"second - first"``. ``ValueError`` when the rows hold no run of one of them.
    """
    if first == second:
        raise ValueError(f"compare two different methods, got {first!r} twice")
    name = f"{second} - {first}"
    rows = list(rows)
    picked = [[{**r, "method": name} for r in rows if r["method"] == m] for m in (first, second)]
    for m, runs in zip((first, second), picked):
        if not runs:
            raise ValueError(f"the runs hold no run of {m!r} (methods there: {sorted({r['method'] for r in rows})})")
    return pair_runs(*picked)


def paired_interval(before: Sequence[float], after: Sequence[float], resamples: int = 2000,
                    level: float = 0.95, seed: int = 0) -> Tuple[float, float, float]:
    """Mean of ``after - before`` over paired runs and a bootstrap ``level`` interval of it:
    ``(mean, low, high)``; NaNs where there is no pair."""
    d = np.asarray(after, dtype=np.float64) - np.asarray(before, dtype=np.float64)
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = d[rng.integers(0, d.size, size=(int(resamples), d.size))].mean(axis=1)
    tail = 100 * (1 - level) / 2
    lo, hi = np.percentile(means, [tail, 100 - tail])
    return float(d.mean()), float(lo), float(hi)


def merge(cells: Sequence[CellComparison], cell: Cell) -> CellComparison:
    """All ``cells`` as one (e.g. the total over a table), named ``cell``."""
    out = CellComparison(cell)
    for c in cells:
        out.runs += c.runs
        out.arrived_before += c.arrived_before
        out.arrived_after += c.arrived_after
        out.lost += c.lost
        out.gained += c.gained
        out.unchanged += c.unchanged
        out.cost_before += c.cost_before
        out.cost_after += c.cost_after
    return out


def comparison_table(cells: Sequence[CellComparison], total_label: Optional[str] = "all",
                     resamples: int = 2000, seed: int = 0) -> str:
    """A Markdown table: per cell the runs, arrivals before -> after, the problems lost and gained,
    the unchanged runs, and the mean largest cost of the runs that arrived both ways with the
    paired difference and its 95% bootstrap interval; a total row last (``total_label``)."""
    rows = list(cells)
    if total_label is not None and len(rows) > 1:
        rows.append(merge(rows, (total_label, 0, "")))
    lines = ["| cell | runs | arrived | lost | gained | unchanged | mean largest cost (both arrived) | "
             "after - before [95%] |", "|---|---|---|---|---|---|---|---|"]
    for c in rows:
        name = c.cell[0] if c.cell[1] == 0 else f"{c.cell[0]}, {c.cell[1]} agents, {c.cell[2]}"
        mean, lo, hi = paired_interval(c.cost_before, c.cost_after, resamples, seed=seed)
        cost = (f"{np.mean(c.cost_before):.2f} -> {np.mean(c.cost_after):.2f}" if c.cost_before else "-")
        diff = f"{mean:+.2f} [{lo:+.2f}, {hi:+.2f}]" if c.cost_before else "-"
        lines.append(f"| {name} | {c.runs} | {c.arrived_before} -> {c.arrived_after} | {_problems(c.lost)} | "
                     f"{_problems(c.gained)} | {c.unchanged} | {cost} | {diff} |")
    return "\n".join(lines)


def _problems(ids: List[int]) -> str:
    if not ids:
        return "0"
    shown = ", ".join(str(i) for i in ids[:8])
    return f"{len(ids)} ({shown}{', ...' if len(ids) > 8 else ''})"


__all__ = ["CellComparison", "comparison_table", "merge", "pair_runs", "paired_interval"]
