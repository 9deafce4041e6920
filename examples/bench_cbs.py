"""CBS on the MovingAI MAPF benchmark: solved count, median and worst solve time per map.

Run: ``python examples/bench_cbs.py [--data-dir DIR] [--time-limit 60] [--maps [NAME ...]]
[--scens SCEN ...] [--agents K] [--tiny] [--vanilla | --both | --ablation | --solvers NAME ...]
[--merge-threshold B|none]
[--no-disjoint-target] [--sweep [--step 5]] [--out results.csv|results.json] [--ray [ADDRESS]]``

Instances are ``(map, scenario, K)``: the first ``K`` agents of a scenario. By default each
map is run at its largest ``K`` (random-32-32-10: 60, empty-16-16: 30, random-32-32-20: 20,
maze-32-32-2: 25, room-32-32-4: 30, empty-8-8: 24) on its six scenarios (random-1..5, even-1),
36 instances in all. ``--sweep`` runs ``K = step, 2 * step, ..., max`` instead (per scenario it
stops at the first ``K`` that is not solved: larger ``K`` count as unsolved).

The solvers: the default CBS of :mod:`agents.search.mapf` (prioritised conflicts, WDG heuristic,
rectangle, corridor, pseudo-corridor and target reasoning with the disjoint target split,
meta-agent merging, bypass; grid coordinates passed) and, with ``--vanilla`` or ``--both``, the same CBS with those
improvements switched off (``vanilla=True``). ``--merge-threshold B`` (``none``: no merging)
and ``--no-disjoint-target`` change the default CBS's options. ``--ablation`` runs every
instance with the solvers of :data:`SOLVERS`: the vanilla CBS, the default one, the default one
with each new technique off in turn (``no-merge``: ``merge_threshold=None``; ``no-disjoint``:
``disjoint_target=False``; ``no-pseudo``: ``pseudo_corridors=False``, head-on conflicts outside
corridors split plainly; ``group``: ``group_bounds=True``, the WDG heuristic with group
constraints beyond pairs, off by default), with merging on any map (``merge-any``: ``merge_space_limit=None``;
by default only meta-agents with few joint configurations are formed, i.e. on tiny maps) and
with merging and the disjoint split off (``no-new``: the solver before them), and prints
per solver the instances solved, the median and worst time and the high-level expansions
(total over the instances, and the lower bound reached on each unsolved one); ``--solvers NAME
...`` does the same with only the named solvers of :data:`SOLVERS` (e.g. ``--solvers cbs
no-pseudo``). ``--tiny`` adds
the instances of ``tiny/`` under the data folder (every ``.map`` there with its ``.scen``, all
its agents), e.g. ``pocket.map``; one named ``infeasible-*`` has no solution and counts as
solved when it is reported ``infeasible``; ``--agents K`` runs ``K`` agents instead of the map's
largest count. Every solution is checked with :func:`agents.search.mapf.validate`
and must be reported optimal; with ``--both`` the two sums of costs must agree wherever both
solve. The time of an instance is the wall-clock time of ``solve_cbs`` (instance set-up
included, file reading excluded); an unsolved instance counts as the time limit in the median
and makes the worst time read ``>limit``. Everything runs in this one process, one instance
after the other, unless ``--ray [ADDRESS]`` runs each scenario as a Ray task (one CPU each; a
local Ray on this machine's cores, ``auto`` for the running cluster): the same instances and
answers, timed while other instances run beside them.

The benchmark files ship with the repository in ``examples/data/movingai/`` (the default
``--data-dir``); another folder must hold ``maps/<name>.map`` and ``scens/<name>-<scen>.scen``.
"""
from __future__ import annotations

import argparse
import csv
import gc
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from agents.search.mapf import load_instance, solve_cbs, validate  # noqa: E402

#: map name -> the largest number of agents of the benchmark target
MAX_AGENTS: Dict[str, int] = {
    "random-32-32-10": 60,
    "empty-16-16": 30,
    "random-32-32-20": 20,
    "maze-32-32-2": 25,
    "room-32-32-4": 30,
    "empty-8-8": 24,
}
SCENARIOS = ["random-1", "random-2", "random-3", "random-4", "random-5", "even-1"]
#: solver name -> options of ``solve_cbs`` (every one but ``vanilla`` gets the grid coordinates)
SOLVERS: Dict[str, Dict[str, Any]] = {
    "vanilla": {"vanilla": True},
    "cbs": {},
    "no-merge": {"merge_threshold": None},
    "merge-any": {"merge_space_limit": None},
    "no-disjoint": {"disjoint_target": False},
    "no-new": {"merge_threshold": None, "disjoint_target": False},
    "no-pseudo": {"pseudo_corridors": False},
    "group": {"group_bounds": True},
}
FIELDS = ["solver", "map", "scen", "agents", "status", "solved", "soc", "lower_bound", "time_s",
          "hl_expanded", "hl_generated", "ll_calls", "ll_expanded", "corridor_splits", "pseudo_corridor_splits",
          "group_searches", "group_raised", "valid", "message"]


