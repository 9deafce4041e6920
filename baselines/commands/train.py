"""``safe-mapf train``: train the goal-conditioned safe agent, one stage at a time."""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any, Dict, List, Optional, Sequence


def register(sub: argparse._SubParsersAction) -> None:
    from agents.training import TrainConfig
    from baselines.cli import add_map_argument
    from baselines.output import add_resume_arguments

    d = TrainConfig()
    p = sub.add_parser(
        "train", help="train the goal-conditioned safe agent (unconstrained or constrained stage)",
        description=run.__doc__,
        epilog="example: safe-mapf train --env SafeCentralObstacle-v0 --stage unconstrained --out runs/u; "
               "safe-mapf train --env SafeCentralObstacle-v0 --stage constrained --init runs/u/model.zip --out runs/c",
    )
    p.add_argument("--env", dest="env_id", default=d.env_id, help="registered environment id")
    add_map_argument(p)
    p.add_argument("--stage", choices=["unconstrained", "constrained"], default=d.stage,
                   help="train from scratch, or fine-tune --init with the Lagrange multiplier")
    p.add_argument("--timesteps", type=int, default=d.timesteps, help="environment steps of this stage")
    p.add_argument("--seed", type=int, default=d.seed, help="seed of the run")
    p.add_argument("--seeds", type=int, nargs="+", default=None, metavar="S",
                   help="one run per seed instead of --seed, each in <out>/s<seed>, and a combined summary in "
                        "<out>/summary.json (default out: runs/<env>-<stage>)")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="with --seeds: run the seeds as Ray tasks (one CPU each) on a local Ray, 'auto' (the "
                        "running cluster) or an address; needs the ray extra: pip install \"safe-mapf[ray]\"")
    p.add_argument("--out", dest="out_dir", default=None,
                   help="output folder (default runs/<env>-<stage>-s<seed>): model.zip, config.json, "
                        "evaluations.jsonl, summary.json")
    p.add_argument("--init", default=None, help="checkpoint to fine-tune (required for --stage constrained)")
    g = p.add_argument_group("training problems")
    g.add_argument("--sampler", choices=["self", "oracle", "uniform"], default=d.sampler,
                   help="self: the paper's self-sampling; oracle: SoRB's ground-truth geodesic band; uniform")
    g.add_argument("--target-distance", type=float, nargs=2, metavar=("LO", "HI"), default=list(d.target_distance),
                   help="self-sampling: band of desired predicted distances (steps)")
    g.add_argument("--target-cost", type=float, nargs=2, metavar=("LO", "HI"), default=None,
                   help="self-sampling: band of desired predicted costs (default: distance only)")
    g.add_argument("--cost-fraction", type=float, default=d.cost_fraction,
                   help="self-sampling: share of the kept problems chosen with --target-cost")
    g.add_argument("--n-candidates", type=int, default=d.n_candidates, help="self-sampling: N")
    g.add_argument("--n-keep", type=int, default=d.n_keep, help="self-sampling: K")
    g.add_argument("--disagreement-weight", type=float, default=d.disagreement_weight)
    g.add_argument("--narrow-fraction", type=float, default=d.narrow_fraction,
                   help="self-sampling: share of each refill's problems that cross a narrow passage (doorway, "
                        "corridor; start and goal on either side), kept without scoring by the critic")
    g.add_argument("--parked-agents", type=int, default=d.parked_agents, metavar="M",
                   help="other agents standing still near the straight line of each training episode, seen in "
                        "the panoramas and in the way (default 0)")
    g.add_argument("--parked-fraction", type=float, default=d.parked_fraction, metavar="P",
                   help="share of the training episodes that have the --parked-agents (default 1: all)")
    g.add_argument("--oracle-band", type=float, nargs=2, metavar=("LO", "HI"), default=list(d.oracle_band),
                   help="oracle sampler: geodesic goal distance band (world units)")
    g = p.add_argument_group("constrained stage")
    g.add_argument("--cost-limit", type=float, default=d.cost_limit, help="episode-cost limit delta")
    g.add_argument("--lagrange-lr", type=float, default=d.lagrange_lr)
    g.add_argument("--lagrange-init", type=float, default=d.lagrange_init)
    g.add_argument("--lagrange-max", type=float, default=None)
    g.add_argument("--lagrange-update-episodes", type=int, default=d.lagrange_update_episodes)
    g = p.add_argument_group("learning")
    g.add_argument("--batch-size", type=int, default=d.batch_size)
    g.add_argument("--learning-rate", type=float, default=None,
                   help="critic learning rate (default: 3e-4 for vectors, 1e-3 for panoramas)")
    g.add_argument("--actor-learning-rate", type=float, default=None, help="default: --learning-rate")
    g.add_argument("--buffer-size", type=int, default=d.buffer_size)
    g.add_argument("--learning-starts", type=int, default=d.learning_starts)
    g.add_argument("--n-critics", type=int, default=d.n_critics)
    g.add_argument("--n-cost-critics", type=int, default=d.n_cost_critics)
    g.add_argument("--net-arch", type=int, nargs="+", default=d.net_arch, help="hidden widths of the heads")
    g.add_argument("--encoder-arch", type=int, nargs="+", default=d.encoder_arch, help="MLP encoder widths")
    g.add_argument("--conv-layers", type=_conv_layer, nargs="+", default=None, metavar="F,K,S",
                   help="image encoder convolutions as filters,kernel,stride (default: the paper's 16,8,4 32,4,4, "
                        "which reads the top-left 20 x 20 pixels of a 32 x 32 view; 16,8,4 32,3,2 reads all)")
    g.add_argument("--share-encoder", dest="share_encoder", action="store_true", default=None,
                   help="one encoder for actor and critics, trained by the critic losses (default for images)")
    g.add_argument("--separate-encoders", dest="share_encoder", action="store_false",
                   help="an encoder per network (default for vectors)")
    g.add_argument("--actor-penalty", type=float, default=None,
                   help="weight of the actor's pre-tanh penalty (default: 0.01 for panoramas, 0 for vectors)")
    g.add_argument("--augmentation", choices=["shift"], default=None,
                   help="image augmentation of the shared encoder (DrQ's random shift)")
    g.add_argument("--distance-bins", type=int, default=None, help="default: the episode step limit")
    g.add_argument("--cost-bins", type=int, default=d.cost_bins)
    g.add_argument("--cost-max", type=float, default=d.cost_max)
    g.add_argument("--action-noise", type=float, default=d.action_noise)
    g.add_argument("--her-ratio", type=float, default=d.her_ratio)
    g.add_argument("--random-goal-ratio", type=float, default=d.random_goal_ratio)
    g = p.add_argument_group("evaluation and output")
    g.add_argument("--eval-freq", type=int, default=d.eval_freq, help="steps between evaluations and checkpoints")
    g.add_argument("--eval-problems", type=int, default=d.eval_problems)
    g.add_argument("--eval-max-distance", type=float, default=None,
                   help="geodesic limit of the success pairs (default: 3 m on the apartments, 10 on the 2D maps)")
    g.add_argument("--eval-pairs", type=int, default=d.eval_pairs)
    g.add_argument("--eval-pair-max-distance", type=float, default=None,
                   help="geodesic limit of the correlation pairs (default: 4 m on the apartments, 15 on the 2D maps)")
    g.add_argument("--eval-seed", type=int, default=d.eval_seed)
    g.add_argument("--threads", type=int, default=d.threads, help="torch threads")
    add_resume_arguments(g, "continue the run in --out from its last resume point, up to --timesteps steps in all "
                            "(with the run's own settings; --timesteps, --threads and the output options may change)")
    g.add_argument("--replay-save-freq", type=int, default=None,
                   help="steps between resume points (model and replay buffer; default: --eval-freq; 0: never)")
    g.add_argument("--no-progress", dest="progress_bar", action="store_false",
                   help="hide the progress bar (it is drawn only when stderr is a terminal)")
    g.add_argument("--tensorboard", dest="tensorboard_log", default=None,
                   help="write TensorBoard event files to this folder")
    g.add_argument("--verbose", type=int, default=d.verbose)
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _conv_layer(text: str) -> tuple:
    """``"16,8,4"`` -> ``(16, 8, 4)`` for ``--conv-layers``."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected filters,kernel,stride (three positive integers), got {text!r}")
    return values


def config_from_args(args: argparse.Namespace):
    """A :class:`agents.training.TrainConfig` from parsed arguments."""
    import dataclasses

    from agents.training import TrainConfig
    from baselines.cli import env_for_map, show_progress

    names = {f.name for f in dataclasses.fields(TrainConfig)}
    kwargs = {k: v for k, v in vars(args).items() if k in names}
    kwargs["env_id"] = env_for_map(args.env_id, getattr(args, "map_file", None))
    for k in ("target_distance", "target_cost", "oracle_band"):
        if kwargs.get(k) is not None:
            kwargs[k] = tuple(kwargs[k])
    kwargs["progress_bar"] = show_progress(not kwargs.get("progress_bar", True))
    return TrainConfig(**kwargs)


def run(args: argparse.Namespace) -> int:
    """Train one stage of the goal-conditioned safe agent and evaluate it periodically.

    Writes model.zip, checkpoint.zip, config.json, evaluations.jsonl and summary.json to the
    output folder and prints the final held-out figures (success rate on pairs within
    --eval-max-distance, mean episode cost, Spearman correlation of predicted distances).
    With --seeds, one such run per seed (in parallel on Ray with --ray) and a combined summary.
    """
    from agents.training import train_stage

    cfg = config_from_args(args)
    command = ["safe-mapf", *getattr(args, "argv", sys.argv[1:])]
    args.interrupt_note = lambda: _interrupt_note(args, cfg)
    if args.seeds is not None or args.ray is not None:
        return _run_seeds(args, cfg, command)
    summary = train_stage(cfg, command=command)  # its checks come first
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(_line(summary))
    return 0


def _interrupt_note(args: argparse.Namespace, cfg: Any) -> str:
    """What an interrupted ``train`` kept, and the command that continues it."""
    import os

    from baselines.cli import resume_command

    folders = ([os.path.join(args.out_dir or "", f"s{s}") for s in args.seeds] if args.seeds
               else [cfg.resolved_out_dir()])
    points = [f for f in folders if os.path.exists(os.path.join(f, "resume", "state.json"))]
    if not points:
        return "no resume point was written yet (one comes every --replay-save-freq steps)"
    return (f"the last resume point is kept in {', '.join(os.path.join(f, 'resume') for f in points)}; continue with: "
            + resume_command(getattr(args, "argv", [])))


def _line(summary: Dict[str, Any], seed: bool = False) -> str:
    ev = summary["final_evaluation"]
    which = f" seed {summary['seed']}" if seed else ""
    return (f"{summary['env_id']} {summary['stage']}{which}: {summary['timesteps']} steps in "
            f"{summary['wall_s']} s (cpu {summary['cpu_s']} s); success={ev['success_rate']:.3f} "
            f"cost={ev['mean_cost']:.2f} spearman={ev['distance_spearman']:.3f} "
            f"lambda={summary['lagrange_multiplier']:.3f}; saved {summary['model']}")


def _train_one(cfg: Any, command: Optional[List[str]], map_specs: Sequence[Any] = ()) -> Dict[str, Any]:
    """One seed's run; ``map_specs``: the ids of maps of one's own to register first (a Ray worker
    does not know the ones the command registered)."""
    from agents.training import train_stage
    from safe_mapf_envs.registration import register_spec

    for spec in map_specs:
        register_spec(spec)
    return train_stage(cfg, command=command)


def _run_seeds(args: argparse.Namespace, cfg: Any, command: Optional[List[str]]) -> int:
    """One run per seed (serially, or as Ray tasks) and a combined summary."""
    import dataclasses
    import os
    import time

    import numpy as np

    from agents.run_folder import write_json_atomic
    from agents.training import check_run

    if args.seeds is None:
        raise ValueError("--ray trains several seeds at once: give them with --seeds S [S ...]")
    seeds = list(dict.fromkeys(args.seeds))
    base = args.out_dir or os.path.join("runs", f"{cfg.env_id.split(':')[-1]}-{cfg.stage}")
    cfgs = [dataclasses.replace(cfg, seed=s, out_dir=os.path.join(base, f"s{s}")) for s in seeds]
    for c in cfgs:  # every seed's folder, before the first run starts
        check_run(c)
    if args.ray is not None:
        from baselines.distributed import require_ray

        require_ray()
    t0 = time.perf_counter()
    if args.ray is not None:
        from baselines.distributed import init_ray

        ray = init_ray(args.ray)
        task = ray.remote(num_cpus=1)(_train_one)
        quiet = [dataclasses.replace(c, progress_bar=False) for c in cfgs]
        from safe_mapf_envs.registration import map_specs

        refs = [task.remote(c, command, map_specs()) for c in quiet]
        summaries = []
        pending = list(refs)
        while pending:  # report each run as it ends
            done, pending = ray.wait(pending, num_returns=1)
            summaries.append(ray.get(done[0]))
            if not args.json:
                print(_line(summaries[-1], seed=True), flush=True)
        summaries.sort(key=lambda s: seeds.index(s["seed"]))
    else:
        summaries = []
        for c in cfgs:
            summaries.append(_train_one(c, command))
            if not args.json:
                print(_line(summaries[-1], seed=True), flush=True)
    keys = {"success_rate": "success", "mean_cost": "cost", "distance_spearman": "spearman"}
    combined: Dict[str, Any] = {
        "env_id": cfg.env_id, "stage": cfg.stage, "seeds": seeds, "timesteps": cfg.timesteps,
        "wall_s": round(time.perf_counter() - t0, 1), "ray": args.ray,
        "runs": [{"seed": s["seed"], "out_dir": os.path.dirname(s["model"]), **{v: s["final_evaluation"][k]
                                                                                  for k, v in keys.items()}}
                 for s in summaries],
    }
    for v in keys.values():
        x = np.array([r[v] for r in combined["runs"]], dtype=np.float64)
        combined[v] = {"mean": float(x.mean()), "std": float(x.std()), "min": float(x.min()), "max": float(x.max())}
    os.makedirs(base, exist_ok=True)
    write_json_atomic(os.path.join(base, "summary.json"), combined)
    if args.json:
        print(json.dumps(combined, indent=2))
    else:
        print(f"{len(seeds)} seeds in {combined['wall_s']} s: " + ", ".join(
            f"{v} {combined[v]['mean']:.3f} ± {combined[v]['std']:.3f}" for v in keys.values())
              + f"; combined summary in {os.path.join(base, 'summary.json')}")
    return 0
