"""Every rule of the search that is on by default, turned off alone: what each one buys.

For each rule of :data:`ABLATIONS` that the driving agent's preset turns on
(:func:`agents.search.config.preset_for`: the panorama preset holds most of them), the constrained
search ("ours", as Table II runs it with ``--fallback``) runs on the same problems with that one
rule off, beside the defaults. A rule is a config option (or the method's safety layer) and the
value that turns it off, so the ablation is a loop over the config's fields. The table pairs each
variant with the defaults problem by problem (:mod:`baselines.compare`): runs arrived, problems
lost and gained, and the mean largest cumulative cost of the runs that arrived both ways with the
paired difference and its 95% bootstrap interval.

Run it on problems the published tables do not use (the default seed, 10001, is a validation
seed); rows go to ``--out``/runs.csv as they come, and ``--resume`` continues an interrupted run:

    python examples/ablate_rules.py --env SafeApartment0-v0 --agents 10 --difficulty hard --problems 20 \\
        --c-max-from examples/table2/apt0/c_max.json --fallback --out ablation/apt0
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any, Dict, List, Tuple

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

#: rule -> (the value that turns it off, what it does); a config option, or the method's ``safety``
ABLATIONS: Dict[str, Tuple[Any, str]] = {
    "hold": ("waits", "agents keep the plan's order at shared places, not its clock"),
    "self_margin": (None, "a waypoint also counts as reached below its own predicted distance to itself"),
    "settle_patience": (None, "a waypoint also counts as reached once the agent hovers beside it"),
    "advance_slack": (None, "a waypoint counts as reached only where the agent is about as near its next target"),
    "progress_patience": (None, "an agent that comes no closer to its target counts as stuck"),
    "skip_after": (2, "stuck once on a leg: its fallback or a replan at once (off: two rounds of escapes)"),
    "sidestep_after": (None, "an agent found stuck often escapes by sidesteps"),
    "retreat": (None, "a leg handed to the fallback policy starts from the waypoint it set off from"),
    "fallback_beyond": (None, "a leg the driver's critic reads as long goes to the fallback policy at once"),
    "safety_radius": (None, "two moving agents close to each other yield"),
    "stuck_window": (None, "an agent whose observation stops changing escapes"),
    "replan_when_stuck": (False, "a stuck agent plans anew from where it stands"),
    "detach_radius": (None, "replans no longer link an agent to look-alikes of a node it failed to reach"),
    "detour": (None, "the planner gives back plain routes where the cut-off leaves longer, costlier detours"),
    "cost_guard": (None, "the planner gives back routes where the cut-off leaves far costlier ones"),
    "proximity_radius": (None, "plans keep agents apart at nodes near each other, not only at the same node"),
    "safety": (False, "the safety layer keeps agents from touching"),
}


def variants(base: Any, config: Any, rules: List[str]) -> List[Tuple[str, Any]]:
    """``(rule, method)`` for each rule of ``rules`` that ``config`` (the driver's preset with the base
    method's options) has on: the base method with that rule off, named after it."""
    out = []
    for rule in rules:
        off, _ = ABLATIONS[rule]
        current = base.safety if rule == "safety" else config.option(rule)
        if current == off:
            continue  # off already: nothing to ablate
        method = base.with_options(**{rule: off})
        out.append((rule, dataclasses.replace(method, name=f"{base.name} without {rule}")))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="SafeApartment0-v0")
    p.add_argument("--agents", type=int, default=10)
    p.add_argument("--difficulty", default="hard", choices=("easy", "medium", "hard"))
    p.add_argument("--problems", type=int, default=20)
    p.add_argument("--seed", type=int, default=10001, help="seed of the graph and the problems (default: a "
                                                             "validation seed, 10001)")
    p.add_argument("--nodes", type=int, default=1000)
    p.add_argument("--c-max", type=float, default=None, help="ours' cost cut-off (default: the method's, 0.25)")
    p.add_argument("--c-max-from", type=Path, default=None,
                   help="a c_max.json of safe-mapf evaluate: the cut-off chosen there for --agents")
    p.add_argument("--fallback", action="store_true", help="ours hands stuck legs to the unconstrained policy")
    p.add_argument("--rules", nargs="+", choices=list(ABLATIONS), default=list(ABLATIONS),
                   help="the rules to turn off, one at a time (default: all that the preset has on)")
    p.add_argument("--max-cycles", type=int, default=300)
    p.add_argument("--out", type=Path, required=True, help="folder for runs.csv and ablation.md")
    p.add_argument("--resume", action="store_true", help="keep the runs already in --out/runs.csv")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)

    import numpy as np
    import torch

    from agents.search.config import preset_for
    from baselines.compare import comparison_table, merge, pair_methods
    from baselines.evaluation import EvaluationSetup, evaluate
    from baselines.methods import METHODS
    from baselines.output import RowWriter, parse_row, read_kept_rows

    torch.set_num_threads(1)
    base = METHODS["ours"]
    if args.c_max_from is not None:
        chosen = json.loads(args.c_max_from.read_text())["chosen"]
        if str(args.agents) not in chosen:
            p.error(f"{args.c_max_from} has no c_max for {args.agents} agents (it has {sorted(chosen)})")
        base = base.with_options(c_max=float(chosen[str(args.agents)]))
    elif args.c_max is not None:
        base = base.with_options(c_max=args.c_max)
    if args.fallback:
        base = base.with_options(fallback="unconstrained")
    setup = EvaluationSetup.build(args.env, n_nodes=args.nodes, seed=args.seed)
    config = base.config(dataclasses.replace(preset_for(setup.models["constrained"]), graph=setup.planner.graph,
                                             solver=setup.planner.solver_config))
    runs = variants(base, config, args.rules)
    skipped = [r for r in args.rules if r not in dict(runs)]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "runs.csv"
    kept = [parse_row(r) for r in read_kept_rows(path)] if args.resume else []
    with RowWriter(path, append=args.resume) as writer:
        rows = evaluate(setup, [base] + [m for _, m in runs], [args.agents], [args.difficulty], args.problems,
                        seed=args.seed, max_cycles=args.max_cycles, progress=not args.no_progress,
                        on_run=lambda row, _p, _ex: writer.write(row), kept=kept, desc="ablation")
    rows = [parse_row({k: str(v) for k, v in r.items()}) for r in rows]
    lines = [f"{args.env}, {args.agents} agents, {args.difficulty}, {args.problems} problems, seed {args.seed}: "
             f"each rule off alone against the defaults ({base.name}, c_max {base.c_max:g}"
             + (", fallback" if base.fallback else "") + ")\n",
             "| rule off | what it does | runs | arrived | lost | gained | unchanged | mean largest cost "
             "(both arrived) | off - on [95%] | safety rate |", "|---|---|---|---|---|---|---|---|---|---|"]
    methods = {r["method"] for r in rows}
    safety = {m: np.mean([float(r["safety_rate"]) for r in rows if r["method"] == m]) for m in methods}
    for rule, method in runs:
        cell = merge(pair_methods(rows, base.name, method.name), (rule, 0, ""))
        row = comparison_table([cell], total_label=None).splitlines()[-1]
        lines.append(f"| {rule} | {ABLATIONS[rule][1]} " + row[row.index("|", 1):]
                     + f" {100 * safety[base.name]:.1f}% -> {100 * safety[method.name]:.1f}% |")
    if skipped:
        lines.append(f"\noff in this preset already: {', '.join(skipped)}")
    text = "\n".join(lines) + "\n"
    (args.out / "ablation.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
