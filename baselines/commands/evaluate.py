"""``safe-mapf evaluate``: the paper's Table I (and Figure 1) on a 2D map, its Table II on an apartment."""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Tuple


def register(sub: argparse._SubParsersAction) -> None:
    from baselines.cli import add_map_argument
    from baselines.evaluation import DIFFICULTIES
    from baselines.methods import DEFAULT_METHODS, MARL_METHODS, METHODS, PAPER_METHODS
    from baselines.output import add_resume_arguments

    p = sub.add_parser("evaluate", help="compare the methods on the same problems (Tables I and II, Figure 1)",
                       description=run.__doc__)
    p.add_argument("--env", default="SafeCentralObstacle-v0", help="env id with shipped checkpoints")
    add_map_argument(p)
    p.add_argument("--unconstrained", default=None, metavar="PATH",
                   help="unconstrained checkpoint (default: the shipped one for --env)")
    p.add_argument("--constrained", default=None, metavar="PATH",
                   help="constrained checkpoint (default: the shipped one for --env)")
    p.add_argument("--agents", type=_positive, nargs="+", default=list(SMALL_AGENTS), metavar="N",
                   help="agent counts (default: 1 5, a small run; the paper's Table I: 1 5 10 20)")
    p.add_argument("--problems", type=_positive, default=SMALL_PROBLEMS, metavar="P",
                   help="problems per difficulty (default: 5, a small run; the paper's Table I: 50)")
    p.add_argument("--difficulty", nargs="+", choices=list(DIFFICULTIES), default=list(DIFFICULTIES),
                   help="difficulties to run")
    p.add_argument("--methods", nargs="+", choices=list(METHODS), default=None,
                   help=f"default: {', '.join(DEFAULT_METHODS)} (--protocol paper: the paper's four, "
                        f"{', '.join(PAPER_METHODS)}); the multi-agent RL baselines {', '.join(MARL_METHODS)} "
                        "(no search) run when named, in both protocols")
    p.add_argument("--ippo", default=None, metavar="PATH",
                   help="IPPO policy of the ippo method (default: the shipped one for --env; see train-marl)")
    p.add_argument("--mappo-lag", dest="mappo_lag", default=None, metavar="PATH",
                   help="MAPPO-Lagrangian policy of the mappo_lag method (default: the shipped one for --env)")
    p.add_argument("--seed", type=_non_negative, default=0, help="seed of the graph nodes and the problems")
    p.add_argument("--nodes", type=_positive, default=1000, help="buffer graph nodes (default 1000)")
    for row in METHOD_FLAGS:  # the flags that change the compared methods
        p.add_argument(row.flag, **row.argument)
    p.add_argument("--c-max-from", default=None, metavar="FILE",
                   help="reuse the per-agent-count c_max of an earlier --c-max auto (its c_max.json; chosen on "
                        "validation problems), e.g. to run the agent counts as separate commands")
    p.add_argument("--c-max-grid", type=float, nargs="+", default=None, metavar="C",
                   help="candidates of --c-max auto (default: the 25/50/75%% quantiles of the graph's edge costs)")
    p.add_argument("--validation-problems", type=_positive, default=10, metavar="P",
                   help="validation problems per difficulty and candidate for --c-max auto (default 10)")
    p.add_argument("--validation-seed", type=_non_negative, default=None, metavar="S",
                   help="seed of the validation problems (default: --seed + 10000; must differ from --seed)")
    p.add_argument("--sparsify", type=_non_negative_float, default=None, metavar="TAU",
                   help="keep only the graph nodes that two-way consistency merging keeps: a node goes when the "
                        "critic's distances to and from the nodes kept so far are within TAU steps of another "
                        "kept node's (default: keep all --nodes)")
    p.add_argument("--repair-problems", type=_non_negative, default=0, metavar="P",
                   help="before the test problems, the search methods' graphs learn which edges their agents fail "
                        "to traverse on P problems per cell drawn with --repair-seed (never the test problems), and "
                        "plan the test problems without them; writes edge_memory_<method>.npz (default 0: off)")
    p.add_argument("--repair-seed", type=_non_negative, default=None, metavar="S",
                   help="seed of the repair problems (default: --seed + 20000; must differ from --seed)")
    p.add_argument("--policies-at", type=_positive, nargs="+", default=None, metavar="N",
                   help="run the methods without search only at these agent counts (the paper's Table II: 1; "
                        "default: every count)")
    p.add_argument("--max-cycles", type=_positive, default=300, help="step limit of a run (default 300)")
    p.add_argument("--out", default="results", help="output folder for runs.csv, table.csv, table.md, figure")
    add_resume_arguments(p, "continue the evaluation in --out: the runs already in its runs.csv are kept and not "
                            "run again (the settings that decide the rows must be those of the evaluation there)")
    p.add_argument("--figure", action=argparse.BooleanOptionalAction, default=True,
                   help="also draw the trajectory figure (default on)")
    p.add_argument("--video", action="store_true",
                   help="also write run.gif: the last search method's execution of the figure's multi-agent problem")
    p.add_argument("--json", action="store_true", help="print the aggregate rows as JSON instead of the table")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (it is drawn only when stderr is a terminal)")
    p.add_argument("--protocol", choices=("strict", "paper"), default="strict",
                   help="strict (default): the protocol above (problems on the graph, CBS with waiting and "
                        "proximity conflicts, closed-loop following, agents that collide). paper: the "
                        "conventions of the paper's published code: problems from random free starts and goals "
                        "whose predicted distance (unconstrained critic, ensemble mean) is nearest to the map's "
                        "8-connected grid diameter // 8, 4, 2; SoRB's graph on the unconstrained distances, ours "
                        "on the constrained distances and the unconstrained costs (max over the ensemble, d_max "
                        "7); fewest-hop routes per agent with start and goal attached only to graph nodes (at "
                        "least one waypoint); waypoints followed open loop (next one when the agent's critic "
                        "predicts < 2 steps); agents pass through each other (agent_collisions=False), so nobody "
                        "waits; a search without a route runs the plain policy instead; cost counted until "
                        "each agent arrives (the start's cost included for one agent); ours runs with c_max = "
                        "the constrained agent's cost limit x 0.1, 0.25, 0.5, 0.75, 1 and each cell reports the "
                        "best of the five, CHOSEN ON THE TEST PROBLEMS (as the published code does; optimistic)")
    p.add_argument("--paper-candidates", type=_positive, default=200, metavar="N",
                   help="--protocol paper: random starts and goals per draw of 5 problems (the published code: "
                        "1000; 200 keeps the drawn pairs within a few hundredths of a step of the target at 1/25 "
                        "of the critic queries)")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="run the runs as Ray tasks: alone, on a local Ray with this machine's cores; 'auto' joins "
                        "the running cluster (ray start --head); or a cluster address. Same rows as the serial "
                        "run for the same seed. Needs the ray extra: pip install \"safe-mapf[ray]\"")
    p.set_defaults(func=run)


