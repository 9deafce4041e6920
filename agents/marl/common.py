"""What both multi-agent trainers share: the training env, the held-out evaluation, the run folder
(progress bar, TensorBoard, evaluation log, resume points) and the loaded policy (:class:`MarlAgent`)."""
from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional

import numpy as np
from pettingzoo.utils.wrappers import BaseParallelWrapper

from ..run_folder import RunFolder as OutputFolder
from ..run_folder import atomic_output, read_json, read_json_lines, write_atomic, write_json_atomic
from .config import MarlConfig

#: file suffix of each algorithm's weights (an SB3 zip for IPPO, a torch file for MAPPO-Lagrangian)
SUFFIX = {"ippo": ".zip", "mappo-lag": ".pt"}
#: what a run writes into its folder (``overwrite`` removes these, and only these)
MARL_OUTPUTS = ("config.json", "evaluations.jsonl", "checkpoint.zip", "checkpoint.pt", "checkpoint.json", "model.zip",
                "model.pt", "model.json", "summary.json")
#: settings a resumed run may change; every other one must be the run's own
RESUMABLE_SETTINGS = ("timesteps", "out_dir", "resume", "overwrite", "threads", "progress_bar", "tensorboard_log")


def _flag(key: str) -> str:
    """The ``safe-mapf train-marl`` option of a setting, for messages."""
    return {"env_id": "--env", "out_dir": "--out", "n_agents": "--agents"}.get(key, "--" + key.replace("_", "-"))

Act = Callable[[np.ndarray], np.ndarray]


def make_env(env_id: str, n_agents: int, max_cycles: int, shaping: float = 0.0, gamma: float = 0.99,
             **kwargs: Any):
    """The parallel env with flat observations (``[position, goal]`` per agent, normalised); with
    ``shaping > 0`` its rewards carry :class:`PotentialShaping`."""
    import safe_mapf_envs

    env = safe_mapf_envs.parallel_env(env_id, n_agents=n_agents, max_cycles=max_cycles,
                                      observation_format="flat", **kwargs)
    return PotentialShaping(env, shaping, gamma) if shaping > 0 else env


