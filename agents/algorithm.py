"""``SafeGoalTD3``: goal-conditioned safe actor-critic on Stable-Baselines3.

The learning half of the paper "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe
Reinforcement Learning", built on Search on the Replay Buffer (SoRB):

- a deterministic goal-conditioned actor trained TD3-style (target policy smoothing, delayed
  Polyak-averaged targets);
- an ensemble of **distributional distance critics**: reward -1 per step and no discount, so
  the return counts steps; each critic predicts a categorical distribution over ``1..K`` steps
  and learns by cross-entropy against the next state's distribution shifted one bin
  (:func:`~agents.distributional.shift_distance_target`);
- an ensemble of **categorical cost critics** over ``[0, cost_max]`` learning the expected
  cumulative cost to the goal with the C51 projection (costs from ``info["cost"]``);
- **Lagrangian fine-tuning** (``constrained=True``): the actor minimises
  ``(distance + lambda * cost) / (1 + lambda)`` and ``lambda >= 0`` rises while episodes cost
  more than ``cost_limit``;
- **training problems** chosen by a :mod:`~agents.self_sampling` sampler: the paper's
  self-sampling by default, SoRB's oracle band or uniform sampling for comparison.

``distance``/``cost`` evaluate the critics for observation-goal pairs and
``pairwise_distance``/``pairwise_cost`` build the ``N x M`` matrices a planner needs.
"""
from __future__ import annotations

import inspect
import io
import pathlib
import warnings
from collections import deque
from typing import Any, ClassVar, Dict, List, Optional, Tuple, Type, TypeVar, Union

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, ConvertCallback
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import FloatSchedule, polyak_update, safe_mean, update_learning_rate
from stable_baselines3.common.vec_env import VecEnv

from .actor import GoalActor
from .augmentation import RandomShift
from .buffers import GoalCostReplayBuffer, GoalCostSamples, check_goal_space
from .callbacks import progress_bar_callback
from .checkpoints import CheckpointError, read_checkpoint
from .critics import CategoricalCritic
from .distributional import categorical_projection, shift_distance_target
from .heads import aggregate_ensemble
from .lagrangian import LagrangeMultiplier
from .policies import SafeGoalPolicy
from .self_sampling import ProblemResetWrapper, ProblemSampler, find_wrappers, install_sampler, make_sampler
from .threads import inference_threads, torch_threads

SelfSafeGoalTD3 = TypeVar("SelfSafeGoalTD3", bound="SafeGoalTD3")


