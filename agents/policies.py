"""The policy of the goal-conditioned safe agent: actor, distance and cost critic ensembles, targets.

Layout (after Stable-Baselines3's ``td3/policies.py``): a :class:`~agents.actor.GoalActor` and
two :class:`~agents.critics.CategoricalCritic` ensembles (distance and cost), each with its own
:class:`~agents.encoders.GoalPairExtractor` (or one shared encoder for images), plus target
copies, gathered in :class:`SafeGoalPolicy`. Its :meth:`SafeGoalPolicy.pairwise` gives the
``N x M`` matrices a planner needs, using the heads' first-layer shortcut
(:mod:`agents.heads`).
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Type, Union, cast

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from .actor import GoalActor
from .buffers import check_goal_space
from .critics import CategoricalCritic
from .distributional import cost_support, distance_support
from .encoders import GoalPairExtractor, encode_chunked, is_image_space
from .heads import AGGREGATES, aggregate_ensemble, first_layer_products, pair_head, pair_head_at


class EncodedObservations:
    """Codes of a batch of raw observations under each encoder of one policy.

    Made by :meth:`SafeGoalPolicy.encode_observations`; :meth:`SafeGoalPolicy.pairwise` takes it
    in place of the raw batch, so that observations scored again and again (a planner's graph
    nodes, against every new start and goal) are encoded once. Valid for the policy that made
    it, as long as its encoders are not trained further.
    """

    def __init__(self, policy: "SafeGoalPolicy", codes: Dict[int, th.Tensor], n: int) -> None:
        self.policy = policy  # held, so the encoder ids below stay its own
        self.codes = codes  # id(features extractor) -> (n, code_dim)
        self.n = int(n)

    def __len__(self) -> int:
        return self.n


def _checked_values(arr: np.ndarray, space: spaces.Space, what: str) -> np.ndarray:
    """``arr`` if its values fit ``space``'s kind: ``uint8`` images as integers in 0-255 (returned
    as ``uint8``), vectors finite; else ``ValueError`` naming ``what``."""
    if space.dtype == np.uint8:
        if arr.dtype.kind not in "ui":
            raise ValueError(f"{what} must be uint8 images (integers 0-255) like the observation space, got "
                             f"{arr.dtype} values; pass the environment's images as they come")
        if arr.dtype != np.uint8:
            if arr.size and (arr.min() < 0 or arr.max() > 255):
                raise ValueError(f"{what} has values outside 0-255")
            arr = arr.astype(np.uint8)
        return arr
    if arr.dtype.kind not in "fiub":
        raise ValueError(f"{what} must be real numbers, got {arr.dtype} values")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} contains NaN or inf")
    return arr


class SafeGoalPolicy(BasePolicy):
    """Actor, distance-critic ensemble and cost-critic ensemble (plus targets) of the safe agent.

    Args:
        observation_space: goal-conditioned ``Dict`` space (vector or image observations).
        action_space: ``Box`` actions.
        lr_schedule: learning-rate schedule (the algorithm sets per-network rates while training).
        net_arch: hidden widths of the heads: a list for all of them, or a dict with keys
            ``pi`` (actor), ``qf`` (distance critics) and ``qc`` (cost critics). The first layer of
            every head sits on ``[code(obs), code(goal), action]``; the pairwise cost of the
            planner's matrices grows with the square of these widths.
        activation_fn: activation of the heads.
        features_extractor_class: extractor of actor and critics (each gets its own instance).
        features_extractor_kwargs: its keyword arguments.
        normalize_images: unused (the encoders scale ``uint8`` images themselves); kept for SB3.
        optimizer_class / optimizer_kwargs: optimiser of each network.
        n_critics: members of the distance ensemble.
        n_cost_critics: members of the cost ensemble.
        n_distance_bins: bins of the distance distribution (bin ``k`` = ``k + 1`` steps); the
            largest representable distance, use the episode step limit.
        n_cost_bins: atoms of the cost distribution.
        cost_max: the largest atom of the cost distribution (the smallest is 0).
        actor_input_norm: a LayerNorm on the actor's input features (default: with a shared
            encoder; see :class:`GoalActor`).
        share_encoder: one observation encoder for actor and critics (the recipe of pixel-based
            off-policy RL: SAC-AE, DrQ), trained by the critic losses only, the actor reading
            its features detached, and one Polyak copy of it under every target network. With
            ``False`` each of the six networks has its own extractor (the layout of the vector
            agents). ``None`` (default): shared for image observations, separate for vectors.

    The encoder of the shared layout is :attr:`encoder` (target: :attr:`encoder_target`);
    ``actor.features_extractor``, ``critic.features_extractor`` and
    ``cost_critic.features_extractor`` are that same module.
    """

    actor: GoalActor
    actor_target: GoalActor
    critic: CategoricalCritic
    critic_target: CategoricalCritic
    cost_critic: CategoricalCritic
    cost_critic_target: CategoricalCritic
    encoder: GoalPairExtractor
    encoder_target: GoalPairExtractor
    observation_space: spaces.Dict
    action_space: spaces.Box

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: Optional[List[int] | Dict[str, List[int]]] = None,
        activation_fn: Type[nn.Module] = nn.ReLU,
        features_extractor_class: Type[BaseFeaturesExtractor] = GoalPairExtractor,
        features_extractor_kwargs: Optional[Dict[str, Any]] = None,
        normalize_images: bool = False,
        optimizer_class: Type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: Optional[Dict[str, Any]] = None,
        n_critics: int = 3,
        n_cost_critics: int = 3,
        n_distance_bins: int = 20,
        n_cost_bins: int = 40,
        cost_max: float = 40.0,
        share_encoder: Optional[bool] = None,
        actor_input_norm: Optional[bool] = None,
    ) -> None:
        check_goal_space(observation_space)
        if not isinstance(action_space, spaces.Box):
            raise ValueError(f"SafeGoalPolicy needs a Box action space, got {action_space!r}")
        for name, v in (("n_critics", n_critics), ("n_cost_critics", n_cost_critics)):
            if int(v) < 1:
                raise ValueError(f"{name} must be >= 1, got {v!r}")
        super().__init__(observation_space, action_space, features_extractor_class, features_extractor_kwargs,
                         optimizer_class=optimizer_class, optimizer_kwargs=optimizer_kwargs,
                         normalize_images=False, squash_output=True)
        if net_arch is None:
            net_arch = [128, 128]
        if isinstance(net_arch, dict):
            unknown = set(net_arch) - {"pi", "qf", "qc"}
            if unknown:
                raise ValueError(f"net_arch keys must be among 'pi', 'qf', 'qc', got {sorted(unknown)}")
            pi_arch = list(net_arch.get("pi", [128, 128]))
            qf_arch = list(net_arch.get("qf", [128, 128]))
            qc_arch = list(net_arch.get("qc", qf_arch))
        else:
            pi_arch = qf_arch = qc_arch = list(net_arch)
        self.net_arch = net_arch
        self.pi_arch, self.qf_arch, self.qc_arch = pi_arch, qf_arch, qc_arch
        self.activation_fn = activation_fn
        self.n_critics = int(n_critics)
        self.n_cost_critics = int(n_cost_critics)
        self.n_distance_bins = int(n_distance_bins)
        self.n_cost_bins = int(n_cost_bins)
        self.cost_max = float(cost_max)
        self._distance_support = distance_support(self.n_distance_bins)
        self._cost_support = cost_support(self.n_cost_bins, self.cost_max)
        if share_encoder is None:
            share_encoder = is_image_space(observation_space["observation"])
        self.share_encoder = bool(share_encoder)
        self.actor_input_norm = self.share_encoder if actor_input_norm is None else bool(actor_input_norm)
        if (optimizer_class is th.optim.Adam and "fused" not in self.optimizer_kwargs
                and "foreach" not in self.optimizer_kwargs):
            # one fused kernel per step instead of one per parameter tensor (the heads are small)
            self.optimizer_kwargs = dict(self.optimizer_kwargs, fused=True)
        self._build(lr_schedule)

    # ------------------------------------------------------------------ construction
    def _make_extractor(self) -> GoalPairExtractor:
        return cast(GoalPairExtractor, self.make_features_extractor())

    def _make_actor(self, fe: Optional[GoalPairExtractor] = None) -> GoalActor:
        fe = fe if fe is not None else self._make_extractor()
        return GoalActor(self.observation_space, self.action_space, self.pi_arch, fe, fe.features_dim,
                         self.activation_fn, input_norm=self.actor_input_norm).to(self.device)

    def _make_critic(self, arch: Sequence[int], support: th.Tensor, n_members: int,
                     fe: Optional[GoalPairExtractor] = None) -> CategoricalCritic:
        fe = fe if fe is not None else self._make_extractor()
        return CategoricalCritic(self.observation_space, self.action_space, arch, fe, fe.features_dim, support,
                                 n_members, self.activation_fn).to(self.device)

    def _build(self, lr_schedule: Schedule) -> None:
        lr = lr_schedule(1)
        enc: Optional[GoalPairExtractor] = None
        enc_t: Optional[GoalPairExtractor] = None
        if self.share_encoder:
            enc = self._make_extractor().to(self.device)
            enc_t = self._make_extractor().to(self.device)
            enc_t.load_state_dict(enc.state_dict())
            self.encoder, self.encoder_target = enc, enc_t
        self.actor = self._make_actor(enc)
        self.actor_target = self._make_actor(enc_t)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic = self._make_critic(self.qf_arch, self._distance_support, self.n_critics, enc)
        self.critic_target = self._make_critic(self.qf_arch, self._distance_support, self.n_critics, enc_t)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.cost_critic = self._make_critic(self.qc_arch, self._cost_support, self.n_cost_critics, enc)
        self.cost_critic_target = self._make_critic(self.qc_arch, self._cost_support, self.n_cost_critics, enc_t)
        self.cost_critic_target.load_state_dict(self.cost_critic.state_dict())

        optimizer_class: Any = self.optimizer_class  # any torch optimizer taking lr=
        opt = lambda params: optimizer_class(list(params), lr=lr, **self.optimizer_kwargs)  # noqa: E731
        if enc is not None:
            # The encoder learns from the critic losses only; its parameters sit in the distance
            # critic's optimizer, the actor's optimizer holds its head alone.
            self.actor.optimizer = opt([*self.actor.norm.parameters(), *self.actor.mu.parameters()])
            self.critic.optimizer = opt([*self.critic.head.parameters(), *enc.parameters()])
            self.cost_critic.optimizer = opt(self.cost_critic.head.parameters())
        else:
            self.actor.optimizer = opt(self.actor.parameters())
            self.critic.optimizer = opt(self.critic.parameters())
            self.cost_critic.optimizer = opt(self.cost_critic.parameters())

        for target in (self.actor_target, self.critic_target, self.cost_critic_target):
            target.set_training_mode(False)
        # the online networks' modules, each once (a shared encoder sits in three of them)
        seen: Dict[int, nn.Module] = {}
        for net in (self.actor, self.critic, self.cost_critic):
            seen.update((id(m), m) for m in net.modules())
        self._mode_modules = list(seen.values())

    def target_parameter_pairs(self) -> Tuple[List[th.Tensor], List[th.Tensor]]:
        """Parameters of the online networks and of their targets, aligned and each listed once
        (a shared encoder appears once), for Polyak averaging."""
        def unique(nets) -> List[th.Tensor]:
            seen, out = set(), []
            for net in nets:
                for p in net.parameters():
                    if id(p) not in seen:
                        seen.add(id(p))
                        out.append(p)
            return out

        online = unique((self.actor, self.critic, self.cost_critic))
        target = unique((self.actor_target, self.critic_target, self.cost_critic_target))
        if len(online) != len(target) or any(a.shape != b.shape for a, b in zip(online, target)):
            raise RuntimeError("online and target networks are not aligned")
        return online, target

    def _get_constructor_parameters(self) -> Dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(dict(
            net_arch=self.net_arch, activation_fn=self.activation_fn,
            features_extractor_class=self.features_extractor_class,
            features_extractor_kwargs=self.features_extractor_kwargs,
            optimizer_class=self.optimizer_class, optimizer_kwargs=self.optimizer_kwargs,
            n_critics=self.n_critics, n_cost_critics=self.n_cost_critics,
            n_distance_bins=self.n_distance_bins, n_cost_bins=self.n_cost_bins, cost_max=self.cost_max,
            share_encoder=self.share_encoder, actor_input_norm=self.actor_input_norm,
            lr_schedule=self._dummy_schedule,
        ))
        return data

    # ------------------------------------------------------------------ SB3 API
    def forward(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self._predict(observation, deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self.actor(observation)

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = False) -> Tuple[np.ndarray, Any]:
        """SB3's ``predict``, refusing what would give meaningless actions silently: NaN or inf
        values, and images that are not integers in 0-255 (``ValueError`` naming the key)."""
        if isinstance(observation, dict):
            for key, space in cast(spaces.Dict, self.observation_space).spaces.items():
                if key in observation:
                    observation = {**observation, key: _checked_values(np.asarray(observation[key]), space, key)}
        return super().predict(observation, state, episode_start, deterministic)

    def set_training_mode(self, mode: bool) -> None:
        # What ``actor/critic/cost_critic.set_training_mode`` do, with each module visited once
        # (SB3 toggles the mode on every environment step; a shared encoder sits in six places).
        mode = bool(mode)
        for m in self._mode_modules:
            object.__setattr__(m, "training", mode)  # a plain flag: skip nn.Module's slow __setattr__
        self.training = mode

    # ------------------------------------------------------------------ distances and costs
    def _as_batch(self, x: Any, what: str) -> Tuple[th.Tensor, bool]:
        """Raw observations (one or a batch) as a tensor with a batch axis; flag: was it a single one."""
        shape = cast(Tuple[int, ...], self.observation_space["observation"].shape)
        arr = x.detach().cpu().numpy() if isinstance(x, th.Tensor) else np.asarray(x)
        if arr.shape == shape:
            arr, single = arr[None], True
        elif arr.ndim == len(shape) + 1 and arr.shape[1:] == shape:
            single = False
        else:
            raise ValueError(f"{what} must be one observation of shape {shape} or a batch (N, *{shape}), "
                             f"got shape {arr.shape}")
        arr = _checked_values(arr, self.observation_space["observation"], what)
        if arr.dtype != np.uint8:
            arr = arr.astype(np.float32, copy=False)
        return th.as_tensor(np.ascontiguousarray(arr), device=self.device), single

    def _pair_values(self, obs: th.Tensor, goals: th.Tensor, quantities: Sequence[str]) -> Dict[str, th.Tensor]:
        """Per-member values for aligned ``(obs[i], goals[i])`` pairs, as ``(E, B)`` tensors."""
        cache: Dict[int, th.Tensor] = {}  # a shared encoder encodes once

        def feats(net) -> th.Tensor:
            fe = net.features_extractor
            if id(fe) not in cache:
                codes = fe.encode(th.cat([obs, goals], 0))
                cache[id(fe)] = th.cat(codes.split([obs.shape[0], goals.shape[0]]), 1)
            return cache[id(fe)]

        actions = self.actor.action_from_features(feats(self.actor))
        out = {}
        for q in quantities:
            critic = self.critic if q == "distance" else self.cost_critic
            out[q] = critic.expected(critic.logits_from_features(feats(critic), actions))
        return out

    @th.inference_mode()
    def values(self, obs: Any, goals: Any, quantities: Sequence[str] = ("distance", "cost"),
               aggregate: str = "max") -> Dict[str, np.ndarray]:
        """Elementwise distance (steps) and/or cumulative cost from ``obs[i]`` to ``goals[i]``.

        ``obs`` and ``goals`` are raw observations: one of shape ``obs_shape`` each, or batches
        ``(N, *obs_shape)`` of equal length. Returns arrays of shape ``(N,)`` (a 0-d array for
        a single pair), or ``(E, N)`` with ``aggregate="none"``.
        """
        self._check_quantities(quantities)
        o, single_o = self._as_batch(obs, "obs")
        g, single_g = self._as_batch(goals, "goal")
        if o.shape[0] != g.shape[0]:
            raise ValueError(f"obs and goal batches must have the same length, got {o.shape[0]} and {g.shape[0]}")
        vals = self._pair_values(o, g, quantities)
        out = {}
        for q, v in vals.items():
            a = aggregate_ensemble(v, aggregate).cpu().numpy()
            out[q] = a[..., 0] if (single_o and single_g) else a
        return out

    @staticmethod
    def _check_quantities(quantities: Sequence[str]) -> None:
        bad = [q for q in quantities if q not in ("distance", "cost")]
        if bad or not quantities:
            raise ValueError(f"quantities must be a non-empty subset of ('distance', 'cost'), got {list(quantities)!r}")

    def _extractors(self) -> List[GoalPairExtractor]:
        """The distinct encoders that :meth:`pairwise` reads (one with a shared encoder)."""
        out: Dict[int, GoalPairExtractor] = {}
        for net in (self.actor, self.critic, self.cost_critic):
            out.setdefault(id(net.features_extractor), cast(GoalPairExtractor, net.features_extractor))
        return list(out.values())

    @th.inference_mode()
    def encode_observations(self, obs: Any) -> EncodedObservations:
        """Encode a batch of raw observations ``(N, *obs_shape)`` once for later :meth:`pairwise` calls."""
        x, single = self._as_batch(obs, "obs")
        if single:
            raise ValueError(f"encode_observations takes a batch (N, *{tuple(x.shape[1:])}), got one observation")
        return EncodedObservations(self, {id(fe): encode_chunked(fe, x) for fe in self._extractors()}, x.shape[0])

    def _pair_input(self, x: Any, what: str) -> Union[th.Tensor, EncodedObservations]:
        if isinstance(x, EncodedObservations):
            if x.policy is not self:
                raise ValueError(f"{what} was encoded by another policy")
            return x
        return self._as_batch(x, what)[0]

    @th.inference_mode()
    def pairwise(
        self,
        obs_a: Any,
        obs_b: Any,
        quantities: Sequence[str] = ("distance", "cost"),
        aggregate: str = "max",
        chunk_size: int = 2048,
        progress: Optional[bool] = None,
        within: Optional[float] = None,
    ) -> Dict[str, np.ndarray]:
        """Distance and/or cost from every ``obs_a[i]`` to every ``obs_b[j]``: ``(N, M)`` float32 arrays.

        ``obs_a`` ``(N, *obs_shape)`` and ``obs_b`` ``(M, *obs_shape)`` are raw observations
        (``obs_b`` used as goals), or :class:`EncodedObservations` from
        :meth:`encode_observations`. Each observation is encoded once per network and its
        first-layer product computed once; a pair then costs a broadcast sum and the remaining
        small layers. The actor's action for a pair is computed once and shared by both
        critics. Pairs are processed in blocks of about ``chunk_size`` (memory stays bounded
        and the working set stays in cache), without gradients. With ``aggregate="none"`` the
        arrays are ``(E, N, M)``. ``progress``: a ``tqdm`` bar over the blocks: ``None`` shows
        it on a terminal once the build has run 2 s (short builds never show one), ``True``
        always, ``False`` never.

        ``within`` (only with ``aggregate="max"`` and the distance among ``quantities``): the
        values are exact only for the pairs whose distance is below ``within``. Every pair is
        first scored by one member of the distance ensemble, a lower bound of the ensemble's
        maximum; a pair whose bound is ``>= within`` keeps that bound as its distance and an
        infinite cost, and only the other pairs are scored by every member. A planner that
        keeps edges shorter than ``d_max`` needs no more, and attaching new observations to a
        graph then costs about a third (most pairs are far apart).
        """
        self._check_quantities(quantities)
        if aggregate not in AGGREGATES:
            raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")
        if within is not None and (aggregate != "max" or "distance" not in quantities):
            raise ValueError("within needs aggregate='max' and the distance among the quantities (one member's "
                             f"distance bounds only the maximum), got aggregate={aggregate!r}, "
                             f"quantities={quantities!r}")
        if int(chunk_size) < 1:
            raise ValueError(f"chunk_size must be >= 1, got {chunk_size!r}")
        n, m, critics, actor_parts, critic_parts = self._pair_parts(obs_a, obs_b, quantities)
        out = {q: np.empty((n, m) if aggregate != "none" else (c.n_members, n, m), dtype=np.float32)
               for q, c in critics.items()}
        if n == 0 or m == 0:
            return out
        views = {q: th.from_numpy(v) for q, v in out.items()}
        cols = min(m, int(chunk_size))
        rows = max(1, int(chunk_size) // max(cols, 1))
        bar = _pair_progress(n * m, progress)
        for j0 in range(0, m, cols):
            j1 = min(m, j0 + cols)
            for i0 in range(0, n, rows):
                i1 = min(n, i0 + rows)
                if bar is not None:
                    bar.update((i1 - i0) * (j1 - j0))
                actions = th.tanh(pair_head(self.actor.mu, actor_parts, i0, i1, j0, j1))  # (1, P, A)
                if within is not None:
                    self._pairs_within(views, critics, critic_parts, actions, (i0, i1, j0, j1), float(within))
                    continue
                for q, c in critics.items():
                    v = c.expected(pair_head(c.head, critic_parts[q], i0, i1, j0, j1, actions))  # (E, P)
                    v = aggregate_ensemble(v, aggregate)
                    if aggregate == "none":
                        views[q][:, i0:i1, j0:j1] = v.reshape(c.n_members, i1 - i0, j1 - j0)
                    else:
                        views[q][i0:i1, j0:j1] = v.reshape(i1 - i0, j1 - j0)
        if bar is not None:
            bar.close()
        return out

    def _pair_parts(self, obs_a: Any, obs_b: Any, quantities: Sequence[str]):
        """What :meth:`pairwise` and :meth:`pairwise_at` share: ``(n, m, critics, actor_parts,
        critic_parts)``, each observation encoded once per encoder and its first-layer products."""
        a, b = self._pair_input(obs_a, "obs_a"), self._pair_input(obs_b, "obs_b")
        critics = {q: (self.critic if q == "distance" else self.cost_critic) for q in quantities}
        codes: Dict[int, Tuple[th.Tensor, th.Tensor]] = {}  # a shared encoder encodes once

        def code(fe: GoalPairExtractor, x: Union[th.Tensor, EncodedObservations]) -> th.Tensor:
            return x.codes[id(fe)] if isinstance(x, EncodedObservations) else encode_chunked(fe, x)

        def encoded(fe: GoalPairExtractor) -> Tuple[th.Tensor, th.Tensor]:
            if id(fe) not in codes:
                codes[id(fe)] = (code(fe, a), code(fe, b))
            return codes[id(fe)]

        code_a, code_b = encoded(self.actor.features_extractor)
        actor_parts = first_layer_products((self.actor.norm(code_a), self.actor.norm(code_b)), self.actor.mu)
        critic_parts = {q: first_layer_products(encoded(c.features_extractor), c.head) for q, c in critics.items()}
        return len(a), len(b), critics, actor_parts, critic_parts

    @th.inference_mode()
    def pairwise_at(
        self,
        obs_a: Any,
        obs_b: Any,
        rows: np.ndarray,
        cols: np.ndarray,
        quantities: Sequence[str] = ("distance", "cost"),
        chunk_size: int = 8192,
        within: Optional[float] = None,
    ) -> Dict[str, np.ndarray]:
        """:meth:`pairwise` (ensemble maximum) of the listed pairs only: ``obs_a[rows[p]]`` to
        ``obs_b[cols[p]]``, as float32 arrays of ``len(rows)`` values. ``within`` as for
        :meth:`pairwise`: exact only below it (a pair one distance member puts at ``within`` or
        beyond keeps that member's distance and an infinite cost). Where a cheap bound rules most
        pairs out (far apart on a large map), this scores the few that are left."""
        self._check_quantities(quantities)
        if within is not None and "distance" not in quantities:
            raise ValueError(f"within needs the distance among the quantities, got {quantities!r}")
        r = np.asarray(rows, dtype=np.int64).ravel()
        c = np.asarray(cols, dtype=np.int64).ravel()
        if r.shape != c.shape:
            raise ValueError(f"rows and cols must have the same length, got {r.shape} and {c.shape}")
        n, m, critics, actor_parts, critic_parts = self._pair_parts(obs_a, obs_b, quantities)
        if len(r) and (r.min() < 0 or r.max() >= n or c.min() < 0 or c.max() >= m):
            raise ValueError(f"pair indices out of range for {n} x {m} observations")
        out = {q: np.empty(len(r), dtype=np.float32) for q in critics}
        step = max(1, int(chunk_size))
        for p0 in range(0, len(r), step):
            rr, cc = th.from_numpy(r[p0:p0 + step]), th.from_numpy(c[p0:p0 + step])
            actions = th.tanh(pair_head_at(self.actor.mu, actor_parts, rr, cc))
            keep = th.arange(len(rr))
            if within is not None:
                dist = critics["distance"]
                bound = dist.expected(pair_head_at(dist.head, critic_parts["distance"], rr, cc, actions,
                                                   slice(0, 1)))[0]
                out["distance"][p0:p0 + len(rr)] = bound.numpy()
                if "cost" in out:
                    out["cost"][p0:p0 + len(rr)] = math.inf
                keep = th.nonzero(bound < within).squeeze(1)
                if keep.numel() == 0:
                    continue
            for q, crit in critics.items():
                v = crit.expected(pair_head_at(crit.head, critic_parts[q], rr[keep], cc[keep], actions[:, keep]))
                out[q][p0 + keep.numpy()] = aggregate_ensemble(v, "max").numpy()
        return out

    @staticmethod
    def _pairs_within(views: Dict[str, th.Tensor], critics: Dict[str, CategoricalCritic], parts, actions: th.Tensor,
                      block: Tuple[int, int, int, int], within: float) -> None:
        """Fill one block of :meth:`pairwise` with ``within`` (see there): a lower bound from one
        distance member everywhere, every member where that bound is below ``within``."""
        i0, i1, j0, j1 = block
        dist = critics["distance"]
        bound = dist.expected(pair_head(dist.head, parts["distance"], i0, i1, j0, j1, actions, slice(0, 1)))[0]
        views["distance"][i0:i1, j0:j1] = bound.view(i1 - i0, j1 - j0)
        if "cost" in views:
            views["cost"][i0:i1, j0:j1] = math.inf
        near = th.nonzero(bound < within).squeeze(1)
        if near.numel() == 0:
            return
        rows, cols = i0 + near // (j1 - j0), j0 + near % (j1 - j0)
        for q, c in critics.items():
            v = c.expected(pair_head_at(c.head, parts[q], rows, cols, actions[:, near]))
            views[q][rows, cols] = aggregate_ensemble(v, "max")


def _pair_progress(total: int, progress: Optional[bool]):
    """A ``tqdm`` bar over ``total`` pairs, or ``None`` for ``progress=False`` (see ``pairwise``)."""
    if progress is False:
        return None
    from tqdm.auto import tqdm

    if progress is None:  # only on a terminal, and only once the build has taken 2 s
        return tqdm(total=total, unit="pair", unit_scale=True, desc="pairwise", delay=2.0, disable=None,
                    mininterval=0.5, leave=False)
    return tqdm(total=total, unit="pair", unit_scale=True, desc="pairwise", mininterval=0.5)


MultiInputPolicy = SafeGoalPolicy

__all__ = ["EncodedObservations", "MultiInputPolicy", "SafeGoalPolicy"]
