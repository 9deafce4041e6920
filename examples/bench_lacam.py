"""The LaCAM* configuration search on the MovingAI MAPF benchmark: one markdown table.

Run: ``python examples/bench_lacam.py [--maps NAME ...] [--agents K|max] [--scens SCEN ...]
[--threads 1] [--seed 0] [--expansion-limit N] [--time-limit S] [--refine-limit N] [--tiny]``

Per instance (the first ``K`` agents of a scenario) the table gives the status and sum of costs
of the first solution of :func:`agents.search.mapf.solve_lacam` (``anytime=False``), its ratio
to the sum of the agents' shortest-path lengths (a lower bound on the optimum), the wall-clock
time of the call and, with ``--refine-limit N``, the sum of costs after a second call that goes
on improving it until ``N`` units of work (``expansion_limit``) are spent. Every plan is checked
with :func:`agents.search.mapf.validate`. By default: random-32-32-20 with 400 agents and
room-32-32-4 with 341 (every agent of its scenarios), scenarios random-1..5, one thread.
``--agents max`` takes every agent of each scenario. ``--tiny`` runs the tightly coupled
instances of ``tiny/`` instead, with refinement until the optimum is proven (or ``infeasible``).

The search's budget is counted in work (``--expansion-limit``), so a status does not depend on
the machine's load; ``--time-limit`` (seconds) is a safety net. ``--threads`` caps the threads
of the numerical libraries (the search itself is single-threaded Python).

The column "published" cites the paper's claim for instances of these sizes: "Improving LaCAM
for Scalable Eventually Optimal Multi-Agent Pathfinding" (Okumura, IJCAI 2023), abstract: LaCAM*
found a (suboptimal) first solution within ten seconds for 99% of the MAPF benchmark instances it
was run on, with up to a thousand agents, on a standard desktop PC (a C++ implementation). It is
a claim over the whole benchmark; per-map figures from the paper's plots are not reproduced.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import List, Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

DATA = REPO / "examples" / "data" / "movingai"
#: map -> agents of the default run (every agent of the map's scenarios)
DEFAULT_AGENTS = {"random-32-32-20": 400, "room-32-32-4": 341}
MAPS = ["random-32-32-20", "room-32-32-4", "random-32-32-10", "maze-32-32-2", "empty-16-16", "empty-8-8"]
SCENARIOS = ["random-1", "random-2", "random-3", "random-4", "random-5", "even-1"]
#: the published claim cited in the table (qualitative: the paper's abstract, not a per-map figure)
PUBLISHED = "99% solved within 10 s [1]"
CITATION = ('[1] K. Okumura, "Improving LaCAM for Scalable Eventually Optimal Multi-Agent Pathfinding", IJCAI 2023, '
            "abstract: LaCAM* (C++) found a first solution within ten seconds for 99% of the MAPF benchmark instances "
            "it was run on, up to a thousand agents, on a desktop PC; a claim over the whole benchmark, not a "
            "figure for this map.")


def run_one(map_path: Path, scen_path: Path, k: Optional[int], seed: int, expansion_limit: Optional[int],
            time_limit: float, refine_limit: Optional[int], anytime_first: bool = False) -> dict:
    """Solve one instance (first solution, then optionally refined); a row of the table."""
    from agents.search.mapf import MapfInstance, load_instance, solve_lacam, validate

    grid = load_instance(map_path, scen_path, k)
    inst = MapfInstance(grid.graph, grid.starts, grid.goals)
    t0 = time.perf_counter()
    res = solve_lacam(inst, expansion_limit=expansion_limit, time_limit=time_limit, seed=seed,
                      anytime=anytime_first)
    seconds = time.perf_counter() - t0
    if res.paths is not None and validate(inst, None, None, res.paths):
        raise AssertionError(f"{map_path.name} {scen_path.name}: invalid plan")
    lb = sum(inst.h[i][s] for i, s in enumerate(inst.starts))
    row = dict(map=map_path.stem, agents=inst.n_agents, scen=scen_path.stem.replace(f"{map_path.stem}-", ""),
               status=res.status, soc=res.soc, lb=lb, seconds=seconds, refined=None, refined_status=None)
    if refine_limit and res.solved:
        better = solve_lacam(inst, expansion_limit=refine_limit, time_limit=time_limit, seed=seed)
        if better.paths is not None and validate(inst, None, None, better.paths):
            raise AssertionError(f"{map_path.name} {scen_path.name}: invalid refined plan")
        row["refined"], row["refined_status"] = better.soc, better.status
    return row


def table(rows: List[dict], refine: bool) -> str:
    """The markdown table of ``rows``."""
    head = ["map", "agents", "scen", "status", "SoC", "SoC / sum of shortest paths", "runtime (s)"]
    if refine:
        head.append("SoC refined")
    head.append("published")
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        ratio = f"{r['soc'] / r['lb']:.2f}" if r["soc"] is not None and r["lb"] else "-"
        cells = [r["map"], str(r["agents"]), r["scen"], r["status"], "-" if r["soc"] is None else str(r["soc"]),
                 ratio, f"{r['seconds']:.2f}"]
        if refine:
            cells.append("-" if r["refined"] is None else f"{r['refined']} ({r['refined_status']})")
        cells.append(PUBLISHED if not r["scen"] == "tiny" else "-")
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=list(DEFAULT_AGENTS), choices=MAPS, metavar="NAME",
                    help=f"benchmark maps (default: {' '.join(DEFAULT_AGENTS)}; any of {', '.join(MAPS)})")
    ap.add_argument("--agents", default=None, metavar="K",
                    help="agents per instance, or 'max' for every agent of the scenario (default: "
                         + ", ".join(f"{m} {k}" for m, k in DEFAULT_AGENTS.items()) + ", else max)")
    ap.add_argument("--scens", nargs="+", default=SCENARIOS[:5], choices=SCENARIOS, metavar="SCEN",
                    help="scenarios (default random-1 .. random-5)")
    ap.add_argument("--threads", type=int, default=1, help="threads of the numerical libraries (default 1)")
    ap.add_argument("--seed", type=int, default=0, help="the search's seed (default 0)")
    ap.add_argument("--expansion-limit", type=int, default=None, metavar="N",
                    help="work budget of the first solution (default: the solver's)")
    ap.add_argument("--time-limit", type=float, default=60.0, metavar="S", help="safety net, seconds (default 60)")
    ap.add_argument("--refine-limit", type=int, default=None, metavar="N",
                    help="also report the sum of costs after improving for N units of work")
    ap.add_argument("--tiny", action="store_true",
                    help="the tiny coupled instances instead, each searched until proven optimal or infeasible")
    args = ap.parse_args(argv)
    if args.threads < 1:
        ap.error(f"--threads must be >= 1, got {args.threads}")
    if args.agents is not None and args.agents != "max" and not (args.agents.isdigit() and int(args.agents) > 0):
        ap.error(f"--agents must be a positive integer or 'max', got {args.agents!r}")
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)
    from agents.search.mapf.lacam import DEFAULT_LACAM_EXPANSION_LIMIT

    limit = DEFAULT_LACAM_EXPANSION_LIMIT if args.expansion_limit is None else args.expansion_limit
    rows = []
    if args.tiny:
        for m in sorted((DATA / "tiny").glob("*.map")):
            row = run_one(m, m.with_suffix(".scen"), None, args.seed, limit, args.time_limit, None,
                          anytime_first=True)
            row["scen"] = "tiny"
            rows.append(row)
    else:
        for name in args.maps:
            k: Optional[int] = None if args.agents == "max" else (
                int(args.agents) if args.agents is not None else DEFAULT_AGENTS.get(name))
            for scen in args.scens:
                rows.append(run_one(DATA / "maps" / f"{name}.map", DATA / "scens" / f"{name}-{scen}.scen", k,
                                    args.seed, limit, args.time_limit, args.refine_limit))
                print(f"  {rows[-1]['map']} {rows[-1]['scen']}: {rows[-1]['status']} in {rows[-1]['seconds']:.2f} s",
                      file=sys.stderr, flush=True)
    print(table(rows, bool(args.refine_limit)))
    if not args.tiny:
        print(f"\n{CITATION}")
    solved = [r for r in rows if r["status"] in ("optimal", "suboptimal", "infeasible")]
    fast = [r for r in solved if r["seconds"] <= 10.0]
    print(f"\n{len(solved)}/{len(rows)} solved, {len(fast)} within 10 s; one thread, seed {args.seed}, "
          f"work budget {limit}")
    return 0 if len(solved) == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