#: The defaults of a bare ``safe-mapf evaluate``: a small run of a minute or two.
SMALL_AGENTS, SMALL_PROBLEMS = (1, 5), 5
#: What the full Table I takes, as measured (README, "Measured").
FULL_RUN_NOTE = ("the full Table I (--agents 1 5 10 20 --problems 50, the four methods of the paper) took "
                 "1126 s serially, 580 s with --ray")


@dataclass(frozen=True)
class MethodFlag:
    """A flag of ``safe-mapf evaluate`` that changes the compared methods: the option it sets on the
    methods it applies to (a config option of :data:`~agents.search.config.OPTIONS`, or a
    :class:`~baselines.methods.Method`'s ``fallback`` or ``safety``).

    Attributes:
        flag: the command-line flag.
        option: the option it sets.
        applies: which methods it changes (a key of :data:`APPLIES`).
        argument: the flag's ``add_argument`` keywords (its default is ``None``: not given).
        value: the option's value from the flag's.
        note: a line of ``table.md``'s header where the flag is given (``{value}``: the flag's value).
        paper: why the flag does not apply to ``--protocol paper``.
    """

    flag: str
    option: str
    applies: str
    argument: Dict[str, Any]
    value: Callable[[Any], Any] = lambda v: v
    note: str = ""
    paper: str = "the published code's graph, followed open loop"

    @property
    def dest(self) -> str:
        return self.flag[2:].replace("-", "_")

    def given(self, args: argparse.Namespace) -> bool:
        v = getattr(args, self.dest)
        return v is not None and v is not False and v != "auto"


#: which methods a :class:`MethodFlag` changes
APPLIES: Dict[str, Callable[[Any], bool]] = {
    "search": lambda m: m.search,
    "constrained search": lambda m: m.search and math.isfinite(m.c_max),
    "constrained driver": lambda m: m.search and m.policy == "constrained",
    "budget": lambda m: m.budget is not None,
    "all": lambda m: True,
}


def _spread_modes() -> Tuple[str, ...]:
    from agents.search.mapf import SPREAD_MODES

    return tuple(SPREAD_MODES)