class PotentialShaping(BaseParallelWrapper):
    """Potential-based reward shaping (Ng, Harada and Russell, 1999) from the agent's own observation.

    ``r += weight * (gamma * phi(o') - phi(o))`` with ``phi(o) = -|goal - position|`` in steps of
    full speed (straight-line distance, read from the flat observation; ``phi = 0`` once the agent
    arrived). Shaping of this form leaves the optimal policies unchanged; it gives PPO a signal
    on maps where random motion rarely reaches a goal (``SafeCentralObstacle-v0``: 55 x 55 units,
    goals reached within 1). Costs are untouched.
    """

    def __init__(self, env, weight: float, gamma: float) -> None:
        super().__init__(env)
        self.weight, self.gamma = float(weight), float(gamma)
        base = env.unwrapped
        self._scale = np.asarray(base.scenario.size, dtype=np.float64) / float(getattr(base, "action_scale", 1.0))
        self._phi: Dict[str, float] = {}

    def _potential(self, obs: np.ndarray) -> float:
        o = np.asarray(obs, dtype=np.float64)
        return -float(np.hypot(*((o[2:4] - o[0:2]) * self._scale)))

    def reset(self, seed: Optional[int] = None, options: Optional[dict] = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        self._phi = {a: self._potential(o) for a, o in obs.items()}
        return obs, infos

    def step(self, actions):
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        rewards = dict(rewards)
        for a in rewards:
            new = 0.0 if terms[a] else self._potential(obs[a])
            rewards[a] += self.weight * (self.gamma * new - self._phi[a])
            self._phi[a] = new
        return obs, rewards, terms, truncs, infos


def flat_observations(observations: Mapping[str, Any], names: List[str]) -> np.ndarray:
    """The agents' observations as one ``(len(names), d)`` float32 array (Dict observations flattened)."""
    from safe_mapf_envs import flatten_observation

    rows = [observations[a] for a in names]
    if rows and isinstance(rows[0], Mapping):
        rows = [flatten_observation(o) for o in rows]
    return np.asarray(rows, dtype=np.float32).reshape(len(names), -1)


def evaluate_policy(act: Act, env_id: str, n_agents: int, max_cycles: int, episodes: int,
                    seed: int, **env_kwargs: Any) -> Dict[str, float]:
    """Held-out episodes (seeds ``seed``, ``seed + 1``, ...) with deterministic actions.

    Returns the share of episodes in which every agent arrived (``success_rate``), the share of
    agents that arrived (``arrival_rate``), an agent's mean episode cost and the mean episode length.
    """
    env = make_env(env_id, n_agents, max_cycles, **env_kwargs)
    success, arrived, costs, steps = [], [], [], []
    for ep in range(episodes):
        obs, _ = env.reset(seed=seed + ep)
        cost = np.zeros(n_agents)
        reached = 0
        t = 0
        while env.agents:
            names = list(env.agents)
            actions = act(flat_observations(obs, names))
            obs, _, term, _, infos = env.step(dict(zip(names, actions)))
            t += 1
            for a, info in infos.items():
                cost[env.agent_name_mapping[a]] += float(info["cost"])
            reached += sum(bool(v) for v in term.values())
        success.append(reached == n_agents)
        arrived.append(reached / n_agents)
        costs.append(float(cost.mean()))
        steps.append(t)
    env.close()
    return {"success_rate": float(np.mean(success)), "arrival_rate": float(np.mean(arrived)),
            "mean_cost": float(np.mean(costs)), "mean_steps": float(np.mean(steps))}


class RunFolder:
    """The output folder of a run: settings, evaluations, resume points, summary, progress and TensorBoard.

    Files: ``config.json`` (settings, command, versions), ``evaluations.jsonl`` (one line per
    evaluation), ``checkpoint<suffix>`` + ``checkpoint.json`` (the last resume point),
    ``model<suffix>`` + ``model.json`` (the final policy, loadable with :func:`load_marl`),
    ``summary.json``.
    """

    def __init__(self, cfg: MarlConfig, command: Optional[List[str]] = None) -> None:
        self.cfg = cfg
        self.out = self.folder(cfg)
        self.suffix = SUFFIX[cfg.algo]
        self.command = command
        self.state = self.check(cfg)
        self.start_steps = int(self.state.get("timesteps", 0))
        self.t0 = time.perf_counter()
        self.cpu0 = time.process_time()
        self.wall_before = float(self.state.get("wall_s", 0.0))
        self.last_eval: Dict[str, float] = {}
        self.bar: Any = None
        from stable_baselines3.common.logger import Logger, make_output_format

        self.owned(cfg).prepare(asdict(cfg), resume=cfg.resume, overwrite=cfg.overwrite,
                                may_differ=RESUMABLE_SETTINGS, describe=_flag,
                                extra={"command": command, "python": platform.python_version(),
                                       "versions": _versions()})
        log = self.out / "evaluations.jsonl"
        if cfg.resume and log.exists():  # keep the evaluations up to the resume point
            kept = [r for r in read_json_lines(log) if r.get("timesteps", 0) <= self.start_steps]
            write_atomic(log, "".join(json.dumps(r) + "\n" for r in kept))
        formats = [make_output_format("tensorboard", cfg.tensorboard_log)] if cfg.tensorboard_log else []
        self.logger = Logger(cfg.tensorboard_log, formats)

    @staticmethod
    def folder(cfg: MarlConfig) -> Path:
        """The run's output folder (default ``runs/<env>-<algo>-s<seed>``)."""
        return Path(cfg.out_dir or os.path.join("runs", f"{cfg.env_id}-{cfg.algo}-s{cfg.seed}"))

    @classmethod
    def owned(cls, cfg: MarlConfig) -> OutputFolder:
        """The folder as :class:`agents.run_folder.RunFolder` sees it (what the run writes, its record)."""
        return OutputFolder(cls.folder(cfg), "safe-mapf train-marl", MARL_OUTPUTS, "config.json",
                            settings_key="config")

    @classmethod
    def check(cls, cfg: MarlConfig) -> Dict[str, Any]:
        """The resume point's description with ``cfg.resume`` (``{}`` without); ``ValueError`` if there is
        none to resume, if the folder holds a run with other settings, or if it holds files and neither
        ``resume`` nor ``overwrite`` is set. Writes nothing."""
        out = cls.folder(cfg)
        cls.owned(cfg).check(asdict(cfg), resume=cfg.resume, overwrite=cfg.overwrite,
                             may_differ=RESUMABLE_SETTINGS, describe=_flag)
        if not cfg.resume:
            return {}
        meta = out / "checkpoint.json"
        if not meta.exists():
            raise ValueError(f"--resume: {out} has no resume point (checkpoint.json); start without --resume")
        state = read_json(meta, what="resume point")
        if not isinstance(state, dict):
            raise ValueError(f"--resume: {meta} is not a resume point's description (not a JSON object)")
        if state.get("algo") != cfg.algo or state.get("env_id") != cfg.env_id:
            raise ValueError(f"--resume: {meta} describes a {state.get('algo')} run on {state.get('env_id')}, "
                             f"not {cfg.algo} on {cfg.env_id}")
        return state

    @property
    def checkpoint(self) -> Path:
        return self.out / f"checkpoint{self.suffix}"

    def open_bar(self) -> None:
        if self.cfg.progress_bar:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=self.cfg.timesteps, initial=self.start_steps, unit="step", mininterval=1.0,
                            desc=f"{self.cfg.algo} {self.cfg.env_id}")

    def advance(self, steps: int) -> None:
        if self.bar is not None:
            self.bar.update(steps)

    def wall(self) -> float:
        return self.wall_before + time.perf_counter() - self.t0

    def evaluate(self, act: Act, steps: int, extra: Optional[Dict[str, float]] = None) -> Dict[str, float]:
        """Run the held-out evaluation, log it (file, TensorBoard) and return it."""
        cfg = self.cfg
        ev = evaluate_policy(act, cfg.env_id, cfg.n_agents, cfg.max_cycles, cfg.eval_episodes, cfg.eval_seed,
                             **cfg.env_kwargs(training=False))
        line = {"timesteps": steps, "wall_s": round(self.wall(), 1), **ev, **(extra or {})}
        with open(self.out / "evaluations.jsonl", "a") as f:
            f.write(json.dumps(line) + "\n")
            f.flush()
        for k, v in line.items():
            self.logger.record(f"eval/{k}", v)
        self.logger.dump(steps)
        self.last_eval = ev
        return ev

    def meta(self, steps: int, obs_dim: int, extra: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        cfg = self.cfg
        return {"algo": cfg.algo, "env_id": cfg.env_id, "n_agents": cfg.n_agents, "obs_dim": int(obs_dim),
                "timesteps": int(steps), "wall_s": round(self.wall(), 1), "config": asdict(cfg),
                "command": self.command, **(extra or {})}

    def save_file(self, save: Callable[[str], Any], path: Path) -> None:
        """Write a policy file with ``save(path)``, whole or not at all (a temporary file, then a rename)."""
        with atomic_output(path) as tmp:
            save(str(tmp))

    def save_checkpoint(self, save: Callable[[str], Any], steps: int, obs_dim: int,
                        extra: Optional[Dict[str, Any]] = None) -> None:
        """A resume point: the checkpoint file (:meth:`save_file`), then its description."""
        self.save_file(save, self.checkpoint)
        self.save_meta("checkpoint", self.meta(steps, obs_dim, extra))

    def save_meta(self, name: str, meta: Dict[str, Any]) -> None:
        write_json_atomic(self.out / f"{name}.json", meta, indent=1)

    def finish(self, steps: int, obs_dim: int, extra: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        """Close the bar and the logger, write ``model.json`` and ``summary.json``; returns the summary."""
        if self.bar is not None:
            self.bar.close()
        self.logger.close()
        meta = self.meta(steps, obs_dim, extra)
        self.save_meta("model", meta)
        summary = {**{k: meta[k] for k in ("algo", "env_id", "n_agents", "timesteps", "wall_s", "command")},
                   "cpu_s": round(time.process_time() - self.cpu0, 1), "model": str(self.out / f"model{self.suffix}"),
                   "final_evaluation": self.last_eval, **(extra or {})}
        write_json_atomic(self.out / "summary.json", summary, indent=1)
        return summary


def _versions() -> Dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("torch", "stable-baselines3", "supersuit", "pettingzoo", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


def print_line(summary: Dict[str, Any]) -> str:
    """One line that reports a finished run."""
    ev = summary.get("final_evaluation", {})
    lam = f" lambda={summary['lagrange_multiplier']:.3f}" if "lagrange_multiplier" in summary else ""
    return (f"{summary['env_id']} {summary['algo']}: {summary['timesteps']} agent steps in {summary['wall_s']} s; "
            f"success={ev.get('success_rate', float('nan')):.3f} arrival={ev.get('arrival_rate', float('nan')):.3f} "
            f"cost={ev.get('mean_cost', float('nan')):.2f}{lam}; saved {summary['model']}")

