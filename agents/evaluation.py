"""Measuring a goal-conditioned agent: success, episode cost and the quality of its distances.

Ground truth (positions, geodesic distances) is used here, and only here, to *score* an
agent; the agent itself is given observations only.

- :func:`sample_problems`: start-goal pairs with a ground-truth geodesic distance in a band;
- :func:`run_episodes`: roll the deterministic policy out on given problems, all episodes
  in lockstep (one batched policy call per step);
- :func:`distance_rank_correlation`: Spearman rank correlation between predicted distances
  and geodesic distances;
- :func:`evaluate_agent`: all of it on held-out problems from a fixed seed;
- :class:`PeriodicEvaluation`: a callback that runs :func:`evaluate_agent` during training,
  logs the figures and saves checkpoints.
"""
from __future__ import annotations

import json
import os
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import gymnasium as gym
import numpy as np
from scipy.stats import spearmanr
from stable_baselines3.common.callbacks import BaseCallback

from .self_sampling import observations_at


def _make_env(env: gym.Env | str) -> gym.Env:
    if isinstance(env, str):
        import safe_mapf_envs  # noqa: F401

        return gym.make(env)
    return env


def _lockstep_envs(base: gym.Env, n: int) -> List[gym.Env]:
    """``base``'s unwrapped env and ``n - 1`` more made like it (no time limit: the caller counts steps)."""
    spec = base.spec
    envs: List[gym.Env] = [base.unwrapped]
    kwargs = dict(spec.kwargs) if spec is not None else {}
    entry = type(base.unwrapped)
    while len(envs) < n:
        envs.append(entry(**kwargs))
    return envs