#: the flags that change the compared methods, one row each
METHOD_FLAGS: Tuple[MethodFlag, ...] = (
    MethodFlag("--c-max", "c_max", "constrained search", dict(
        type=lambda t: _c_max(t), default=None,
        help="edge cost cut-off of the constrained searches: a number, or 'auto' to choose it per agent count "
             "on validation problems drawn with --validation-seed (never the test problems) from --c-max-grid "
             "(default: the methods' own, 0.25)"),
        paper="its c_max grid is the cost limit x 0.1 .. 1, chosen per cell on the test problems"),
    MethodFlag("--budget", "budget", "budget", dict(type=float, default=None, help="risk budget of ours_budget"),
               paper="its c_max grid is the cost limit x 0.1 .. 1, chosen per cell on the test problems"),
    MethodFlag("--max-edges", "max_edges", "search", dict(
        type=lambda t: _positive(t), default=None, metavar="K",
        help="keep at most K edges out of each graph node (its shortest; default: every edge under the cut-offs)")),
    MethodFlag("--fallback", "fallback", "constrained driver", dict(
        action="store_true", default=None,
        help="the constrained searches (ours, ours_budget) hand an agent's leg over to the unconstrained policy "
             "once the constrained one is stuck on it (e.g. it will not approach a goal beside furniture); the "
             "other methods are unchanged"),
        value=lambda v: "unconstrained",
        note="--fallback: the constrained searches hand a leg on which the constrained policy is stuck to the "
             "unconstrained policy",
        paper="its agents follow their plans open loop"),
    MethodFlag("--hold", "hold", "search", dict(
        choices=("order", "waits", "all"), default=None,
        help="how the search methods' agents keep to the plan: 'order' (the plan's order at shared places, "
             "however late an agent is), 'waits' or 'all' (the plan's clock; see SearchPolicy; default: 'order' "
             "for panorama agents, 'waits' for vector agents)")),
    MethodFlag("--repair-routes", "repair_routes", "search", dict(
        action="store_true", default=None,
        help="the search methods' agents about to set off along an edge another agent failed on in the run plan "
             "around it first (the replanning config's repair_routes; default off)"),
        note="--repair-routes: an agent about to set off along an edge another agent failed on plans around it "
             "first",
        paper="its agents follow their plans open loop"),
    MethodFlag("--spread-routes", "spread_routes", "search", dict(
        choices=_spread_modes(), default=None,
        help="the search methods' plans prefer, of routes equal in cost and conflicts, those through fewer nodes "
             "of other routes ('routes') or also near them ('near'); default: the solver's ('off')"),
        note="--spread-routes {value}: the search methods' plans spread routes that way"),
    MethodFlag("--max-leg", "max_leg", "search", dict(
        type=float, default=None, metavar="STEPS",
        help="the search methods' plans take no leg that the constrained agent's critic reads beyond STEPS (the "
             "graph config's max_leg; 'inf': any leg; default: with --fallback, the constrained searches of "
             "panorama agents take none beyond 14, where the leg would go to the fallback at once; otherwise any)"),
        note="--max-leg {value:g}: the search methods' plans take no leg the constrained agent's critic reads "
             "beyond that many steps"),
    MethodFlag("--safety", "safety", "all", dict(
        choices=("on", "off"), default=None,
        help="the safety layer between the controller and the env, which keeps agents from touching each other "
             "with the team's shared positions (agents.search.execution.safety; default on; 'off' shows what the "
             "agents do without it)"),
        value=lambda v: v == "on",
        note="--safety off: no safety layer between the controller and the env"),
)


def apply_method_flags(methods: List[Any], args: argparse.Namespace) -> List[Any]:
    """``methods`` with the given flags of :data:`METHOD_FLAGS` applied to the methods each applies to."""
    for row in METHOD_FLAGS:
        if row.given(args):
            change = {row.option: row.value(getattr(args, row.dest))}
            methods = [m.with_options(**change) if APPLIES[row.applies](m) else m for m in methods]
    return methods


#: what an evaluation writes into --out (--overwrite removes these, and only these)
EVALUATE_OUTPUTS = ("run.json", "runs.csv", "table.csv", "table.json", "table.md", "figure.png", "run.gif",
                    "failures.csv", "anatomy.csv", "anatomy.md", "anatomy.png", "c_max.json", "validation_runs.csv",
                    "edge_memory_*.npz")
#: options that do not change the rows: a resumed evaluation may give others
NOT_ROW_SETTINGS = ("out", "resume", "overwrite", "no_progress", "json", "figure", "video", "ray", "command", "func",
                    "argv", "interrupt_note")


