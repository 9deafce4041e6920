"""Choosing the training problems: the paper's self-sampling (Algorithm 1) and two references.

What a goal-conditioned agent practises decides what it learns. Search on the Replay Buffer
picks goals at a desired *ground-truth* distance from the start, which needs an oracle that
real observations (images) do not offer. The paper "Safe Multi-Agent Navigation guided by
Goal-Conditioned Safe Reinforcement Learning" instead lets the agent's own critics choose
(Algorithm 1): draw ``N`` random start-goal pairs from the environment, predict their distance
(and cost), keep the ``K`` pairs closest to a desired target ``tau`` as training problems, and
draw ``N`` new candidates once the ``K`` are used up. As the critics improve, so do the problems.

Samplers (all give :class:`ProblemResetWrapper` the ``options`` of the next ``reset``):

- :class:`SelfSampler`: Algorithm 1 (observations only: the critics score observations);
- :class:`OracleSampler`: goals in a ground-truth geodesic band (SoRB's sampler, for comparison);
- :class:`UniformSampler`: the environment's own start and goal sampling.

How a sampler reaches the episodes: the training environment carries a
:class:`ProblemResetWrapper` (``SafeGoalTD3`` adds one to a plain ``gym.Env``), and
:func:`install_sampler` connects the sampler to it. ``SafeGoalTD3.learn`` installs the model's
own ``problem_sampler`` before its first reset; :class:`ProblemSamplingCallback` does the same
for a sampler passed to ``learn(callback=...)``, as Stable-Baselines3's ``EvalCallback`` brings
evaluation to any algorithm. This module does not import the algorithm: a sampler scores
candidates with any model whose ``policy.values`` follows :class:`~agents.policies.SafeGoalPolicy`.

Environment requirements of :class:`SelfSampler`: ``sample_states(n, rng)`` returning ``n``
random free states, ``reset(options={"start": s, "goal": g})``, and ``observations_at(states)``,
the observations of states (vectors or panoramas), as the package's envs provide.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence, Tuple, Union, cast

import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

Band = Union[float, Tuple[float, float]]


def observations_at(env: gym.Env, states: np.ndarray) -> np.ndarray:
    """The observations an agent would receive at ``states``: ``env.unwrapped.observations_at(states)``."""
    fn = getattr(env.unwrapped, "observations_at", None)
    if fn is None:
        raise ValueError(f"{type(env.unwrapped).__name__} has no observations_at(states) method: self-sampling and "
                         "the planners need the observation of a sampled state (the package's envs have one)")
    return np.asarray(fn(states))


def _check_band(band: Band, name: str) -> Tuple[float, float]:
    if np.isscalar(band):
        lo = hi = float(cast(float, band))
    else:
        pair = cast(Sequence[float], band)
        lo, hi = float(pair[0]), float(pair[1])
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0 or hi < lo:
        raise ValueError(f"{name} must be a number >= 0 or a band (lo, hi) with 0 <= lo <= hi, got {band!r}")
    return lo, hi


class ProblemSampler:
    """Chooses the start and goal of each training episode (base class)."""

    #: name used in configs and logs
    name = "base"

    def bind(self, model: Optional[BaseAlgorithm]) -> None:
        """Give the sampler the model whose critics it may use (``None`` to unbind)."""

    def reset_options(self, env: gym.Env) -> Optional[Dict[str, Any]]:
        """Options for the next ``env.reset``; ``None`` lets the environment sample."""
        raise NotImplementedError

    @property
    def stats(self) -> Dict[str, float]:
        """Numbers worth logging (empty by default)."""
        return {}


class UniformSampler(ProblemSampler):
    """Uniform start and goal in the free space.

    The environments of this project sample default goals within reach of their time limit;
    this sampler asks them for goals anywhere (``goal_distance="uniform"``), as it always
    has. Other environments sample as they do by default.
    """

    name = "uniform"

    def reset_options(self, env: gym.Env) -> Optional[Dict[str, Any]]:
        from safe_mapf_envs import NavigationEnvBase  # here: importing the algorithm registers no env

        if isinstance(getattr(env, "unwrapped", None), NavigationEnvBase):
            return {"goal_distance": "uniform"}
        return None


class OracleSampler(ProblemSampler):
    """Goals at a ground-truth geodesic distance in ``band`` (SoRB's oracle sampler).

    Needs an environment that accepts ``reset(options={"goal_distance": (lo, hi)})``.
    """

    name = "oracle"

    def __init__(self, band: Band = (2.0, 15.0)) -> None:
        self.band = _check_band(band, "band")

    def reset_options(self, env: gym.Env) -> Optional[Dict[str, Any]]:
        return {"goal_distance": self.band}


class SelfSampler(ProblemSampler):
    """Algorithm 1: the critics pick training problems at a desired predicted distance (and cost).

    Args:
        n_candidates: ``N``, random start-goal pairs drawn per refill.
        n_keep: ``K``, problems kept per refill (one per episode).
        target_distance: ``tau`` in steps: a number, or a band ``(lo, hi)`` from which each
            candidate draws its own target uniformly (a diverse set of distances).
        target_cost: optional target for the predicted cumulative cost (number or band); when
            given, the squared cost error is added to the score of a ``cost_fraction`` share
            of the kept problems (the rest are chosen by distance alone, so the agent keeps
            practising ordinary problems too).
        cost_fraction: share of the ``K`` problems chosen with the cost target.
        disagreement_weight: subtracted times the ensemble's standard deviation of the
            predicted distance, favouring pairs the critics disagree on (0 disables it).
        aggregate: how the ensemble's distances combine before scoring (``"mean"``, ``"max"``...).
        seed: seed of the sampler's generator (default: the model's seed).
        narrow_fraction: share of the ``K`` kept problems that go through a narrow passage
            (a doorway, a corridor, a gap between furniture; the env's
            ``sample_narrow_crossings``), start and goal ``narrow_reach`` steps on either side.
            They are not scored: a critic that has never been through a passage reads its far
            side as unreachable, so choosing by predicted distance would never pick them, and
            uniformly drawn problems seldom cross a passage a little wider than an agent
            (0: the paper's sampler).
        narrow_reach: band of distances (in steps of the agent at full speed) of start and goal
            from the passage.
    """

    name = "self"

    def __init__(
        self,
        n_candidates: int = 1000,
        n_keep: int = 100,
        target_distance: Band = (2.0, 15.0),
        target_cost: Optional[Band] = None,
        cost_fraction: float = 0.5,
        disagreement_weight: float = 0.0,
        aggregate: str = "mean",
        seed: Optional[int] = None,
        narrow_fraction: float = 0.0,
        narrow_reach: Band = (2.0, 6.0),
    ) -> None:
        if not 0.0 <= narrow_fraction <= 1.0:
            raise ValueError(f"narrow_fraction must be in [0, 1], got {narrow_fraction!r}")
        if int(n_candidates) < 1 or int(n_keep) < 1 or int(n_keep) > int(n_candidates):
            raise ValueError(f"need 1 <= n_keep <= n_candidates, got n_keep={n_keep}, n_candidates={n_candidates}")
        if not 0.0 <= cost_fraction <= 1.0:
            raise ValueError(f"cost_fraction must be in [0, 1], got {cost_fraction!r}")
        if not np.isfinite(disagreement_weight) or disagreement_weight < 0:
            raise ValueError(f"disagreement_weight must be >= 0, got {disagreement_weight!r}")
        self.n_candidates = int(n_candidates)
        self.n_keep = int(n_keep)
        self.target_distance = _check_band(target_distance, "target_distance")
        self.target_cost = None if target_cost is None else _check_band(target_cost, "target_cost")
        self.cost_fraction = float(cost_fraction)
        self.disagreement_weight = float(disagreement_weight)
        self.narrow_fraction = float(narrow_fraction)
        self.narrow_reach = _check_band(narrow_reach, "narrow_reach")
        self.aggregate = aggregate
        self.rng = np.random.default_rng(seed)
        self._seeded = seed is not None
        self.model: Optional[BaseAlgorithm] = None
        self._pool: List[Tuple[np.ndarray, np.ndarray]] = []
        self.n_refills = 0
        self.last_distance: Optional[np.ndarray] = None
        self.last_cost: Optional[np.ndarray] = None
        self._stats: Dict[str, float] = {}

    def bind(self, model: Optional[BaseAlgorithm]) -> None:
        self.model = model
        if model is not None and not self._seeded and model.seed is not None:
            self.rng = np.random.default_rng([int(model.seed), 1])
            self._seeded = True

    def _targets(self, band: Tuple[float, float], n: int) -> np.ndarray:
        lo, hi = band
        return np.full(n, lo) if lo == hi else self.rng.uniform(lo, hi, size=n)

    def score(self, obs: np.ndarray, goals: np.ndarray) -> Tuple[np.ndarray, Optional[np.ndarray]]:
        """Scores of the candidate pairs (lower is better): by distance, and with the cost target.

        The first is the squared error of the predicted distance to its target (minus the
        disagreement bonus); the second adds the squared error of the predicted cost to its
        target (``None`` without a cost target). Predictions are kept in ``last_distance`` and
        ``last_cost`` for logging.
        """
        if self.model is None:
            self.last_distance = self.last_cost = None
            return self.rng.random(len(obs)), None  # no critic yet: random problems
        policy: Any = self.model.policy  # a SafeGoalPolicy: values() of the distance and cost critics
        vals = policy.values(obs, goals, quantities=("distance", "cost"), aggregate="none")
        d = np.asarray(vals["distance"])
        c = _combine(np.asarray(vals["cost"]), self.aggregate)
        pred = _combine(d, self.aggregate)
        self.last_distance, self.last_cost = pred, c
        loss = (pred - self._targets(self.target_distance, len(pred))) ** 2
        if self.disagreement_weight > 0:
            loss = loss - self.disagreement_weight * d.std(0)
        if self.target_cost is None:
            return loss, None
        return loss, loss + (c - self._targets(self.target_cost, len(c))) ** 2

    def refill(self, env: gym.Env) -> None:
        """Draw ``N`` candidate pairs, keep the best ``K`` as the next training problems."""
        u: Any = env.unwrapped  # the project's env: sample_states
        n_narrow = int(round(self.narrow_fraction * self.n_keep))
        n_scored = self.n_keep - n_narrow
        chosen = np.empty(0, int)
        pool: List[Tuple[np.ndarray, np.ndarray]] = []
        if n_scored:  # the paper's self-sampling: the candidates the critics score best
            starts = np.asarray(u.sample_states(self.n_candidates, self.rng))
            goals = np.asarray(u.sample_states(self.n_candidates, self.rng))
            by_distance, by_cost = self.score(observations_at(env, starts), observations_at(env, goals))
            n_cost = 0 if by_cost is None else int(round(self.cost_fraction * n_scored))
            if n_cost:
                chosen = np.argpartition(cast(np.ndarray, by_cost), n_cost - 1)[:n_cost]
            rest = by_distance.copy()
            rest[chosen] = np.inf
            n_rest = n_scored - n_cost
            if n_rest:
                chosen = np.concatenate([chosen, np.argpartition(rest, n_rest - 1)[:n_rest]])
            pool = [(starts[i], goals[i]) for i in chosen]
        if n_narrow:
            step = float(getattr(u, "action_scale", 1.0))
            lo, hi = self.narrow_reach
            a, b = u.sample_narrow_crossings(n_narrow, (lo * step, hi * step), self.rng)
            pool += list(zip(a, b))
        keep = self.rng.permutation(len(pool))
        self._pool = [pool[i] for i in keep]
        self.n_refills += 1
        if self.last_distance is not None and self.last_cost is not None and len(chosen):
            self._stats = {"sampler/pred_distance": float(self.last_distance[chosen].mean()),
                           "sampler/pred_cost": float(self.last_cost[chosen].mean())}

    def reset_options(self, env: gym.Env) -> Optional[Dict[str, Any]]:
        if not self._pool:
            self.refill(env)
        start, goal = self._pool.pop()
        return {"start": start, "goal": goal}

    @property
    def stats(self) -> Dict[str, float]:
        return dict(self._stats, **{"sampler/refills": float(self.n_refills)})

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["model"] = None  # never pickle the model through its sampler
        return state


def _combine(values: np.ndarray, aggregate: str) -> np.ndarray:
    if aggregate == "mean":
        return values.mean(0)
    if aggregate == "max":
        return values.max(0)
    if aggregate == "min":
        return values.min(0)
    raise ValueError(f"aggregate must be 'mean', 'max' or 'min', got {aggregate!r}")


class ProblemResetWrapper(gym.Wrapper):
    """Asks a :class:`ProblemSampler` for the ``options`` of every ``reset`` without options.

    A ``reset`` called with explicit ``options`` passes them through unchanged; without a
    sampler the wrapper does nothing.
    """

    def __init__(self, env: gym.Env, sampler: Optional[ProblemSampler] = None) -> None:
        super().__init__(env)
        self.sampler = sampler

    def reset(self, *, seed: Optional[int] = None, options: Optional[Dict[str, Any]] = None):
        if options is None and self.sampler is not None:
            options = self.sampler.reset_options(self.env)
        return self.env.reset(seed=seed, options=options)


SAMPLERS = {"self": SelfSampler, "oracle": OracleSampler, "uniform": UniformSampler}


def make_sampler(spec: Union[str, ProblemSampler, None], **kwargs: Any) -> ProblemSampler:
    """A sampler from its name (``"self"``, ``"oracle"``, ``"uniform"``) and keyword arguments."""
    if isinstance(spec, ProblemSampler):
        if kwargs:
            raise ValueError("sampler keyword arguments are only accepted with a sampler name")
        return spec
    if spec is None:
        spec = "uniform"
    if spec not in SAMPLERS:
        raise ValueError(f"problem sampler must be one of {sorted(SAMPLERS)} or a ProblemSampler, got {spec!r}")
    return SAMPLERS[spec](**kwargs)


def find_wrappers(env: gym.Env) -> Sequence[ProblemResetWrapper]:
    """The :class:`ProblemResetWrapper` layers inside ``env``'s wrapper chain."""
    out = []
    while isinstance(env, gym.Wrapper):
        if isinstance(env, ProblemResetWrapper):
            out.append(env)
        env = env.env
    return out


def install_sampler(env: VecEnv, sampler: ProblemSampler, model: Optional[BaseAlgorithm] = None) -> None:
    """Make ``sampler`` choose the problems of ``env``'s next resets, scoring with ``model``'s critics.

    ``env`` is the model's vectorised training environment; each of its environments must
    carry a :class:`ProblemResetWrapper`. A sampler other than :class:`UniformSampler` runs in
    this process, so ``env`` must be a ``DummyVecEnv``; the uniform sampler needs nothing
    (it leaves the choice to the environment). ``ValueError`` names what is missing.
    """
    if not isinstance(env, DummyVecEnv):
        if isinstance(sampler, UniformSampler):
            return
        raise ValueError(f"the {sampler.name!r} problem sampler needs a DummyVecEnv (it runs in this "
                         f"process), got {type(env).__name__}")
    wrappers = [w for e in env.envs for w in find_wrappers(e)]
    if not wrappers and not isinstance(sampler, UniformSampler):
        raise ValueError("the environment has no ProblemResetWrapper; wrap it with "
                         "agents.self_sampling.ProblemResetWrapper to use the "
                         f"{sampler.name!r} problem sampler")
    sampler.bind(model)
    for w in wrappers:
        w.sampler = sampler


class ProblemSamplingCallback(BaseCallback):
    """A Stable-Baselines3 callback that lets ``sampler`` choose the training problems.

    At the start of ``learn`` it connects ``sampler`` to the training environment's
    :class:`ProblemResetWrapper` layers (:func:`install_sampler`), bound to the learning model
    (a :class:`SelfSampler` scores candidates with its critics); the episode already under way
    keeps its problem, every later one is the sampler's. After each rollout it records the
    sampler's :attr:`~ProblemSampler.stats` in the model's logger. The sampler stays installed
    after ``learn`` returns.

    Example: ``model.learn(10_000, callback=ProblemSamplingCallback(SelfSampler(target_distance=8)))``.
    """

    def __init__(self, sampler: Union[str, ProblemSampler], verbose: int = 0, **sampler_kwargs: Any) -> None:
        super().__init__(verbose)
        self.sampler = make_sampler(sampler, **sampler_kwargs)

    def _init_callback(self) -> None:
        install_sampler(self.training_env, self.sampler, self.model)

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        for k, v in self.sampler.stats.items():
            self.logger.record(k, v)


__all__ = [
    "OracleSampler",
    "ProblemResetWrapper",
    "ProblemSampler",
    "ProblemSamplingCallback",
    "SAMPLERS",
    "SelfSampler",
    "UniformSampler",
    "find_wrappers",
    "install_sampler",
    "make_sampler",
    "observations_at",
]