def instance_files(data: Path, name: str, scen: str) -> tuple:
    """The ``.map`` and ``.scen`` files of an instance (``scen == "tiny"``: ``tiny/<name>.*``)."""
    if scen == "tiny":
        return data / "tiny" / f"{name}.map", data / "tiny" / f"{name}.scen"
    return data / "maps" / f"{name}.map", data / "scens" / f"{name}-{scen}.scen"


def run_one(data: Path, name: str, scen: str, k: Optional[int], solver: str, time_limit: float,
            options: Optional[Dict[str, Any]] = None) -> dict:
    """Solve one instance and check the answer; a row of the results table.

    ``solver`` names the options in :data:`SOLVERS`; ``options`` are added to them.
    """
    inst = load_instance(*instance_files(data, name, scen), k)
    kw = dict(SOLVERS[solver])
    kw.update(options or {})
    if solver != "vanilla":
        kw["grid_coords"] = inst.cells
    gc.collect()
    t0 = time.perf_counter()
    res = solve_cbs(inst.graph, inst.starts, inst.goals, time_limit=time_limit, **kw)
    elapsed = time.perf_counter() - t0
    valid = None
    if res.solved:
        problems = validate(inst.graph, inst.starts, inst.goals, res.paths)
        valid = not problems
        if problems:
            print(f"  INVALID {solver} {name} {scen} K={k}: {problems[0]}", flush=True)
    if scen == "tiny" and name.startswith("infeasible-"):
        solved = res.status == "infeasible"  # a tiny instance made to have no solution
    else:
        solved = res.status == "optimal" and bool(valid)
    return {
        "solver": solver, "map": name, "scen": scen, "agents": len(inst.starts), "status": res.status,
        "solved": solved, "soc": res.soc, "lower_bound": res.lower_bound, "time_s": round(elapsed, 3),
        "hl_expanded": res.stats.hl_expanded, "hl_generated": res.stats.hl_generated,
        "ll_calls": res.stats.ll_calls, "ll_expanded": res.work,
        "corridor_splits": res.stats.corridor_splits, "pseudo_corridor_splits": res.stats.pseudo_corridor_splits,
        "group_searches": res.stats.group_searches, "group_raised": res.stats.group_raised,
        "valid": valid,
        "message": res.message,
    }


def run_chain(data: Path, name: str, scen: str, ks: List[Optional[int]], solver: str, time_limit: float,
              options: Optional[Dict[str, Any]] = None) -> List[dict]:
    """Solve one scenario at growing agent counts; once one is not solved, the larger ones are skipped."""
    rows: List[dict] = []
    failed = False
    for k in ks:
        if failed:
            row: dict = {f: None for f in FIELDS}
            row.update(solver=solver, map=name, scen=scen, agents=k, status="skipped", solved=False,
                       time_s=time_limit, message="a smaller K was not solved")
        else:
            row = run_one(data, name, scen, k, solver, time_limit, options)
            failed = not row["solved"]
        rows.append(row)
    return rows


def print_rows(rows: List[dict]) -> None:
    for row in rows:
        if row["status"] == "skipped":
            continue
        lb = "" if row["solved"] else f" lb {row['lower_bound']}"
        print(f"  {row['solver']:11s} {row['map']:18s} {row['scen']:9s} K={row['agents']:2d}  {row['status']:10s} "
              f"soc {row['soc']}{lb}  {row['time_s']:7.2f} s  hl {row['hl_expanded']}  "
              f"corridor/pseudo splits {row['corridor_splits']}/{row['pseudo_corridor_splits']}  "
              f"group searches/raised {row['group_searches']}/{row['group_raised']}", flush=True)


def summary(rows: List[dict], time_limit: float) -> str:
    """``solved/total, median and worst time`` of some rows (unsolved count as the limit)."""
    if not rows:
        return "no instances"
    times = [r["time_s"] if r["solved"] else time_limit for r in rows]
    n_ok = sum(r["solved"] for r in rows)
    worst = f"{max(times):.2f} s" if n_ok == len(rows) else f">{time_limit:g} s"
    return f"{n_ok}/{len(rows)} solved, median {statistics.median(times):.2f} s, worst {worst}"