def _folder(args: argparse.Namespace):
    from agents.run_folder import RunFolder

    return RunFolder(args.out, "safe-mapf evaluate", EVALUATE_OUTPUTS, "run.json")


def _settings(args: argparse.Namespace) -> dict:
    """The options that decide the rows (recorded in run.json, compared by --resume)."""
    return {k: v for k, v in sorted(vars(args).items()) if k not in NOT_ROW_SETTINGS and not callable(v)}


def _flag(key: str) -> str:
    return "--" + key.replace("_", "-")


def _check_before_work(args: argparse.Namespace):
    """Agent counts that fit the map and the graph, what ``--out`` allows (``--resume``,
    ``--overwrite``) and that it is writable; returns the output folder. Writes nothing."""
    import safe_mapf_envs
    from baselines.evaluation import placeable_agents
    from baselines.output import check_output_dir

    too_many = [n for n in args.agents if n > args.nodes]
    if too_many:
        raise ValueError(f"--agents {max(too_many)}: more agents than graph nodes (--nodes {args.nodes}); every "
                         "agent needs a start and a goal node of its own")
    _folder(args).check(_settings(args), resume=args.resume, overwrite=args.overwrite, may_differ=NOT_ROW_SETTINGS,
                        describe=_flag)
    if args.protocol == "strict":  # agents collide: they must fit on the map side by side, apart
        try:  # the env's constructor decides whether every reset can place them
            safe_mapf_envs.parallel_env(args.env, n_agents=max(args.agents)).close()
        except ValueError as exc:
            raise ValueError(f"--agents {max(args.agents)}: {exc}") from None
        placed, separation = placeable_agents(args.env, max(args.agents), n_nodes=args.nodes, seed=args.seed)
        if placed < max(args.agents):
            raise ValueError(f"--agents {max(args.agents)}: the {args.nodes} graph nodes of --seed {args.seed} hold "
                             f"about {placed} agents {separation:g} units apart, as a problem's starts must stand "
                             "(the most of 200 placements); use fewer agents or more --nodes")
    return check_output_dir(args.out)


def _open_rows(args: argparse.Namespace, out, failure_file: bool = True):
    """Make ``--out`` ready (see :class:`agents.run_folder.RunFolder`) and open its row files.

    Returns ``(kept, writer, failures, failure_writer)``: the rows of the runs an interrupted
    evaluation there already ran (``--resume``; parsed) and a writer that appends to
    ``runs.csv``; the failure records of the kept runs and a writer that appends to
    ``failures.csv`` (``None``, ``[]`` and ``None`` without ``failure_file``). Without ``--resume``
    both start empty."""
    import shlex

    from baselines.anatomy import FAILURE_FIELDS, RUN_KEYS
    from baselines.cli import resume_command
    from baselines.output import RowWriter, parse_row, read_kept_rows, write_rows_atomic

    _folder(args).prepare(_settings(args), resume=args.resume, overwrite=args.overwrite,
                          may_differ=NOT_ROW_SETTINGS, describe=_flag,
                          extra={"command": shlex.join(["safe-mapf", *getattr(args, "argv", [])])})
    kept = read_kept_rows(out / "runs.csv") if args.resume else []
    keys = {tuple(r[k] for k in RUN_KEYS) for r in kept}
    failures = [r for r in (read_kept_rows(out / "failures.csv") if args.resume else [])
                if tuple(r.get(k) for k in RUN_KEYS) in keys]
    if args.resume:  # without a line an interruption cut off
        write_rows_atomic(kept, out / "runs.csv", fields=list(kept[0]) if kept else None)
    if failure_file:
        write_rows_atomic(failures, out / "failures.csv", fields=FAILURE_FIELDS)
    writer = RowWriter(out / "runs.csv", append=True)
    args.interrupt_note = lambda: (
        f"kept {len(kept) + writer.count} runs in {out / 'runs.csv'}; continue with: "
        + resume_command(getattr(args, "argv", [])))
    failure_writer = RowWriter(out / "failures.csv", FAILURE_FIELDS, append=True) if failure_file else None
    return [parse_row(r) for r in kept], writer, failures, failure_writer



def _read_c_max_file(path, flag: str) -> dict:
    """The content of a ``c_max.json`` (``flag`` names where it came from in errors)."""
    from agents.run_folder import read_json

    try:
        meta = read_json(path, what=f"{flag} file")
    except FileNotFoundError:
        raise ValueError(f"{flag} {str(path)!r}: no such file") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("chosen"), dict):
        raise ValueError(f"{flag} {str(path)!r} is not the c_max.json of an evaluation (no 'chosen' entry)")
    return meta


