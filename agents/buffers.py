"""A goal-relabelling replay buffer that also stores the safety cost of every step.

Stable-Baselines3's ``HerReplayBuffer`` relabels goals but keeps the stored ``done`` flags, so
a relabelled transition that reaches its new goal is not marked terminal. The distance critic
of Search on the Replay Buffer depends on exactly that flag (a terminal step is "one step to
go"), so this buffer recomputes termination for every sampled transition with the
environment's vectorized ``compute_terminated(achieved_goal, desired_goal, info)``.

Goals of a sampled batch are, per transition:

- a **future** achieved goal of the same episode with probability ``her_ratio`` (the "future"
  strategy of Hindsight Experience Replay, including the step's own next state);
- the achieved goal of a **random** stored transition with probability ``random_goal_ratio``
  (far-away goals, so the critics also learn what is out of reach);
- the episode's own desired goal otherwise.

Costs come from ``info["cost"]`` and do not depend on the goal. Where ``info`` carries
``"position"`` and ``"goal"`` (ground truth, as the environments of this project report), they
are stored too and handed to ``compute_terminated`` as ``info={"position": ..., "goal": ...}``
arrays, which environments with image goals can use to decide termination.
"""
from __future__ import annotations

import os
from typing import Any, Callable, Dict, List, NamedTuple, Optional, cast

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.vec_env import VecEnv

TensorDict = Dict[str, th.Tensor]

#: The keys of a goal-conditioned observation (Gymnasium-Robotics convention).
GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")


class GoalCostSamples(NamedTuple):
    """A sampled batch; ``observations["desired_goal"]`` already holds the relabelled goals."""

    observations: TensorDict
    actions: th.Tensor
    next_observations: TensorDict
    dones: th.Tensor
    rewards: th.Tensor
    costs: th.Tensor
    discounts: Optional[th.Tensor] = None


def check_goal_space(observation_space: spaces.Space) -> spaces.Dict:
    """Raise ``ValueError`` unless ``observation_space`` is a goal-conditioned ``Dict`` space."""
    if not isinstance(observation_space, spaces.Dict):
        raise ValueError(f"a goal-conditioned Dict observation space is required, got {observation_space!r}")
    missing = [k for k in GOAL_KEYS if k not in observation_space.spaces]
    if missing:
        raise ValueError(f"the observation space lacks the goal-conditioned keys {missing}; it has "
                         f"{sorted(observation_space.spaces)}")
    if observation_space["achieved_goal"].shape != observation_space["desired_goal"].shape:
        raise ValueError("achieved_goal and desired_goal must have the same shape, got "
                         f"{observation_space['achieved_goal'].shape} and {observation_space['desired_goal'].shape}")
    return observation_space