def ablation_table(rows: List[dict], solvers: List[str], time_limit: float) -> str:
    """Per solver: solved, median and worst time, high-level expansions, lower bounds of the unsolved."""
    head = f"{'solver':11s} {'solved':>7s} {'median s':>9s} {'worst s':>9s} {'hl nodes':>10s}"
    lines = [head + "  unsolved: status:lower bound"]
    for solver in solvers:
        sel = [r for r in rows if r["solver"] == solver]
        if not sel:
            continue
        times = [r["time_s"] if r["solved"] else time_limit for r in sel]
        n_ok = sum(r["solved"] for r in sel)
        worst = f"{max(times):.2f}" if n_ok == len(sel) else f">{time_limit:g}"
        hl = sum(r["hl_expanded"] or 0 for r in sel)
        lbs = " ".join(f"{r['map']}/{r['scen']}:{r['status']}:{r['lower_bound']}" for r in sel if not r["solved"])
        solved = f"{n_ok}/{len(sel)}"
        lines.append(f"{solver:11s} {solved:>7s} {statistics.median(times):9.2f} {worst:>9s} {hl:10d}  {lbs}")
    return "\n".join(lines)


def write_out(path: Path, rows: List[dict]) -> None:
    if path.suffix.lower() == ".json":
        path.write_text(json.dumps(rows, indent=1))
    else:
        with path.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=FIELDS)
            w.writeheader()
            w.writerows(rows)


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-dir", type=Path, default=REPO / "examples" / "data" / "movingai",
                    help="folder with maps/ and scens/ (default: examples/data/movingai in the repository)")
    ap.add_argument("--time-limit", type=float, default=60.0, metavar="S", help="seconds per instance (default 60)")
    ap.add_argument("--maps", nargs="*", default=list(MAX_AGENTS), choices=list(MAX_AGENTS), metavar="NAME",
                    help=f"maps to run (default all: {' '.join(MAX_AGENTS)}; none, with --tiny: the tiny ones only)")
    ap.add_argument("--scens", nargs="+", default=SCENARIOS, choices=SCENARIOS, metavar="SCEN",
                    help="scenarios to run (default all six)")
    ap.add_argument("--agents", type=int, default=None, metavar="K",
                    help="agents per instance (default: the map's largest count)")
    ap.add_argument("--tiny", action="store_true",
                    help="also run the tiny instances of DATA/tiny (every .map with its .scen, all agents)")
    who = ap.add_mutually_exclusive_group()
    who.add_argument("--vanilla", action="store_true", help="run vanilla CBS (improvements off) only")
    who.add_argument("--both", action="store_true",
                     help="run the improved and the vanilla CBS and compare their sums of costs")
    who.add_argument("--ablation", action="store_true",
                     help=f"run every instance with each solver of {', '.join(SOLVERS)} and print a table")
    who.add_argument("--solvers", nargs="+", default=None, choices=list(SOLVERS), metavar="NAME",
                     help="like --ablation with only these solvers (e.g. cbs no-pseudo)")
    ap.add_argument("--merge-threshold", default=None, metavar="B",
                    help="merge_threshold of the default CBS: an integer, or 'none' for no meta-agents")
    ap.add_argument("--no-disjoint-target", action="store_true",
                    help="the default CBS splits target conflicts the overlapping way (disjoint_target=False)")
    ap.add_argument("--sweep", action="store_true", help="run K = step..max per scenario instead of K = max only")
    ap.add_argument("--step", type=int, default=5, help="agent-count step of --sweep (default 5)")
    ap.add_argument("--out", type=Path, default=None, metavar="FILE", help="write every row as .csv or .json")
    ap.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                    help="solve the scenarios as Ray tasks (one CPU each): a local Ray, 'auto' or a cluster address "
                         "(needs the ray extra)")
    args = ap.parse_args(argv)
    data = args.data_dir
    if not (data / "maps").is_dir() or not (data / "scens").is_dir():
        ap.error(f"{data} has no maps/ and scens/ folders: pass --data-dir")
    if args.ablation:
        solvers = list(SOLVERS)
    elif args.solvers:
        solvers = list(dict.fromkeys(args.solvers))
        args.ablation = True  # the same table, for these solvers
    else:
        solvers = ["vanilla"] if args.vanilla else (["cbs", "vanilla"] if args.both else ["cbs"])
    options: Dict[str, Any] = {}
    if args.merge_threshold is not None:
        mt = args.merge_threshold.lower()
        if mt == "none":
            options["merge_threshold"] = None
        elif mt.isdigit():
            options["merge_threshold"] = int(mt)
        else:
            ap.error(f"--merge-threshold must be an integer or 'none', got {args.merge_threshold!r}")
    if args.no_disjoint_target:
        options["disjoint_target"] = False
    if options and args.ablation:
        ap.error("--ablation sets the options itself: drop --merge-threshold / --no-disjoint-target")
    if not args.maps and not args.tiny:
        ap.error("--maps needs map names (none: only with --tiny)")
    tiny = sorted(p.stem for p in (data / "tiny").glob("*.map")) if args.tiny else []

    rows: List[dict] = []
    where = "" if args.ray is None else f", on Ray ({args.ray})"
    print(f"CBS on MovingAI, time limit {args.time_limit:g} s per instance, solvers: {', '.join(solvers)}{where}",
          flush=True)
    chains: List[tuple] = []  # (solver, map, scenario, agent counts): one task each
    for name in tiny:
        chains += [(solver, name, "tiny", [None]) for solver in solvers]
    for name in args.maps:
        kmax = MAX_AGENTS[name] if args.agents is None else args.agents
        ks: List[Optional[int]] = list(range(args.step, kmax, args.step)) + [kmax] if args.sweep else [kmax]
        chains += [(solver, name, scen, ks) for scen in args.scens for solver in solvers]
    results: Dict[int, List[dict]] = {}
    if args.ray is None:
        for i, (solver, name, scen, ks) in enumerate(chains):
            results[i] = run_chain(data, name, scen, ks, solver, args.time_limit, options)
            print_rows(results[i])
    else:
        from baselines.distributed import init_ray

        ray = init_ray(args.ray)
        if __name__ != "__main__":  # imported from a file path: workers cannot import it by name
            ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
        task = ray.remote(num_cpus=1)(run_chain)
        refs = {task.remote(data, name, scen, ks, solver, args.time_limit, options): i
                for i, (solver, name, scen, ks) in enumerate(chains)}
        pending = list(refs)
        while pending:  # print each chain as it ends
            done, pending = ray.wait(pending, num_returns=1)
            results[refs[done[0]]] = ray.get(done[0])
            print_rows(results[refs[done[0]]])
    for i in range(len(chains)):
        rows += results[i]
    for name in tiny + args.maps:
        kmax = MAX_AGENTS.get(name, 0) if args.agents is None else args.agents
        for solver in solvers:
            sel = [r for r in rows if r["map"] == name and r["solver"] == solver]
            print(f"{name:18s} {solver:11s} {summary(sel, args.time_limit)}", flush=True)
            if args.sweep and name in MAX_AGENTS:
                top = [r for r in sel if r["agents"] == kmax]
                print(f"{'':18s} {solver:11s} at K={kmax}: {summary(top, args.time_limit)}", flush=True)

    mismatches = 0
    if args.both:
        solved = {(r["map"], r["scen"], r["agents"]): r["soc"] for r in rows if r["solver"] == "cbs" and r["solved"]}
        for r in rows:
            if r["solver"] == "vanilla" and r["solved"]:
                key = (r["map"], r["scen"], r["agents"])
                if key in solved and solved[key] != r["soc"]:
                    mismatches += 1
                    print(f"SOC MISMATCH {key}: cbs {solved[key]} vanilla {r['soc']}")
    print("overall:")
    for solver in solvers:
        sel = [r for r in rows if r["solver"] == solver]
        print(f"  {solver:11s} {summary(sel, args.time_limit)}")
    if args.ablation:
        print("ablation:")
        print(ablation_table(rows, solvers, args.time_limit))
        socs: Dict[tuple, set] = {}
        for r in rows:
            if r["solved"]:
                socs.setdefault((r["map"], r["scen"], r["agents"]), set()).add(r["soc"])
        for key, vals in socs.items():
            if len(vals) > 1:
                mismatches += 1
                print(f"SOC MISMATCH {key}: {sorted(vals)}")
    if args.both:
        both = sum(1 for r in rows if r["solver"] == "vanilla" and r["solved"]
                   and solved.get((r["map"], r["scen"], r["agents"])) is not None)
        print(f"  sums of costs agree on all {both} instances both solve" if not mismatches
              else f"  {mismatches} sum-of-cost mismatches")
    invalid = sum(1 for r in rows if r["valid"] is False)
    if invalid:
        print(f"  {invalid} INVALID solutions")
    if args.out:
        write_out(args.out, rows)
        print(f"rows written to {args.out}")
    return 1 if (mismatches or invalid) else 0


if __name__ == "__main__":
    sys.exit(main())