def _small_run_note(args: argparse.Namespace) -> str:
    """A line for runs with the small default size, saying what the full table takes."""
    if args.json or tuple(args.agents) != SMALL_AGENTS or args.problems != SMALL_PROBLEMS:
        return ""
    return f"a small run (the defaults: --agents 1 5 --problems 5); {FULL_RUN_NOTE}\n"


def _c_max(text: str):
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number or 'auto', got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"c_max must be > 0, got {text!r}")
    return value


def _int_at_least(minimum: int, what: str):
    """An argparse type: an integer >= ``minimum``, with an error that says ``what`` is expected."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(f"expected a {what} integer, got {text!r}")
        return value

    return parse


_positive = _int_at_least(1, "positive")


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative number, got {text!r}")
    return value
_non_negative = _int_at_least(0, "non-negative")


def run(args: argparse.Namespace) -> int:
    """Run each method on the same problems (difficulties easy / medium / hard target the
    largest finite shortest-path distance on the buffer graph divided by 8 / 4 / 2), then write
    per-run rows (runs.csv), the aggregate (table.csv, table.json), a Markdown table laid out like the
    paper's Table I (table.md, printed) and the trajectory figure (figure.png)."""
    import torch

    from baselines.anatomy import failure_records
    from baselines.cli import show_progress
    from baselines.evaluation import EvaluationSetup, evaluate
    from baselines.methods import DEFAULT_METHODS, get_methods

    repair_seed = _check_flags(args)
    torch.set_num_threads(1)
    if args.protocol == "paper":
        return _run_paper(args)
    chosen, validation_seed = _c_max_from_file(args)
    out = _check_before_work(args)
    print(_small_run_note(args), end="", file=sys.stderr, flush=True)
    methods = get_methods(dict.fromkeys(args.methods or DEFAULT_METHODS))
    marl = _marl_models(args, [m.name for m in methods])  # before any work: a missing policy fails here
    methods = apply_method_flags(methods, args)  # the flags' changes to the methods' configs
    t0 = time.perf_counter()
    models = _load_models(args, marl)
    kept, writer, failures, failure_writer = _open_rows(args, out)  # every check passed: the folder is ours
    assert failure_writer is not None
    setup = EvaluationSetup.build(args.env, n_nodes=args.nodes, seed=args.seed, models=models, sparsify=args.sparsify)
    progress = show_progress(args.no_progress or args.json)
    if chosen is None and args.c_max == "auto":
        chosen, validation_seed = _choose_c_max(args, setup, methods, out, progress)
    memories = _edge_memories(args, setup, methods, out, progress, chosen, repair_seed) if args.repair_problems \
        else None

    def keep(row, _problem, ex) -> None:
        records = failure_records(row, ex.failures)
        for record in records:  # before the row: a row in runs.csv always has its failures beside it
            failure_writer.write(record)
        writer.write(row)
        failures.extend(records)

    with writer, failure_writer:  # rows reach the files as they come
        rows = evaluate(setup, methods, args.agents, args.difficulty, args.problems, seed=args.seed,
                        max_cycles=args.max_cycles, progress=progress, policy_agents=args.policies_at,
                        c_max_by_agents=chosen, ray=args.ray, memories=memories, on_run=keep, kept=kept)
    notes = _notes(args, chosen, validation_seed, memories, repair_seed)
    agg, text, anatomy = _write_tables(args, out, rows, failures, [m.name for m in methods], notes,
                                       wall=time.perf_counter() - t0)
    _draw(args, out, setup, methods, chosen)
    if args.json:
        print(json.dumps(agg))
    else:
        print(text)
        print("\nWhy agents did not arrive (failed agents per reason):\n\n" + anatomy)
        print(f"\nwrote {out / 'runs.csv'}, {out / 'table.csv'}, {out / 'table.json'}, {out / 'table.md'}, "
              f"{out / 'failures.csv'}, {out / 'anatomy.md'}, {out / 'anatomy.png'}"
              + (f", {out / 'figure.png'}" if args.figure else "") + (f", {out / 'run.gif'}" if args.video else ""))
    return 0