class GoalCostReplayBuffer(DictReplayBuffer):
    """Replay buffer for goal-conditioned safe RL: stores costs, relabels goals and termination.

    Args:
        buffer_size: capacity in transitions (over all envs).
        observation_space: a goal-conditioned ``Dict`` space.
        action_space: the action space.
        device: torch device of the sampled tensors.
        n_envs: number of parallel environments.
        optimize_memory_usage: not supported (must be ``False``).
        env: the (vectorized) environment whose ``compute_terminated`` decides termination of
            relabelled goals. Optional when ``compute_terminated`` is given.
        compute_terminated: ``f(achieved_goal, desired_goal, info) -> bool array``; default:
            the env's method of that name.
        her_ratio: fraction of sampled transitions whose goal is a future achieved goal.
        random_goal_ratio: fraction whose goal is the achieved goal of a random transition.
        seed: seed of the buffer's own random generator.
        achieved_goal_is_observation: the environment's ``achieved_goal`` is always its
            ``observation`` (true of every environment of this project): store it once. For
            panoramas this saves a third of the buffer's memory.
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Dict,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        env: Optional[VecEnv] = None,
        compute_terminated: Optional[Callable[..., Any]] = None,
        her_ratio: float = 0.5,
        random_goal_ratio: float = 0.0,
        seed: Optional[int] = None,
        achieved_goal_is_observation: bool = False,
    ) -> None:
        check_goal_space(observation_space)
        if optimize_memory_usage:
            raise ValueError("GoalCostReplayBuffer does not support optimize_memory_usage=True")
        for name, v in (("her_ratio", her_ratio), ("random_goal_ratio", random_goal_ratio)):
            if not (0.0 <= v <= 1.0):
                raise ValueError(f"{name} must be in [0, 1], got {v!r}")
        if her_ratio + random_goal_ratio > 1.0:
            raise ValueError(f"her_ratio + random_goal_ratio must be <= 1, got {her_ratio} + {random_goal_ratio}")
        super().__init__(buffer_size, observation_space, action_space, device, n_envs=n_envs,
                         optimize_memory_usage=False, handle_timeout_termination=True)
        self.her_ratio = float(her_ratio)
        self.random_goal_ratio = float(random_goal_ratio)
        self.env = env
        self._compute_terminated = compute_terminated
        self.rng = np.random.default_rng(seed)
        self.costs = np.zeros((self.buffer_size, self.n_envs), dtype=np.float32)
        self.ep_start = np.zeros((self.buffer_size, self.n_envs), dtype=np.int64)
        self.ep_length = np.zeros((self.buffer_size, self.n_envs), dtype=np.int64)
        self._current_ep_start = np.zeros(self.n_envs, dtype=np.int64)
        self.positions: Optional[np.ndarray] = None
        self.goal_positions: Optional[np.ndarray] = None
        self.achieved_goal_is_observation = bool(achieved_goal_is_observation)
        if self.achieved_goal_is_observation:
            if observation_space["achieved_goal"] != observation_space["observation"]:
                raise ValueError("achieved_goal_is_observation=True needs equal achieved_goal and observation spaces")
            for store in (self.observations, self.next_observations):
                store["achieved_goal"] = store["observation"]  # one array; add() writes it twice

    # ------------------------------------------------------------------ bookkeeping
    def seed(self, seed: Optional[int]) -> None:
        """Reseed the buffer's random generator (goal and index sampling)."""
        self.rng = np.random.default_rng(seed)

    def set_env(self, env: Optional[VecEnv]) -> None:
        """Set the environment that decides termination of relabelled goals."""
        self.env = env

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["env"] = None  # environments are not pickled with the buffer
        return state

    def compute_terminated(self, achieved: np.ndarray, desired: np.ndarray, info: Dict[str, np.ndarray]) -> np.ndarray:
        """Vectorized termination of ``achieved`` vs ``desired`` goals (batch axis first)."""
        if self._compute_terminated is not None:
            out = self._compute_terminated(achieved, desired, info)
        elif self.env is not None:
            out = self.env.env_method("compute_terminated", achieved, desired, info, indices=[0])[0]
        else:
            raise ValueError("goal relabelling needs compute_terminated: pass env= or compute_terminated= "
                             "to GoalCostReplayBuffer (or call set_env)")
        return np.asarray(out, dtype=np.float32).reshape(len(achieved))

    def add(  # type: ignore[override]
        self,
        obs: Dict[str, np.ndarray],
        next_obs: Dict[str, np.ndarray],
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: List[Dict[str, Any]],
    ) -> None:
        """Store one step of every env; ``infos[i]["cost"]`` is the step's cost (0 if absent)."""
        pos = self.pos
        # Overwriting an old episode: forget all of it, so no relabelling reaches into new data.
        for e in np.flatnonzero(self.ep_length[pos] > 0):
            old = (self.ep_start[pos, e] + np.arange(self.ep_length[pos, e])) % self.buffer_size
            self.ep_length[old, e] = 0
        self.ep_start[pos] = self._current_ep_start
        self.ep_length[pos] = 0
        self.costs[pos] = [float(info.get("cost", 0.0)) for info in infos]
        if self.positions is None and all("position" in i and "goal" in i for i in infos):
            p = np.asarray(infos[0]["position"])
            self.positions = np.zeros((self.buffer_size, self.n_envs, *p.shape), dtype=np.float32)
            self.goal_positions = np.zeros_like(self.positions)
        if self.positions is not None:
            nan = np.full(self.positions.shape[2:], np.nan)
            goal_positions = cast(np.ndarray, self.goal_positions)  # set together with positions
            self.positions[pos] = [info.get("position", nan) for info in infos]
            goal_positions[pos] = [info.get("goal", nan) for info in infos]
        super().add(obs, next_obs, action, reward, done, infos)
        for e in np.flatnonzero(np.asarray(done).reshape(self.n_envs)):
            start = int(self._current_ep_start[e])
            end = self.pos if self.pos > start else self.pos + self.buffer_size
            idx = np.arange(start, end) % self.buffer_size
            self.ep_length[idx, e] = end - start
            self._current_ep_start[e] = self.pos

    # ------------------------------------------------------------------ save / load (resume)
    _STATE = ("actions", "rewards", "dones", "timeouts", "costs", "ep_start", "ep_length")

    def save_arrays(self, path: str) -> None:
        """Write the stored transitions (the filled part only) to an uncompressed ``.npz``.

        Used to resume a training run; :meth:`load_arrays` restores them into a buffer of the
        same spaces (and at least the same capacity).
        """
        n = self.buffer_size if self.full else self.pos
        arrays: Dict[str, Any] = {}
        for prefix, store in (("obs", self.observations), ("next_obs", self.next_observations)):
            for k, v in store.items():
                if not (k == "achieved_goal" and self.achieved_goal_is_observation):
                    arrays[f"{prefix}/{k}"] = v[:n]
        for k in self._STATE:
            arrays[k] = getattr(self, k)[:n]
        if self.positions is not None:
            arrays["positions"] = self.positions[:n]
            arrays["goal_positions"] = cast(np.ndarray, self.goal_positions)[:n]
        arrays["meta"] = np.array([self.pos, int(self.full), self.buffer_size, self.n_envs], dtype=np.int64)
        tmp = path + ".tmp.npz"
        np.savez(tmp, **arrays)
        os.replace(tmp, path)

    def load_arrays(self, path: str) -> None:
        """Restore transitions written by :meth:`save_arrays` (``ValueError`` naming ``path`` if the
        file is missing, truncated or corrupt, holds non-finite values, or does not fit). The file
        is read whole, without pickle, before anything is restored."""
        from .run_folder import read_npz

        data = read_npz(path, "replay-buffer file")
        try:
            pos, full, size, n_envs = (int(v) for v in data["meta"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path} is not a replay-buffer file: its 'meta' entry is missing or malformed") from exc
        for k, arr in data.items():
            if arr.dtype.kind == "f" and not np.isfinite(arr).all():
                raise ValueError(f"{path}: its array {k!r} holds non-finite values (NaN or infinity)")
        if size != self.buffer_size or n_envs != self.n_envs:
            raise ValueError(f"{path} holds a buffer of {size} x {n_envs} transitions, this one is "
                             f"{self.buffer_size} x {self.n_envs}")
        needed = [f"{prefix}/{k}" for prefix, store in (("obs", self.observations),
                                                        ("next_obs", self.next_observations))
                  for k in store if not (k == "achieved_goal" and self.achieved_goal_is_observation)]
        missing = [k for k in needed + list(self._STATE) if k not in data]
        if missing:
            raise ValueError(f"{path} is not a complete replay-buffer file: it lacks {missing}")
        n = size if full else pos
        for prefix, store in (("obs", self.observations), ("next_obs", self.next_observations)):
            for k, v in store.items():
                if k == "achieved_goal" and self.achieved_goal_is_observation:
                    continue
                src = data[f"{prefix}/{k}"]
                if src.shape[1:] != v.shape[1:]:
                    raise ValueError(f"{path}: {prefix}/{k} has shape {src.shape[1:]}, expected {v.shape[1:]}")
                v[:n] = src
        for k in self._STATE:
            getattr(self, k)[:n] = data[k]
        if "positions" in data:
            p = data["positions"]
            self.positions = np.zeros((self.buffer_size, self.n_envs, *p.shape[2:]), dtype=np.float32)
            self.goal_positions = np.zeros_like(self.positions)
            self.positions[:n], self.goal_positions[:n] = p, data["goal_positions"]
        self.pos, self.full = pos, bool(full)
        # The run resumes with fresh episodes: an episode unfinished at the save stays unsampleable.
        self._current_ep_start = np.full(self.n_envs, self.pos, dtype=np.int64)

    def n_complete_transitions(self) -> int:
        """Transitions of finished episodes (the ones that can be sampled)."""
        return int(np.count_nonzero(self.ep_length > 0))

    # ------------------------------------------------------------------ sampling
    def sample(self, batch_size: int, env=None) -> GoalCostSamples:  # type: ignore[override]
        """Sample ``batch_size`` transitions of finished episodes, with relabelled goals and dones."""
        valid = np.flatnonzero(self.ep_length.reshape(-1) > 0)
        if len(valid) == 0:
            raise ValueError("the replay buffer holds no finished episode yet; collect more steps before sampling")
        flat = valid[self.rng.integers(len(valid), size=batch_size)]
        t, e = np.divmod(flat, self.n_envs)
        return self._get_goal_samples(t, e)

    def _get_goal_samples(self, t: np.ndarray, e: np.ndarray) -> GoalCostSamples:
        b = len(t)
        obs = {k: v[t, e] for k, v in self.observations.items()}
        next_obs = {k: v[t, e] for k, v in self.next_observations.items()}
        goals = obs["desired_goal"].copy()
        goal_pos = None if self.goal_positions is None else self.goal_positions[t, e].copy()
        positions = cast(np.ndarray, self.positions)  # not None whenever goal_pos is not None

        u = self.rng.random(b)
        future = np.flatnonzero(u < self.her_ratio)
        rand = np.flatnonzero((u >= self.her_ratio) & (u < self.her_ratio + self.random_goal_ratio))
        relabelled = np.concatenate([future, rand])
        if len(future):
            start, length = self.ep_start[t[future], e[future]], self.ep_length[t[future], e[future]]
            offset = (t[future] - start) % self.buffer_size
            f_off = offset + (self.rng.random(len(future)) * (length - offset)).astype(np.int64)
            ft = (start + np.minimum(f_off, length - 1)) % self.buffer_size
            goals[future] = self.next_observations["achieved_goal"][ft, e[future]]
            if goal_pos is not None:
                goal_pos[future] = positions[ft, e[future]]
        if len(rand):
            valid = np.flatnonzero(self.ep_length.reshape(-1) > 0)
            rt, re = np.divmod(valid[self.rng.integers(len(valid), size=len(rand))], self.n_envs)
            goals[rand] = self.next_observations["achieved_goal"][rt, re]
            if goal_pos is not None:
                goal_pos[rand] = positions[rt, re]

        dones = self.dones[t, e] * (1.0 - self.timeouts[t, e])
        if len(relabelled):
            info = {} if goal_pos is None else {"position": positions[t[relabelled], e[relabelled]],
                                                "goal": goal_pos[relabelled]}
            dones = dones.copy()
            dones[relabelled] = self.compute_terminated(
                next_obs["achieved_goal"][relabelled], goals[relabelled], info)
        obs["desired_goal"] = goals
        next_obs["desired_goal"] = goals

        def to(a: np.ndarray) -> th.Tensor:  # the arrays are fresh copies: no second copy
            return self.to_torch(a, copy=False)
        return GoalCostSamples(
            observations={k: to(v) for k, v in obs.items()},
            actions=to(self.actions[t, e]),
            next_observations={k: to(v) for k, v in next_obs.items()},
            dones=to(dones.astype(np.float32)),
            rewards=to(self.rewards[t, e]),
            costs=to(self.costs[t, e]),
        )


__all__ = ["GOAL_KEYS", "GoalCostReplayBuffer", "GoalCostSamples", "check_goal_space"]