class SafeGoalTD3(OffPolicyAlgorithm):
    """Goal-conditioned safe TD3 with distributional distance and cost critics.

    Args:
        policy: ``"MultiInputPolicy"`` or a :class:`~agents.policies.SafeGoalPolicy` subclass.
        env: a goal-conditioned environment (registered id, ``gym.Env`` or ``VecEnv``). Gym
            environments are wrapped in a :class:`~agents.self_sampling.ProblemResetWrapper`
            so the problem sampler can choose each episode's start and goal.
        learning_rate: critic learning rate (number or schedule).
        buffer_size: replay capacity.
        learning_starts: random-action steps before learning.
        batch_size: minibatch size.
        tau: Polyak coefficient of the target networks.
        train_freq / gradient_steps: as in SB3.
        action_noise: exploration noise added to the actor's actions.
        replay_buffer_class: default :class:`~agents.buffers.GoalCostReplayBuffer`.
        replay_buffer_kwargs: e.g. ``her_ratio``, ``random_goal_ratio``.
        actor_learning_rate: actor learning rate (default: ``learning_rate``).
        cost_learning_rate: cost-critic learning rate (default: ``learning_rate``).
        policy_delay: critic updates per actor update.
        target_update_interval: gradient steps between target updates.
        target_policy_noise / target_noise_clip: TD3 target policy smoothing.
        actor_aggregate: how the actor combines the ensemble (``"mean"`` or ``"max"``).
        constrained: learn ``lambda`` and penalise cost in the actor loss (fine-tuning stage).
        cost_limit: the episode-cost limit ``delta``.
        lagrange_lr: learning rate of ``lambda``.
        lagrange_init: initial ``lambda``.
        lagrange_max: optional cap on ``lambda``.
        lagrange_update_episodes: finished episodes per ``lambda`` update (their mean cost).
        problem_sampler: ``"self"`` (Algorithm 1), ``"oracle"``, ``"uniform"`` or a
            :class:`~agents.self_sampling.ProblemSampler`.
        problem_sampler_kwargs: keyword arguments of a named sampler.
        env_id: the environment id recorded in checkpoints (default: from ``env``).
        augmentation: ``None`` or ``"shift"``: DrQ's random-shift augmentation of image
            observations (pad each view by ``shift_pad`` pixels, crop back at a random offset)
            for the shared-encoder layout; ignored for vector observations.
        shift_pad: the largest shift of ``"shift"``, in pixels.
        actor_preactivation_penalty: weight of ``mean(u ** 2)`` in the actor loss, ``u`` the action
            before ``tanh``: keeps the actor out of ``tanh``'s flat ends, where its gradient
            vanishes and it stops learning (0: off).
        stats_window_size, tensorboard_log, policy_kwargs, verbose, seed, device: as in SB3.

    The discount is fixed to 1 (distances count steps); the episode's time limit keeps
    returns finite and the last distance bin absorbs "too far".
    """

    policy_aliases: ClassVar[Dict[str, Type[BasePolicy]]] = {"MultiInputPolicy": SafeGoalPolicy}
    policy: SafeGoalPolicy
    replay_buffer: GoalCostReplayBuffer
    actor: GoalActor
    actor_target: GoalActor
    critic: CategoricalCritic
    critic_target: CategoricalCritic
    cost_critic: CategoricalCritic
    cost_critic_target: CategoricalCritic

    def __init__(
        self,
        policy: Union[str, Type[SafeGoalPolicy]],
        env: Union[GymEnv, str, None],
        learning_rate: Union[float, Schedule] = 3e-4,
        buffer_size: int = 100_000,
        learning_starts: int = 1000,
        batch_size: int = 256,
        tau: float = 0.05,
        train_freq: Union[int, Tuple[int, str]] = 1,
        gradient_steps: int = 1,
        action_noise: Optional[ActionNoise] = None,
        replay_buffer_class: Optional[Type[ReplayBuffer]] = None,
        replay_buffer_kwargs: Optional[Dict[str, Any]] = None,
        actor_learning_rate: Optional[Union[float, Schedule]] = None,
        cost_learning_rate: Optional[Union[float, Schedule]] = None,
        policy_delay: int = 1,
        target_update_interval: int = 5,
        target_policy_noise: float = 0.1,
        target_noise_clip: float = 0.3,
        actor_aggregate: str = "mean",
        constrained: bool = False,
        cost_limit: float = 10.0,
        lagrange_lr: float = 0.035,
        lagrange_init: float = 0.0,
        lagrange_max: Optional[float] = None,
        lagrange_update_episodes: int = 10,
        problem_sampler: Union[str, ProblemSampler, None] = "self",
        problem_sampler_kwargs: Optional[Dict[str, Any]] = None,
        env_id: Optional[str] = None,
        augmentation: Optional[str] = None,
        shift_pad: int = 2,
        actor_preactivation_penalty: float = 0.0,
        stats_window_size: int = 100,
        tensorboard_log: Optional[str] = None,
        policy_kwargs: Optional[Dict[str, Any]] = None,
        verbose: int = 0,
        seed: Optional[int] = None,
        device: Union[th.device, str] = "auto",
        _init_setup_model: bool = True,
    ) -> None:
        if env_id is None:
            env_id = env if isinstance(env, str) else getattr(getattr(env, "spec", None), "id", None)
        if isinstance(env, str):
            import safe_mapf_envs  # noqa: F401  (registers the environment ids)

            env = gym.make(env)
        if tensorboard_log is not None:
            try:
                from torch.utils.tensorboard import SummaryWriter  # noqa: F401
            except ImportError:
                warnings.warn("tensorboard is not installed: TensorBoard logging is disabled", stacklevel=2)
                tensorboard_log = None
        for name, v in (("policy_delay", policy_delay), ("target_update_interval", target_update_interval),
                        ("lagrange_update_episodes", lagrange_update_episodes)):
            if int(v) < 1:
                raise ValueError(f"{name} must be >= 1, got {v!r}")
        if augmentation not in (None, "shift"):
            raise ValueError(f"augmentation must be None or 'shift', got {augmentation!r}")
        if int(shift_pad) < 0:
            raise ValueError(f"shift_pad must be >= 0, got {shift_pad!r}")
        if actor_aggregate not in ("mean", "max", "min"):
            raise ValueError(f"actor_aggregate must be 'mean', 'max' or 'min', got {actor_aggregate!r}")
        super().__init__(
            policy, env,  # type: ignore[arg-type]  # load() builds the model without an env
            learning_rate, buffer_size, learning_starts, batch_size, tau, 1.0, train_freq,
            gradient_steps, action_noise=action_noise, replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs, optimize_memory_usage=False, policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size, tensorboard_log=tensorboard_log, verbose=verbose, device=device,
            seed=seed, sde_support=False, supported_action_spaces=(spaces.Box,), support_multi_env=True,
        )
        self.env_id = env_id
        self.augmentation = augmentation
        self.shift_pad = int(shift_pad)
        if not (np.isfinite(actor_preactivation_penalty) and actor_preactivation_penalty >= 0):
            raise ValueError(f"actor_preactivation_penalty must be >= 0, got {actor_preactivation_penalty!r}")
        self.actor_preactivation_penalty = float(actor_preactivation_penalty)
        self.actor_learning_rate = actor_learning_rate
        self.cost_learning_rate = cost_learning_rate
        self.policy_delay = int(policy_delay)
        self.target_update_interval = int(target_update_interval)
        self.target_policy_noise = float(target_policy_noise)
        self.target_noise_clip = float(target_noise_clip)
        self.actor_aggregate = actor_aggregate
        self.constrained = bool(constrained)
        self.lagrange_update_episodes = int(lagrange_update_episodes)
        self.lagrangian = LagrangeMultiplier(cost_limit, lagrange_lr, lagrange_init, lagrange_max)
        self.problem_sampler = problem_sampler
        self.problem_sampler_kwargs = dict(problem_sampler_kwargs or {})
        self.ep_cost_buffer: deque = deque(maxlen=stats_window_size)
        self._pending_episode_costs: List[float] = []
        self._episode_cost_acc: Optional[np.ndarray] = None
        self._sampler: Optional[ProblemSampler] = None
        if _init_setup_model:
            self._setup_model()

    # ------------------------------------------------------------------ setup
    @staticmethod
    def _wrap_env(env: GymEnv, verbose: int = 0, monitor_wrapper: bool = True) -> VecEnv:
        if isinstance(env, gym.Env) and not find_wrappers(env):
            env = ProblemResetWrapper(env)
        return BaseAlgorithm._wrap_env(env, verbose, monitor_wrapper)

    def _setup_model(self) -> None:
        check_goal_space(self.observation_space)
        if self.replay_buffer_class is None:
            self.replay_buffer_class = GoalCostReplayBuffer
        super()._setup_model()
        if isinstance(self.replay_buffer, GoalCostReplayBuffer):
            self.replay_buffer.set_env(self.env)
            self.replay_buffer.seed(self.seed)
        self._create_aliases()
        self.augment = None
        if self.augmentation == "shift" and self.policy.share_encoder:
            self.augment = RandomShift(self.shift_pad, th.Generator().manual_seed(self.seed or 0))
        self._sampler = make_sampler(self.problem_sampler, **self.problem_sampler_kwargs)
        self.actor_lr_schedule = FloatSchedule(self.actor_learning_rate if self.actor_learning_rate is not None
                                               else self.learning_rate)
        self.cost_lr_schedule = FloatSchedule(self.cost_learning_rate if self.cost_learning_rate is not None
                                              else self.learning_rate)

    def _create_aliases(self) -> None:
        self.actor = self.policy.actor
        self.actor_target = self.policy.actor_target
        self.critic = self.policy.critic
        self.critic_target = self.policy.critic_target
        self.cost_critic = self.policy.cost_critic
        self.cost_critic_target = self.policy.cost_critic_target

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        super().set_env(env, force_reset)
        if isinstance(self.replay_buffer, GoalCostReplayBuffer):
            self.replay_buffer.set_env(self.env)

    @property
    def sampler(self) -> Optional[ProblemSampler]:
        """The problem sampler choosing training episodes."""
        return self._sampler

    def set_problem_sampler(self, sampler: Union[str, ProblemSampler], **kwargs: Any) -> None:
        """Replace the problem sampler (e.g. switch between stages)."""
        self.problem_sampler = sampler
        self.problem_sampler_kwargs = dict(kwargs)
        self._sampler = make_sampler(sampler, **kwargs)

    def _attach_sampler(self) -> None:
        """Connect the model's own problem sampler to the training environment's
        :class:`~agents.self_sampling.ProblemResetWrapper` layers (before the first reset of a
        ``learn`` call, so that every episode of the call is a sampled problem)."""
        if self.env is not None and self._sampler is not None:
            install_sampler(self.env, self._sampler, self)

    def _init_callback(self, callback: MaybeCallback, progress_bar: bool = False) -> BaseCallback:
        if isinstance(callback, list):
            callback = CallbackList(callback)
        if not isinstance(callback, BaseCallback):
            callback = ConvertCallback(callback)
        if progress_bar:
            bar = progress_bar_callback()
            callback = CallbackList([callback, bar])
        callback.init_callback(self)
        return callback

    def learn(self: SelfSafeGoalTD3, total_timesteps: int, callback: MaybeCallback = None, log_interval: int = 10,
              tb_log_name: str = "SafeGoalTD3", reset_num_timesteps: bool = True,
              progress_bar: bool = False) -> SelfSafeGoalTD3:
        """Train for ``total_timesteps`` environment steps (SB3's ``learn``).

        The model's problem sampler (``problem_sampler``) chooses every episode of the call,
        the first included; a :class:`~agents.self_sampling.ProblemSamplingCallback` in
        ``callback`` replaces it from the next episode on.
        """
        self._attach_sampler()
        return super().learn(total_timesteps=total_timesteps, callback=callback, log_interval=log_interval,
                             tb_log_name=tb_log_name, reset_num_timesteps=reset_num_timesteps,
                             progress_bar=progress_bar)

    # ------------------------------------------------------------------ costs and lambda
    def _update_info_buffer(self, infos: List[Dict[str, Any]], dones: Optional[np.ndarray] = None) -> None:
        super()._update_info_buffer(infos, dones)
        if dones is None:
            return
        if self._episode_cost_acc is None or len(self._episode_cost_acc) != len(infos):
            self._episode_cost_acc = np.zeros(len(infos))
        for i, info in enumerate(infos):
            self._episode_cost_acc[i] += float(info.get("cost", 0.0))
            if dones[i]:
                self.ep_cost_buffer.append(float(self._episode_cost_acc[i]))
                self._pending_episode_costs.append(float(self._episode_cost_acc[i]))
                self._episode_cost_acc[i] = 0.0
        if len(self._pending_episode_costs) > 10 * self.lagrange_update_episodes:
            del self._pending_episode_costs[: -self.lagrange_update_episodes]

    def _maybe_update_lagrangian(self) -> None:
        if self.constrained and len(self._pending_episode_costs) >= self.lagrange_update_episodes:
            self.lagrangian.update(self._pending_episode_costs)
            self._pending_episode_costs = []

    @property
    def lagrange_multiplier(self) -> float:
        """The current ``lambda`` (0 throughout the unconstrained stage)."""
        return self.lagrangian.value

    # ------------------------------------------------------------------ training
    def train(self, gradient_steps: int, batch_size: int = 256) -> None:
        if self.replay_buffer.n_complete_transitions() == 0:
            return  # goals are relabelled within finished episodes only: wait for the first one
        self.policy.set_training_mode(True)
        progress = self._current_progress_remaining
        update_learning_rate(self.critic.optimizer, self.lr_schedule(progress))
        update_learning_rate(self.cost_critic.optimizer, self.cost_lr_schedule(progress))
        update_learning_rate(self.actor.optimizer, self.actor_lr_schedule(progress))
        self._maybe_update_lagrangian()
        lam = self.lagrangian.value if self.constrained else 0.0
        d_losses, c_losses, a_losses, pred_d = [], [], [], []
        step = self._shared_encoder_step if self.policy.share_encoder else self._separate_encoders_step
        for _ in range(gradient_steps):
            self._n_updates += 1
            data = self.replay_buffer.sample(batch_size)
            d_loss, c_loss, actor_out = step(data, lam, self._n_updates % self.policy_delay == 0)
            d_losses.append(d_loss)
            c_losses.append(c_loss)
            if actor_out is not None:
                a_losses.append(actor_out[0])
                pred_d.append(actor_out[1])
            if self._n_updates % self.target_update_interval == 0:
                polyak_update(*self.policy.target_parameter_pairs(), self.tau)

        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/distance_critic_loss", float(np.mean(d_losses)))
        self.logger.record("train/cost_critic_loss", float(np.mean(c_losses)))
        if a_losses:
            self.logger.record("train/actor_loss", float(np.mean(a_losses)))
            self.logger.record("train/predicted_distance", float(np.mean(pred_d)))
        self.logger.record("train/lambda", self.lagrangian.value)

    def _targets(self, data: GoalCostSamples, f_actor: th.Tensor, f_d: th.Tensor,
                 f_c: th.Tensor) -> Tuple[th.Tensor, th.Tensor]:
        """Target distributions of the distance and cost critics from the next step's features as
        seen by the target actor, distance critic and cost critic (call without gradients)."""
        next_actions = self.actor_target.action_from_features(f_actor)
        if self.target_policy_noise > 0:
            noise = th.randn_like(next_actions) * self.target_policy_noise
            next_actions = (next_actions + noise.clamp(-self.target_noise_clip, self.target_noise_clip)).clamp(-1, 1)
        e_d, e_c = self.critic.n_members, self.cost_critic.n_members
        dones = data.dones.reshape(1, -1)
        next_d = th.softmax(self.critic_target.logits_from_features(f_d, next_actions), dim=-1)
        target_d = shift_distance_target(next_d, dones.expand(e_d, -1))
        next_c = th.softmax(self.cost_critic_target.logits_from_features(f_c, next_actions), dim=-1)
        costs = data.costs.reshape(1, -1).expand(e_c, -1)
        target_c = categorical_projection(next_c, costs, dones.expand(e_c, -1), self.cost_critic.support)
        return target_d, target_c

    @staticmethod
    def _cross_entropy(target: th.Tensor, logits: th.Tensor) -> th.Tensor:
        """Cross-entropy summed over ensemble members, averaged over the batch."""
        return -(target * th.log_softmax(logits, dim=-1)).sum(-1).mean(-1).sum()

    def _actor_step(self, f_actor: th.Tensor, f_d: th.Tensor, f_c: th.Tensor, lam: float) -> Tuple[float, float]:
        """One actor update: minimise the predicted distance (plus ``lam`` times the cost)
        of its action, with the critics' features ``f_d``/``f_c`` held fixed."""
        pre = self.actor.preactivation(f_actor)
        actions = th.tanh(pre)
        dist = aggregate_ensemble(self.critic.expected(self.critic.logits_from_features(f_d, actions)),
                                  self.actor_aggregate)
        if lam > 0:
            cost = aggregate_ensemble(self.cost_critic.expected(self.cost_critic.logits_from_features(f_c, actions)),
                                      self.actor_aggregate)
            a_loss = ((dist + lam * cost) / (1.0 + lam)).mean()
        else:
            a_loss = dist.mean()
        if self.actor_preactivation_penalty > 0:
            a_loss = a_loss + self.actor_preactivation_penalty * pre.square().mean()
        self.actor.optimizer.zero_grad()
        a_loss.backward()
        self.actor.optimizer.step()
        return a_loss.item(), dist.mean().item()

    def _separate_encoders_step(self, data: GoalCostSamples, lam: float, update_actor: bool):
        """One update with an extractor per network (the vector agents' layout)."""
        obs, next_obs = data.observations, data.next_observations
        with th.no_grad():
            target_d, target_c = self._targets(
                data, self.actor_target.extract_features(next_obs), self.critic_target.extract_features(next_obs),
                self.cost_critic_target.extract_features(next_obs))
        d_loss = self._cross_entropy(target_d, self.critic(obs, data.actions))
        self.critic.optimizer.zero_grad()
        d_loss.backward()
        self.critic.optimizer.step()
        c_loss = self._cross_entropy(target_c, self.cost_critic(obs, data.actions))
        self.cost_critic.optimizer.zero_grad()
        c_loss.backward()
        self.cost_critic.optimizer.step()
        actor_out = None
        if update_actor:
            with th.no_grad():
                f_d = self.critic.extract_features(obs)
                f_c = self.cost_critic.extract_features(obs) if lam > 0 else f_d
            actor_out = self._actor_step(self.actor.extract_features(obs), f_d, f_c, lam)
        return d_loss.item(), c_loss.item(), actor_out

    def _shared_encoder_step(self, data: GoalCostSamples, lam: float, update_actor: bool):
        """One update of the shared-encoder layout (pixel-based off-policy RL, after SAC-AE/DrQ).

        The observation and the goal are encoded in one batched pass by the online encoder,
        which the distance and cost losses train together (one backward pass); the next
        observation and the goal are encoded by the Polyak target encoder without gradients;
        the actor reads the online features detached, so its loss never reaches the encoder.
        """
        enc, enc_t = self.policy.encoder, self.policy.encoder_target
        obs, goal = data.observations["observation"], data.observations["desired_goal"]
        next_obs = data.next_observations["observation"]
        b = obs.shape[0]
        if self.augment is not None:
            obs, goal, next_obs = (self.augment(x) for x in (obs, goal, next_obs))
        with th.no_grad():
            next_feats = th.cat(enc_t.encode(th.cat([next_obs, goal], 0)).split([b, b]), 1)
            target_d, target_c = self._targets(data, next_feats, next_feats, next_feats)
        feats = th.cat(enc.encode(th.cat([obs, goal], 0)).split([b, b]), 1)
        d_loss = self._cross_entropy(target_d, self.critic.logits_from_features(feats, data.actions))
        c_loss = self._cross_entropy(target_c, self.cost_critic.logits_from_features(feats, data.actions))
        self.critic.optimizer.zero_grad()
        self.cost_critic.optimizer.zero_grad()
        (d_loss + c_loss).backward()
        self.critic.optimizer.step()
        self.cost_critic.optimizer.step()
        actor_out = None
        if update_actor:
            f = feats.detach()
            actor_out = self._actor_step(f, f, f, lam)
        return d_loss.item(), c_loss.item(), actor_out

    def dump_logs(self) -> None:
        if self.ep_cost_buffer:
            self.logger.record("rollout/ep_cost_mean", safe_mean(list(self.ep_cost_buffer)))
        if self._sampler is not None:
            for k, v in self._sampler.stats.items():
                self.logger.record(k, v)
        super().dump_logs()

    # ------------------------------------------------------------------ critics as functions
    # CPU threads of these queries: the ``threads`` argument, else $SAFE_MAPF_INFERENCE_THREADS,
    # else torch's setting where the user chose it, else one (see :mod:`agents.threads`).
    def distance(self, obs: np.ndarray, goal: np.ndarray, aggregate: str = "max",
                 threads: Optional[int] = None) -> np.ndarray:
        """Predicted steps from ``obs[i]`` to ``goal[i]`` (expected value of the distance distribution).

        ``obs``/``goal``: raw observations, one (``obs_shape``) or batches ``(N, *obs_shape)``;
        for the vector environments, positions divided by the world size. ``aggregate``
        combines the ensemble: ``"max"`` (pessimistic), ``"mean"``, ``"min"`` or ``"none"``
        (``(E, N)``). ``threads``: CPU threads of the query (default: one, unless set by
        ``SAFE_MAPF_INFERENCE_THREADS`` or ``torch.set_num_threads``; see :mod:`agents.threads`).
        """
        with torch_threads(inference_threads(threads)):
            return self.policy.values(obs, goal, ("distance",), aggregate)["distance"]

    def cost(self, obs: np.ndarray, goal: np.ndarray, aggregate: str = "max",
             threads: Optional[int] = None) -> np.ndarray:
        """Predicted cumulative cost from ``obs[i]`` to ``goal[i]`` (same conventions as :meth:`distance`)."""
        with torch_threads(inference_threads(threads)):
            return self.policy.values(obs, goal, ("cost",), aggregate)["cost"]

    def pairwise_distance(self, obs_a: np.ndarray, obs_b: np.ndarray, aggregate: str = "max",
                          chunk_size: int = 2048, threads: Optional[int] = None,
                          progress: Optional[bool] = None) -> np.ndarray:
        """``D[i, j]``: predicted steps from ``obs_a[i]`` to ``obs_b[j]``, shape ``(N, M)`` (float32).

        ``threads`` as in :meth:`distance`. ``progress``: a progress bar over the blocks of
        pairs: ``None`` (default) shows one on a terminal once the build has run 2 s, ``True``
        always, ``False`` never.
        """
        with torch_threads(inference_threads(threads)):
            return self.policy.pairwise(obs_a, obs_b, ("distance",), aggregate, chunk_size,
                                        progress=progress)["distance"]

    def pairwise_cost(self, obs_a: np.ndarray, obs_b: np.ndarray, aggregate: str = "max",
                      chunk_size: int = 2048, threads: Optional[int] = None,
                      progress: Optional[bool] = None) -> np.ndarray:
        """``C[i, j]``: predicted cumulative cost from ``obs_a[i]`` to ``obs_b[j]``, shape ``(N, M)``
        (``threads`` and ``progress`` as in :meth:`pairwise_distance`)."""
        with torch_threads(inference_threads(threads)):
            return self.policy.pairwise(obs_a, obs_b, ("cost",), aggregate, chunk_size, progress=progress)["cost"]

    def encode_observations(self, obs: np.ndarray, threads: Optional[int] = None):
        """Encode a batch of observations once: the result stands in for ``obs`` in
        :meth:`pairwise`, :meth:`pairwise_distance` and :meth:`pairwise_cost` (a planner's graph
        nodes, scored against every new start and goal). Stale once the model trains further."""
        with torch_threads(inference_threads(threads)):
            return self.policy.encode_observations(obs)

    def pairwise(self, obs_a: np.ndarray, obs_b: np.ndarray, aggregate: str = "max",
                 chunk_size: int = 2048, threads: Optional[int] = None,
                 progress: Optional[bool] = None, within: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray]:
        """``(D, C)`` together, sharing the actor's pass over the pairs (cheaper than two calls;
        ``threads`` and ``progress`` as in :meth:`pairwise_distance`; ``within``: exact only below
        that distance, far cheaper where most pairs are far apart, see ``SafeGoalPolicy.pairwise``)."""
        with torch_threads(inference_threads(threads)):
            out = self.policy.pairwise(obs_a, obs_b, ("distance", "cost"), aggregate, chunk_size, progress, within)
        return out["distance"], out["cost"]

    def pairwise_at(self, obs_a: np.ndarray, obs_b: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                    threads: Optional[int] = None, within: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray]:
        """``(D, C)`` of the listed pairs only, ``obs_a[rows[p]]`` to ``obs_b[cols[p]]`` (ensemble
        maximum; ``within`` as for :meth:`pairwise`); ``obs_a`` / ``obs_b`` may be encoded by
        :meth:`encode_observations`."""
        with torch_threads(inference_threads(threads)):
            out = self.policy.pairwise_at(obs_a, obs_b, rows, cols, ("distance", "cost"), within=within)
        return out["distance"], out["cost"]

    # ------------------------------------------------------------------ save / load
    def _excluded_save_params(self) -> List[str]:
        excluded = super()._excluded_save_params() + [
            "actor", "actor_target", "critic", "critic_target", "cost_critic", "cost_critic_target",
            "_sampler", "_episode_cost_acc", "actor_lr_schedule", "cost_lr_schedule", "augment",
        ]
        if not isinstance(self.problem_sampler, (str, type(None))):
            excluded.append("problem_sampler")
        return excluded

    def _get_torch_save_params(self) -> Tuple[List[str], List[str]]:
        return ["policy", "actor.optimizer", "critic.optimizer", "cost_critic.optimizer"], []

    @classmethod
    def load(
        cls: Type[SelfSafeGoalTD3],
        path: Union[str, pathlib.Path, io.BufferedIOBase],
        env: Optional[GymEnv] = None,
        device: Union[th.device, str] = "auto",
        custom_objects: Optional[Dict[str, Any]] = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **overrides: Any,
    ) -> SelfSafeGoalTD3:
        """Load a checkpoint, optionally with some settings changed (e.g. to fine-tune it).

        ``overrides`` are constructor arguments of :class:`SafeGoalTD3` (``learning_rate``,
        ``batch_size``, ``action_noise``, ``constrained``, ``problem_sampler``, ...) that replace
        the stored ones before the model is set up, so the learning-rate schedules and the
        problem sampler follow them; the networks and optimiser states are the checkpoint's.
        ``policy_kwargs`` must equal the stored ones (the networks are fixed by the file).
        Special cases:

        - ``seed``: after the networks are loaded, the random generators (torch, numpy, the
          environment, the action space) and the replay buffer's sampling are seeded with it,
          so a fine-tuning run is reproducible from its seed;
        - ``cost_limit``, ``lagrange_lr``, ``lagrange_init``, ``lagrange_max``: a new Lagrange
          multiplier from these, the missing ones taken from the stored multiplier
          (``lagrange_init`` from its current value).

        Nothing the file supplies is unpickled (see :mod:`agents.checkpoints`): its serialized
        entries are rebuilt from what is known, its tensors are read weights-only and must be
        finite. A corrupt, incomplete, unsafe or mismatched file raises :class:`CheckpointError`
        naming the file and the entry; an unknown override raises ``TypeError``.
        """
        overrides = dict(overrides)
        unknown = sorted(set(overrides) - set(_load_overrides()))
        if unknown:
            raise TypeError(f"{cls.__name__}.load got unknown overrides {unknown}; "
                            f"accepted: {sorted(_load_overrides())}")
        lagrange = {k: overrides.pop(k) for k in _LAGRANGE_OVERRIDES if k in overrides}
        archive = read_checkpoint(path, custom_objects=custom_objects, owner=cls.__name__, env=env,
                                  provided=list(overrides))
        name = archive.name
        try:
            # the very bytes checked, with every serialized entry replaced: nothing is unpickled
            model = super().load(archive.stream(), env=env, device=device, custom_objects=archive.custom_objects,
                                 print_system_info=print_system_info, force_reset=force_reset, **overrides)
        except ValueError as exc:
            if "spaces do not match" in str(exc) or "do not match" in str(exc):
                raise CheckpointError(f"{name} does not fit the given environment: {exc}") from exc
            raise CheckpointError(f"{name}: {exc}") from exc
        except (RuntimeError, KeyError) as exc:
            raise CheckpointError(f"{name}: the stored networks do not match the policy architecture "
                                  f"({type(exc).__name__}: {exc})") from exc
        if lagrange:
            old = model.lagrangian
            model.lagrangian = LagrangeMultiplier(
                lagrange.get("cost_limit", old.cost_limit), lagrange.get("lagrange_lr", old.learning_rate),
                lagrange.get("lagrange_init", old.value), lagrange.get("lagrange_max", old.max_value))
        if overrides.get("seed") is not None:
            model.set_random_seed(model.seed)
            model.replay_buffer.seed(model.seed)
        return model


#: ``load`` overrides that build a new Lagrange multiplier instead of setting an attribute
_LAGRANGE_OVERRIDES = ("cost_limit", "lagrange_lr", "lagrange_init", "lagrange_max")


def _load_overrides() -> List[str]:
    """Names ``SafeGoalTD3.load`` accepts as overrides: the constructor's settings."""
    fixed = {"self", "policy", "env", "device", "_init_setup_model", "stats_window_size"}
    return [k for k in inspect.signature(SafeGoalTD3.__init__).parameters if k not in fixed]


__all__ = ["SafeGoalTD3"]