def _check_flags(args: argparse.Namespace) -> int:
    """Checks of the flags among themselves and of the env id, before anything is loaded; returns the
    seed of the repair problems. ``--map`` registers the map's env and sets ``args.env`` to it."""
    import gymnasium as gym

    import safe_mapf_envs  # noqa: F401  (registers the ids)
    from baselines.cli import env_for_map
    from baselines.evaluation import REPAIR_SEED_OFFSET
    from baselines.methods import DEFAULT_METHODS, get_methods

    args.env = env_for_map(args.env, args.map_file)  # a map of one's own: its id, registered
    repair_seed = args.seed + REPAIR_SEED_OFFSET if args.repair_seed is None else args.repair_seed
    if args.repair_problems and repair_seed == args.seed:
        raise ValueError(f"--repair-seed must differ from --seed ({args.seed}): the graph never learns on the test "
                         "problems")
    if args.max_leg is not None and not args.max_leg > 0:  # NaN too
        raise ValueError(f"--max-leg must be > 0 steps, got {args.max_leg}")
    if args.c_max == "auto" and args.validation_seed == args.seed:
        raise ValueError(f"--validation-seed must differ from --seed ({args.seed}): c_max is never chosen on the "
                         "test problems")
    if args.env.split(":")[-1] not in gym.registry:
        known = sorted(k for k in gym.registry if k.startswith("Safe"))
        raise ValueError(f"unknown env id {args.env!r}; registered: {', '.join(known)}")
    if args.ray is not None:
        from baselines.distributed import require_ray

        require_ray()  # before any work
    if args.protocol == "strict" and args.c_max == "auto" and args.c_max_from is None and not any(
            m.search and math.isfinite(m.c_max) for m in get_methods(dict.fromkeys(args.methods or DEFAULT_METHODS))):
        raise ValueError("--c-max auto needs a constrained search among --methods (ours or ours_budget)")
    return repair_seed


def _c_max_from_file(args: argparse.Namespace):
    """The per-agent-count c_max of ``--c-max-from`` and the seed it was chosen on (``(None, None)``
    without it); checked against this run's seed and agent counts."""
    if args.c_max_from is None:
        return None, None
    if args.c_max is not None:
        raise ValueError("give --c-max or --c-max-from, not both")
    meta = _read_c_max_file(args.c_max_from, "--c-max-from")
    if meta.get("test_seed") is not None and meta.get("validation_seed") == args.seed:
        raise ValueError(f"{args.c_max_from} chose c_max on seed {args.seed}, the test seed of this run")
    chosen = {int(k): float(v) for k, v in meta["chosen"].items()}
    missing = sorted(set(args.agents) - set(chosen))
    if missing:
        raise ValueError(f"{args.c_max_from} has no c_max for agent counts {missing} (it has {sorted(chosen)})")
    return {k: chosen[k] for k in args.agents}, meta.get("validation_seed")


def _load_models(args: argparse.Namespace, marl: dict) -> dict:
    """The two agents (``--unconstrained`` / ``--constrained`` or the shipped ones) and the MARL policies."""
    from agents import load_pretrained
    from agents.search.models import default_second_opinion

    models = {k: load_pretrained(args.env, kind=k, path=getattr(args, k)) for k in ("unconstrained", "constrained")}
    models.update(marl)
    if args.max_leg is not None and math.isfinite(args.max_leg) and default_second_opinion(
            models["unconstrained"], models["constrained"]) is None:
        raise ValueError("--max-leg needs a constrained agent with a distance critic of its own to read the legs with")
    return models


def _choose_c_max(args: argparse.Namespace, setup, methods, out, progress: bool):
    """``--c-max auto``: the per-agent-count c_max chosen on validation problems (or before an
    interruption, ``--resume``), written to ``c_max.json`` with the validation runs; and its seed."""
    from agents.run_folder import write_atomic
    from baselines.evaluation import VALIDATION_SEED_OFFSET, select_c_max, write_csv

    if args.resume and (out / "c_max.json").exists():
        meta = _read_c_max_file(out / "c_max.json", "--resume: the folder's")  # chosen before the interruption
        return {k: float(meta["chosen"][str(k)]) for k in args.agents}, meta.get("validation_seed")
    constrained = [m for m in methods if m.search and math.isfinite(m.c_max)]  # not empty: checked before
    vseed = args.seed + VALIDATION_SEED_OFFSET if args.validation_seed is None else args.validation_seed
    sel = select_c_max(setup, constrained[0], args.agents, args.difficulty, grid=args.c_max_grid,
                       n_problems=args.validation_problems, seed=vseed, test_seed=args.seed,
                       max_cycles=args.max_cycles, progress=progress, ray=args.ray)
    write_csv(sel.rows, out / "validation_runs.csv")
    write_atomic(out / "c_max.json", json.dumps(
        {"chosen": {str(k): v for k, v in sel.chosen.items()}, "grid": sel.grid, "validation_seed": sel.seed,
         "test_seed": args.seed, "validation_problems": args.validation_problems, "method": constrained[0].name,
         "table": sel.table}, indent=1))
    return sel.chosen, sel.seed