def sample_problems(
    env: gym.Env | str,
    n: int,
    rng: np.random.Generator,
    max_distance: float,
    min_distance: float = 0.0,
    candidates: int = 64,
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` random start-goal pairs whose geodesic distance lies in ``[min_distance, max_distance]``.

    Returns ``(starts, goals, geodesic)`` in world units, shapes ``(n, 2)``, ``(n, 2)``, ``(n,)``.
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not (0 <= min_distance <= max_distance):
        raise ValueError(f"need 0 <= min_distance <= max_distance, got {min_distance}, {max_distance}")
    u: Any = _make_env(env).unwrapped  # the project's env: sample_states, geodesic_distance
    starts, goals, dists = [], [], []
    for _ in range(200 * n):
        s = u.sample_states(1, rng)[0]
        cand = u.sample_states(candidates, rng)
        d = np.asarray(u.geodesic_distance(s, cand))
        ok = np.flatnonzero((d >= min_distance) & (d <= max_distance))
        if len(ok):
            k = ok[rng.integers(len(ok))]
            starts.append(s)
            goals.append(cand[k])
            dists.append(d[k])
            if len(starts) == n:
                return np.array(starts), np.array(goals), np.array(dists)
    raise ValueError(f"could not find {n} pairs with geodesic distance in [{min_distance}, {max_distance}]")


def run_episodes(
    model: Any,
    env: gym.Env | str,
    starts: np.ndarray,
    goals: np.ndarray,
    max_steps: Optional[int] = None,
    deterministic: bool = True,
    batch: int = 100,
) -> Dict[str, np.ndarray]:
    """Run the policy from each ``starts[i]`` to ``goals[i]`` (world units).

    Episodes run in lockstep batches of ``batch`` environments so that each step is one
    batched ``model.predict`` call. ``max_steps`` defaults to the environment's time limit.

    Returns arrays ``success`` (bool), ``steps`` (int), ``cost`` (episode cost, float) and
    ``final_distance`` (straight-line distance to the goal at the end, world units).
    """
    base = _make_env(env)
    spec = base.spec
    if max_steps is None:
        max_steps = spec.max_episode_steps if spec is not None and spec.max_episode_steps else 20
    starts, goals = np.asarray(starts, float).reshape(-1, 2), np.asarray(goals, float).reshape(-1, 2)
    n = len(starts)
    envs = _lockstep_envs(base, min(batch, n))
    out = {"success": np.zeros(n, bool), "steps": np.zeros(n, int), "cost": np.zeros(n),
           "final_distance": np.zeros(n)}
    for b0 in range(0, n, len(envs)):
        idx = np.arange(b0, min(n, b0 + len(envs)))
        obs = [envs[k].reset(options={"start": starts[i], "goal": goals[i]})[0] for k, i in enumerate(idx)]
        active = np.ones(len(idx), bool)
        for t in range(max_steps):
            live = np.flatnonzero(active)
            if not len(live):
                break
            batch_obs = {key: np.stack([obs[k][key] for k in live]) for key in obs[0]}
            actions, _ = model.predict(batch_obs, deterministic=deterministic)
            for a, k in zip(actions, live):
                o, _, term, trunc, info = envs[k].step(a)
                obs[k] = o
                i = idx[k]
                out["cost"][i] += info["cost"]
                out["steps"][i] = t + 1
                out["final_distance"][i] = info["distance_to_goal"]
                if term:
                    out["success"][i] = True
                    active[k] = False
    return out


ADVANCE_RULES = ("critic", "reach")


def _leg_goal(obs: Dict[str, np.ndarray], waypoints: Optional[np.ndarray], leg: int, n_points: int) -> np.ndarray:
    """The goal observation of a route's ``leg``-th point: a waypoint's, or the env's own goal for the last."""
    if leg == n_points - 1 or waypoints is None:
        return obs["desired_goal"]
    return waypoints[leg - 1]


def run_routes(
    model: Any,
    env: gym.Env | str,
    routes: Sequence[np.ndarray],
    advance: str = "critic",
    advance_distance: float = 2.0,
    max_steps: int = 300,
    batch: int = 50,
) -> Dict[str, np.ndarray]:
    """Drive the policy along each route open loop: from ``routes[i][0]`` through its waypoints to ``routes[i][-1]``.

    ``routes[i]`` is a ``(W, 2)`` array of positions (world units): the start, the waypoints and the
    goal. The policy is given the observation at its current waypoint as its goal and moves on to the
    next one once ``advance`` says so, at most one waypoint per step:

    - ``"critic"``: once the model's own predicted distance to the waypoint is below
      ``advance_distance`` (the rule of the published code of the paper: no localisation, no
      rescue);
    - ``"reach"``: once the agent is truly within the env's ``goal_threshold`` of it (ground truth: an
      agent whose every waypoint is checked for it, which isolates its driving from its critic).

    A route succeeds when the agent reaches its goal (the env's termination) within ``max_steps``.
    Episodes run in lockstep batches of ``batch`` envs (one batched policy call per step).

    Returns arrays ``success`` (bool), ``steps``, ``cost``, ``hops`` (legs of the route, ``W - 1``),
    ``advanced`` (waypoints moved past before the end), ``pass_distance`` (the agent's mean distance
    from a waypoint when it moved past it, world units; NaN where it passed none) and ``stuck_at``
    (index of the leg a failed route ended on, ``-1`` for a success).
    """
    if advance not in ADVANCE_RULES:
        raise ValueError(f"advance must be one of {', '.join(ADVANCE_RULES)}, got {advance!r}")
    if max_steps < 1 or batch < 1:
        raise ValueError(f"max_steps and batch must be >= 1, got {max_steps}, {batch}")
    paths = [np.asarray(r, float).reshape(-1, 2) for r in routes]
    for i, r in enumerate(paths):
        if len(r) < 2 or not np.isfinite(r).all():
            raise ValueError(f"route {i} needs a start and a goal of finite positions, got {r.tolist()}")
    base = _make_env(env)
    n = len(paths)
    out = {"success": np.zeros(n, bool), "steps": np.zeros(n, int), "cost": np.zeros(n),
           "hops": np.array([len(r) - 1 for r in paths]), "advanced": np.zeros(n, int),
           "pass_distance": np.full(n, np.nan), "stuck_at": -np.ones(n, int)}
    if not n:
        return out
    envs = _lockstep_envs(base, min(batch, n))
    u: Any = envs[0]
    threshold = float(u.goal_threshold)
    # the observation at every waypoint (the goal's comes from the env itself)
    wp_obs = [observations_at(base, r[1:-1]) if len(r) > 2 else None for r in paths]
    for b0 in range(0, n, len(envs)):
        idx = np.arange(b0, min(n, b0 + len(envs)))
        obs = [envs[k].reset(options={"start": paths[i][0], "goal": paths[i][-1]})[0] for k, i in enumerate(idx)]
        leg = np.ones(len(idx), int)  # index of the route point each agent drives to, 1..W-1
        pos = np.stack([paths[i][0] for i in idx])
        active = np.ones(len(idx), bool)
        for t in range(max_steps):
            live = np.flatnonzero(active)
            if not len(live):
                break
            ahead = [k for k in live if leg[k] < len(paths[idx[k]]) - 1]
            if ahead:
                if advance == "critic":
                    o = np.stack([obs[k]["observation"] for k in ahead])
                    g = np.stack([_leg_goal(obs[k], wp_obs[idx[k]], leg[k], len(paths[idx[k]])) for k in ahead])
                    near = np.asarray(model.distance(o, g, aggregate="max")) < advance_distance
                else:
                    near = np.array([np.linalg.norm(pos[k] - paths[idx[k]][leg[k]]) <= threshold for k in ahead])
                for k in np.asarray(ahead)[near]:
                    i = idx[k]
                    passed = float(np.linalg.norm(pos[k] - paths[i][leg[k]]))
                    done = out["advanced"][i]
                    out["pass_distance"][i] = (passed if done == 0 else
                                               (out["pass_distance"][i] * done + passed) / (done + 1))
                    out["advanced"][i] += 1
                    leg[k] += 1
            batch_obs = {key: np.stack([obs[k][key] for k in live]) for key in obs[0]}
            batch_obs["desired_goal"] = np.stack([_leg_goal(obs[k], wp_obs[idx[k]], leg[k], len(paths[idx[k]]))
                                                  for k in live])
            actions, _ = model.predict(batch_obs, deterministic=True)
            for a, k in zip(actions, live):
                o_k, _, term, _, info = envs[k].step(a)
                obs[k] = o_k
                pos[k] = info["position"]
                i = idx[k]
                out["cost"][i] += info["cost"]
                out["steps"][i] = t + 1
                if term:
                    out["success"][i] = True
                    active[k] = False
        for k in np.flatnonzero(active):
            out["stuck_at"][idx[k]] = leg[k] - 1
    return out


def distance_rank_correlation(
    model: Any,
    env: gym.Env | str,
    starts: np.ndarray,
    goals: np.ndarray,
    geodesic: np.ndarray,
    aggregate: str = "max",
) -> Dict[str, float]:
    """Spearman (and Pearson) correlation of predicted distances with geodesic distances."""
    e = _make_env(env)
    pred = np.asarray(model.distance(observations_at(e, starts), observations_at(e, goals), aggregate=aggregate))
    rho = spearmanr(pred, geodesic).statistic
    pearson = float(np.corrcoef(pred, geodesic)[0, 1])
    return {"spearman": float(rho), "pearson": pearson, "n_pairs": int(len(pred))}


def evaluate_agent(
    model: Any,
    env: gym.Env | str,
    n_problems: int = 200,
    max_distance: float = 10.0,
    n_pairs: int = 500,
    pair_max_distance: float = 15.0,
    seed: int = 12345,
    aggregate: str = "max",
) -> Dict[str, float]:
    """Success, episode cost and distance quality on held-out problems drawn with ``seed``.

    Policy: ``n_problems`` pairs with geodesic distance at most ``max_distance``. Distances:
    ``n_pairs`` pairs with geodesic distance at most ``pair_max_distance``.
    """
    e = _make_env(env)
    rng = np.random.default_rng(seed)
    s, g, _ = sample_problems(e, n_problems, rng, max_distance)
    ep = run_episodes(model, e, s, g)
    ps, pg, pd = sample_problems(e, n_pairs, rng, pair_max_distance)
    corr = distance_rank_correlation(model, e, ps, pg, pd, aggregate)
    return {
        "success_rate": float(ep["success"].mean()),
        "mean_cost": float(ep["cost"].mean()),
        "mean_steps": float(ep["steps"].mean()),
        "distance_spearman": corr["spearman"],
        "distance_pearson": corr["pearson"],
    }


class PeriodicEvaluation(BaseCallback):
    """Evaluate every ``eval_freq`` environment steps; log ``eval/*``, keep a history, save checkpoints.

    Args:
        env_id: the environment to evaluate on (a fresh instance, independent of training).
        eval_freq: environment steps between evaluations.
        save_path: if given, the model is saved there (``.zip``) after each evaluation.
        log_path: if given, one JSON line per evaluation is appended there.
        eval_kwargs: keyword arguments of :func:`evaluate_agent`.
        wall_offset, cpu_offset: seconds the run took before this callback started (a resumed
            run's earlier parts), added to the logged ``wall_s`` and ``cpu_s``.
    """

    def __init__(self, env_id: str, eval_freq: int = 10_000, save_path: Optional[str] = None,
                 log_path: Optional[str] = None, eval_kwargs: Optional[Dict[str, Any]] = None,
                 verbose: int = 1, wall_offset: float = 0.0, cpu_offset: float = 0.0) -> None:
        super().__init__(verbose)
        if eval_freq < 1:
            raise ValueError(f"eval_freq must be >= 1, got {eval_freq}")
        self.env_id = env_id
        self.eval_freq = int(eval_freq)
        self.save_path = save_path
        self.log_path = log_path
        self.eval_kwargs = dict(eval_kwargs or {})
        self.history: List[Dict[str, float]] = []
        self._env: Optional[gym.Env] = None
        self._last = 0
        self._t0 = time.time() - float(wall_offset)
        self._cpu0 = time.process_time() - float(cpu_offset)

    def _on_training_start(self) -> None:
        self._env = _make_env(self.env_id)
        # on the run's own grid of eval_freq steps, also when it resumes between two evaluations
        self._last = self.num_timesteps - self.num_timesteps % self.eval_freq

    def _on_step(self) -> bool:
        if self.num_timesteps - self._last >= self.eval_freq:
            self._last = self.num_timesteps
            self.evaluate()
        return True

    def evaluate(self) -> Dict[str, float]:
        """Run one evaluation now; return (and log) its figures."""
        metrics = evaluate_agent(self.model, self._env if self._env is not None else self.env_id, **self.eval_kwargs)
        metrics.update(timesteps=int(self.num_timesteps), wall_s=round(time.time() - self._t0, 1),
                       cpu_s=round(time.process_time() - self._cpu0, 1),
                       lagrange_multiplier=float(getattr(self.model, "lagrange_multiplier", 0.0)))
        self.history.append(metrics)
        for k in ("success_rate", "mean_cost", "mean_steps", "distance_spearman"):
            self.logger.record(f"eval/{k}", metrics[k])
        if self.verbose:
            print(f"[eval] steps={metrics['timesteps']} success={metrics['success_rate']:.3f} "
                  f"cost={metrics['mean_cost']:.2f} spearman={metrics['distance_spearman']:.3f} "
                  f"lambda={metrics['lagrange_multiplier']:.3f} wall={metrics['wall_s']}s cpu={metrics['cpu_s']}s",
                  flush=True)
        if self.log_path:
            os.makedirs(os.path.dirname(os.path.abspath(self.log_path)), exist_ok=True)
            with open(self.log_path, "a") as f:
                f.write(json.dumps(metrics) + "\n")
        if self.save_path:
            from .run_folder import atomic_output

            with atomic_output(self.save_path) as tmp:  # whole or not at all
                self.model.save(tmp)
        return metrics


__all__ = [
    "ADVANCE_RULES",
    "PeriodicEvaluation",
    "distance_rank_correlation",
    "evaluate_agent",
    "run_episodes",
    "run_routes",
    "sample_problems",
]
