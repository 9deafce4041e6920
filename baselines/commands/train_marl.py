"""``safe-mapf train-marl``: the multi-agent RL baselines (IPPO, MAPPO-Lagrangian) on a PettingZoo env."""
from __future__ import annotations

import argparse
import json
import os
import sys


def register(sub: argparse._SubParsersAction) -> None:
    from agents.marl.config import ALGOS, MarlConfig
    from baselines.output import add_resume_arguments

    d = MarlConfig()
    p = sub.add_parser(
        "train-marl", help="train a multi-agent RL baseline (IPPO or MAPPO-Lagrangian), one policy for all agents",
        description=run.__doc__,
        epilog="example: safe-mapf train-marl --algo mappo-lag --env SafeCenterDot-v0 --agents 5 "
               "--timesteps 2000000 --out runs/cdot-mappo",
    )
    p.add_argument("--algo", choices=ALGOS, default=d.algo,
                   help="ippo: SB3 PPO over SuperSuit's vector env; mappo-lag: centralised critics and a Lagrangian "
                        "cost")
    p.add_argument("--env", dest="env_id", default=d.env_id, help="registered id with vector observations")
    p.add_argument("--agents", dest="n_agents", type=_int, default=d.n_agents, help="agents per training episode")
    p.add_argument("--timesteps", type=_int, default=d.timesteps,
                   help="agent steps in all (environment steps x agents)")
    p.add_argument("--seed", type=_int, default=d.seed, help="seed of the run")
    p.add_argument("--seeds", type=_int, nargs="+", default=None, metavar="S",
                   help="one run per seed instead of --seed (serially), each in <out>/s<seed>")
    p.add_argument("--out", dest="out_dir", default=None,
                   help="output folder (default runs/<env>-<algo>-s<seed>): model.zip or model.pt with model.json, "
                        "checkpoint files, config.json, evaluations.jsonl, summary.json")
    add_resume_arguments(p, "continue the run in --out from its last resume point, up to --timesteps agent steps "
                            "in all (with the run's own settings; --timesteps, --threads and the output options may "
                            "change)")
    g = p.add_argument_group("learning")
    g.add_argument("--max-cycles", type=_int, default=d.max_cycles, help="steps per training episode")
    g.add_argument("--goal-distance", type=float, nargs=2, metavar=("LO", "HI"), default=None,
                   help="geodesic start-goal distance band of the training episodes (default: goals anywhere)")
    g.add_argument("--shaping", type=float, default=d.shaping,
                   help="weight of potential-based shaping by the straight-line distance to the goal, read from "
                        "each agent's observation (0: the env's -1 per step alone)")
    g.add_argument("--n-envs", type=_int, default=d.n_envs, help="environment copies per rollout")
    g.add_argument("--n-steps", type=_int, default=d.n_steps, help="steps per copy per rollout")
    g.add_argument("--batch-size", type=_int, default=d.batch_size)
    g.add_argument("--n-epochs", type=_int, default=d.n_epochs)
    g.add_argument("--learning-rate", type=float, default=d.learning_rate)
    g.add_argument("--gamma", type=float, default=d.gamma)
    g.add_argument("--gae-lambda", type=float, default=d.gae_lambda)
    g.add_argument("--clip-range", type=float, default=d.clip_range)
    g.add_argument("--ent-coef", type=float, default=d.ent_coef)
    g.add_argument("--net-arch", type=_int, nargs="+", default=d.net_arch, help="hidden widths")
    g = p.add_argument_group("mappo-lag: the cost constraint")
    g.add_argument("--cost-limit", type=float, default=d.cost_limit, help="limit of an agent's episode cost")
    g.add_argument("--lagrange-lr", type=float, default=d.lagrange_lr)
    g.add_argument("--lagrange-init", type=float, default=d.lagrange_init)
    g.add_argument("--lagrange-start", type=_int, default=d.lagrange_start,
                   help="agent steps before the multiplier starts to move")
    g = p.add_argument_group("evaluation and output")
    g.add_argument("--eval-freq", type=_int, default=d.eval_freq,
                   help="agent steps between evaluations and resume points (0: only at the end)")
    g.add_argument("--eval-episodes", type=_int, default=d.eval_episodes)
    g.add_argument("--eval-seed", type=_int, default=d.eval_seed)
    g.add_argument("--threads", type=_int, default=d.threads, help="torch threads")
    g.add_argument("--tensorboard", dest="tensorboard_log", default=None,
                   help="write TensorBoard event files to this folder")
    g.add_argument("--no-progress", dest="progress_bar", action="store_false",
                   help="hide the progress bar (it is drawn only when stderr is a terminal)")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _interrupt_note(args: argparse.Namespace, cfgs) -> str:
    """What an interrupted ``train-marl`` kept, and the command that continues it."""

    from agents.marl.common import RunFolder
    from baselines.cli import resume_command

    points = [RunFolder.folder(c) for c in cfgs if (RunFolder.folder(c) / "checkpoint.json").exists()]
    if not points:
        return "no resume point was written yet (one comes every --eval-freq agent steps)"
    return (f"the last resume point is kept in {', '.join(map(str, points))}; continue with: "
            + resume_command(getattr(args, "argv", [])))


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def run(args: argparse.Namespace) -> int:
    """Train one parameter-shared policy for every agent of a PettingZoo env (goal-conditioned: each
    agent acts on its own position and goal), evaluating it on held-out episodes every --eval-freq
    agent steps. Writes the final policy (model.zip for ippo, model.pt for mappo-lag, each with
    model.json), resume points, config.json, evaluations.jsonl and summary.json; `safe-mapf evaluate
    --methods ippo mappo_lag --ippo PATH --mappo-lag PATH` puts the policies in the tables."""
    import dataclasses

    from agents.marl.common import RunFolder, print_line
    from agents.marl.config import MarlConfig
    from agents.marl.training import train_marl
    from baselines.cli import MissingExtraError, show_progress

    names = {f.name for f in dataclasses.fields(MarlConfig)}
    kwargs = {k: v for k, v in vars(args).items() if k in names}
    kwargs["progress_bar"] = show_progress(not args.progress_bar or args.json)
    seeds = list(dict.fromkeys(args.seeds)) if args.seeds else [args.seed]
    base = args.out_dir or os.path.join("runs", f"{args.env_id.split(':')[-1]}-{args.algo}")
    cfgs = [MarlConfig(**{**kwargs, "seed": s,
                          "out_dir": os.path.join(base, f"s{s}") if args.seeds else args.out_dir}) for s in seeds]
    if args.algo == "ippo":
        try:
            import supersuit  # noqa: F401
        except ImportError:
            raise MissingExtraError("--algo ippo needs SuperSuit: pip install \"safe-mapf[marl]\"") from None
    for cfg in cfgs:  # every run's folder, before the first run starts
        RunFolder.check(cfg)
    command = ["safe-mapf", *getattr(args, "argv", sys.argv[1:])]
    args.interrupt_note = lambda: _interrupt_note(args, cfgs)
    for cfg in cfgs:
        summary = train_marl(cfg, command=command)
        print(json.dumps(summary, indent=1) if args.json else print_line(summary), flush=True)
    return 0