def _edge_memories(args: argparse.Namespace, setup, methods, out, progress: bool, chosen, repair_seed: int) -> dict:
    """``--repair-problems``: per search method, the edge memory its graph learns on the repair problems
    (or learned before an interruption, ``--resume``), written to ``edge_memory_<method>.npz``."""
    from agents.run_folder import atomic_output
    from agents.search.execution.repair import EdgeMemory
    from baselines.evaluation import learn_edge_memory

    paths = {m.name: out / f"edge_memory_{m.name}.npz" for m in methods if m.search}
    if args.resume and all(p.exists() for p in paths.values()):  # learned before the interruption
        return {name: EdgeMemory.load(p) for name, p in paths.items()}
    memories = learn_edge_memory(setup, methods, args.agents, args.difficulty, args.repair_problems,
                                 seed=repair_seed, test_seed=args.seed, max_cycles=args.max_cycles,
                                 progress=progress, policy_agents=args.policies_at, c_max_by_agents=chosen,
                                 ray=args.ray)
    for name, memory in memories.items():
        with atomic_output(out / f"edge_memory_{name}.npz") as tmp:
            memory.save(tmp)
    return memories


def _notes(args: argparse.Namespace, chosen, validation_seed, memories, repair_seed: int) -> str:
    """The lines of ``table.md``'s header after its first: the chosen c_max, the method flags given, the
    edges the repair problems removed."""
    text = ""
    if chosen is not None:
        text += ("c_max chosen on validation problems (seed " + str(validation_seed) + "): "
                 + ", ".join(f"{k} agent{'s' if k > 1 else ''}: {v:g}" for k, v in chosen.items()) + "\n\n")
    for row in METHOD_FLAGS:
        if row.note and row.given(args) and (row.dest != "safety" or args.safety == "off"):
            text += row.note.format(value=getattr(args, row.dest)) + "\n\n"
    if memories:
        text += (f"--repair-problems {args.repair_problems} (seed {repair_seed}): edges removed after failed "
                 "traversals, " + ", ".join(f"{k}: {len(m)}" for k, m in memories.items()) + "\n\n")
    return text


def _write_tables(args: argparse.Namespace, out, rows, failures, names, notes: str, wall: float):
    """Write ``table.csv``, ``table.json``, ``table.md`` and the failure anatomy; returns the
    aggregated rows, the header and table printed, and the anatomy's table."""
    from agents.run_folder import write_atomic
    from baselines.evaluation import markdown_table, write_csv
    from baselines.metrics import aggregate

    agg = aggregate(rows)
    write_csv(agg, out / "table.csv")
    write_atomic(out / "table.json", json.dumps(agg, indent=1))
    anatomy = write_anatomy(rows, failures, out, title=args.env)
    table = markdown_table(agg, names)
    header = (f"{args.env}: largest cumulative cost over agents, mean ± std over successful runs "
              f"(success rate; safety rate: the share of agents that never touched another); {args.problems} "
              f"problem{'s' if args.problems != 1 else ''} per cell, seed {args.seed}, {wall:.0f} s\n\n") + notes
    write_atomic(out / "table.md", header + table + "\n\nMean cumulative cost over agents:\n\n"
                                  + markdown_table(agg, names, value="mean_cost") + "\n")
    return agg, header + table, anatomy


def _draw(args: argparse.Namespace, out, setup, methods, chosen) -> None:
    """The trajectory figure (``--figure``) and the GIF (``--video``): the smallest evaluated agent
    count and the largest one up to 10, the constrained searches with the c_max chosen for the latter."""
    from agents.run_folder import atomic_output

    counts = sorted(set(args.agents))
    multi = max([k for k in counts if k <= 10] or counts[:1])
    fig_methods = methods
    if chosen is not None:
        fig_methods = [m.with_options(c_max=chosen[multi]) if m.search and math.isfinite(m.c_max) else m
                       for m in methods]
    if args.figure:
        from baselines.figures import trajectory_figure

        with atomic_output(out / "figure.png") as tmp:
            trajectory_figure(setup, fig_methods, tmp, agent_counts=sorted({counts[0], multi}), seed=args.seed)
    if args.video:
        from baselines.figures import run_animation

        search = [m for m in fig_methods if m.search] or list(fig_methods)
        with atomic_output(out / "run.gif") as tmp:
            run_animation(setup, search[-1], tmp, n_agents=multi, seed=args.seed, max_cycles=args.max_cycles)


def _marl_models(args: argparse.Namespace, names) -> dict:
    """The policies of the MARL methods among ``names`` (``--ippo``/``--mappo-lag`` or the shipped ones)."""
    from baselines.marl_rows import load_marl_models

    return load_marl_models(args.env, names, {"ippo": args.ippo, "mappo_lag": args.mappo_lag})


def write_anatomy(rows, failures, out, title: str = "") -> str:
    """Write the failure anatomy of an evaluation into ``out``: ``failures.csv`` (one row per agent
    that did not arrive), ``anatomy.csv`` / ``anatomy.md`` (reasons per cell) and ``anatomy.png``
    (stacked bars); returns the Markdown table."""
    from agents.run_folder import atomic_output, write_atomic
    from baselines.anatomy import FAILURE_FIELDS, anatomy_figure, anatomy_table, failure_summary
    from baselines.contact_anatomy import contact_summary, contact_table
    from baselines.evaluation import write_csv
    from baselines.output import write_rows_atomic

    write_rows_atomic(failures, out / "failures.csv", fields=FAILURE_FIELDS)  # a header alone: every agent arrived
    summary = failure_summary(rows)
    write_csv(summary, out / "anatomy.csv")
    table = anatomy_table(summary)
    text = (f"{title}: why agents did not arrive (failed agents per reason, share of the cell's failed "
            "agents)\n\n" + table + "\n")
    contacts = contact_summary(rows)
    if contacts:
        text += (f"\n{title}: why agents touched (contacts between agents per reason, counted when they "
                 "begin; baselines.contact_anatomy)\n\n" + contact_table(contacts) + "\n")
    write_atomic(out / "anatomy.md", text)
    with atomic_output(out / "anatomy.png") as tmp:
        anatomy_figure(summary, tmp, title=title)
    return table


def _run_paper(args: argparse.Namespace) -> int:
    """``--protocol paper``: the published code's conventions (see :mod:`baselines.paper_protocol`)."""

    from agents import load_pretrained
    from baselines.cli import show_progress
    from baselines.methods import MARL_METHODS, get_methods
    from baselines.paper_protocol import PAPER_PROTOCOL_METHODS, PaperSetup, evaluate_paper, write_paper_outputs

    names = list(dict.fromkeys(args.methods or PAPER_PROTOCOL_METHODS))
    allowed = PAPER_PROTOCOL_METHODS + MARL_METHODS
    if set(names) - set(allowed):
        raise ValueError(f"--protocol paper runs {', '.join(allowed)}; not {sorted(set(names) - set(allowed))}")
    marl = _marl_models(args, names)
    for row in METHOD_FLAGS:
        if row.given(args) or getattr(args, row.dest) == "auto":
            raise ValueError(f"{row.flag} does not apply to --protocol paper ({row.paper})")
    for flag, value in (("--repair-problems", args.repair_problems or None), ("--sparsify", args.sparsify)):
        if value is not None:
            raise ValueError(f"{flag} does not apply to --protocol paper (the published code's graph, followed "
                             "open loop)")
    methods = get_methods(names)
    out = _check_before_work(args)
    print(_small_run_note(args), end="", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    models = {k: load_pretrained(args.env, kind=k, path=getattr(args, k)) for k in ("unconstrained", "constrained")}
    models.update(marl)
    kept, writer, _, _ = _open_rows(args, out, failure_file=False)  # every check passed: the folder is ours
    setup = PaperSetup.build(args.env, models, n_nodes=args.nodes, seed=args.seed)
    progress = show_progress(args.no_progress or args.json)
    with writer:  # rows reach the file as they come
        rows = evaluate_paper(setup, methods, args.agents, args.difficulty, args.problems, seed=args.seed,
                              max_cycles=args.max_cycles, progress=progress, policy_agents=args.policies_at,
                              candidates=args.paper_candidates, on_row=writer.write, ray=args.ray, kept=kept)
    agg, text = write_paper_outputs(rows, out, names, env_id=args.env, n_problems=args.problems, seed=args.seed,
                                    wall=time.perf_counter() - t0, cost_limit=setup.cost_limit,
                                    grid=setup.c_max_grid(), targets=setup.targets)
    if args.json:
        print(json.dumps(agg))
    else:
        print(text)
        print(f"\nwrote {out / 'runs.csv'}, {out / 'table.csv'}, {out / 'table.json'}, {out / 'table.md'}, "
              f"{out / 'c_max.json'}")
    return 0

