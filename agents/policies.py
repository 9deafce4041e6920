"""Networks of the goal-conditioned safe agent: encoders, actor, ensembles of categorical critics.

Layout (after Stable-Baselines3's ``td3/policies.py``): a :class:`GoalActor` and two
:class:`CategoricalCritic` ensembles (distance and cost), each with its own
:class:`GoalPairExtractor`, plus target copies, gathered in :class:`SafeGoalPolicy`.

The extractor encodes the ``observation`` and the ``desired_goal`` with the **same** encoder
(an MLP for vectors, :class:`PanoramaEncoder` for stacks of images) and concatenates the two
codes. Every head is an MLP whose first layer is linear in ``[code(obs), code(goal), action]``.
That makes the ``N x M`` matrices a planner needs cheap: the codes of the ``N + M``
observations and their first-layer products are computed once, and a pair only costs a
broadcast sum plus the remaining small layers (:meth:`SafeGoalPolicy.pairwise`).
"""
from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Type, Union, cast

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel, BasePolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from .buffers import check_goal_space
from .distributional import cost_support, distance_support

#: Ways to combine the members of an ensemble: pessimistic (max), mean, optimistic (min), or
#: ``"none"`` to return every member (ensemble axis first).
AGGREGATES = ("max", "mean", "min", "none")


# --------------------------------------------------------------------------- encoders
def is_image_space(space: spaces.Space) -> bool:
    """Whether observations of ``space`` are images (a ``Box`` of three or more axes)."""
    return isinstance(space, spaces.Box) and len(space.shape) >= 3


class MlpEncoder(nn.Module):
    """An MLP for vector observations: ``obs -> code``."""

    def __init__(self, input_dim: int, net_arch: Sequence[int] = (64, 64),
                 activation_fn: Type[nn.Module] = nn.ReLU) -> None:
        super().__init__()
        if not net_arch:
            raise ValueError("the MLP encoder needs at least one layer, got net_arch=[]")
        layers: List[nn.Module] = []
        last = input_dim
        for width in net_arch:
            layers += [nn.Linear(last, int(width)), activation_fn()]
            last = int(width)
        self.net = nn.Sequential(*layers)
        self.output_dim = last

    def forward(self, x: th.Tensor) -> th.Tensor:
        return self.net(x.float().flatten(1))


class PanoramaEncoder(nn.Module):
    """The paper's image encoder: ``Conv(16, 8, 4) + Conv(32, 4, 4) + FC(256)``.

    Input: a batch of panoramas of shape ``(B, views, H, W, C)`` (channels last, e.g.
    ``(4, 32, 32, 4)``: four RGB-D views) or single images ``(B, H, W, C)``. Each view goes
    through the same convolutions (``(filters, kernel, stride)`` per layer, no padding); the
    flattened views are concatenated and mapped by one fully connected layer. ``uint8``
    inputs are scaled to ``[0, 1]``.

    Two exact shortcuts make it several times cheaper than a plain ``nn.Conv2d`` stack on a
    CPU (the parameters are the ``nn.Conv2d`` ones, so outputs and checkpoints are the same):

    - only the pixels inside the stack's receptive field are read. Without padding, the last
      rows and columns a strided stack cannot reach never influence the output (the paper's
      layers on 32 x 32 views read the top-left 20 x 20 pixels of each view);
    - where the first convolution has few output positions per view (at most
      ``PATCH_PRODUCT_MAX_POSITIONS``: the paper's 4 x 4 on its 20 x 20 crop), it runs as one
      matrix product over strided patches of the channels-last ``uint8`` input (no permute, no
      float copy of the unread pixels), and a later layer whose kernel covers its whole input
      runs as a linear layer. With more positions (an encoder that reads a whole 32 x 32 view
      has 7 x 7) the patch copy costs more than it saves, and the cropped views go through
      ``nn.Conv2d`` (measured on one thread, forward and backward over 128 panoramas: 48 ms as
      patches, 25 ms as ``nn.Conv2d``).
    """

    #: largest first-layer output map (positions per view) computed as a patch product
    PATCH_PRODUCT_MAX_POSITIONS = 16

    def __init__(
        self,
        obs_shape: Tuple[int, ...],
        features_dim: int = 256,
        conv_layers: Sequence[Tuple[int, int, int]] = ((16, 8, 4), (32, 4, 4)),
        scale: float = 1.0 / 255.0,
    ) -> None:
        super().__init__()
        if len(obs_shape) not in (3, 4):
            raise ValueError(f"PanoramaEncoder expects (views, H, W, C) or (H, W, C) observations, "
                             f"got shape {obs_shape}")
        if not conv_layers:
            raise ValueError("PanoramaEncoder needs at least one convolution, got conv_layers=[]")
        self.obs_shape = tuple(int(s) for s in obs_shape)
        views, h, w, c = (1, *self.obs_shape) if len(obs_shape) == 3 else self.obs_shape
        self.views, self.scale = views, float(scale)
        layers: List[nn.Module] = []
        sizes: List[Tuple[int, int]] = []  # feature-map size after each layer
        in_ch = c
        for filters, kernel, stride in conv_layers:
            if kernel > min(h, w):
                raise ValueError(f"conv kernel {kernel} is larger than the {h}x{w} feature map "
                                 f"of a {obs_shape} observation")
            layers += [nn.Conv2d(in_ch, int(filters), int(kernel), stride=int(stride)), nn.ReLU()]
            in_ch = int(filters)
            h, w = (h - kernel) // stride + 1, (w - kernel) // stride + 1
            sizes.append((h, w))
        self.cnn = nn.Sequential(*layers, nn.Flatten())
        self.fc = nn.Sequential(nn.Linear(views * in_ch * h * w, int(features_dim)), nn.ReLU())
        self.output_dim = int(features_dim)
        self._convs = [m for m in layers if isinstance(m, nn.Conv2d)]
        # Receptive field, from the last layer back: the part of each feature map (and of the
        # input) that later layers read; the rest never influences the output.
        used = [sizes[-1]]
        for conv in reversed(self._convs):
            k, s = conv.kernel_size[0], conv.stride[0]
            used.insert(0, ((used[0][0] - 1) * s + k, (used[0][1] - 1) * s + k))
        self.read_size: Tuple[int, int] = used[0]
        self._sizes = used[1:]  # the output size of each layer on the read part

    def forward(self, x: th.Tensor) -> th.Tensor:
        b = x.shape[0]
        rh, rw = self.read_size
        x = x.reshape(b * self.views, *x.shape[-3:])[:, :rh, :rw, :]  # (N, H', W', C), channels last
        oh, ow = self._sizes[0]
        if oh * ow > self.PATCH_PRODUCT_MAX_POSITIONS:
            h = x.permute(0, 3, 1, 2).to(th.float32)
            if x.dtype == th.uint8 and self.scale != 1.0:
                h = h * self.scale
            return self.fc(self.cnn(h).reshape(b, -1))
        first = self._convs[0]
        uint8 = x.dtype == th.uint8
        k, s = first.kernel_size[0], first.stride[0]
        n, _, _, c = x.shape
        x = x.to(th.float32).contiguous()  # (a uint8 input is scaled through the weight below)
        st = x.stride()
        patches = x.as_strided((n, oh, ow, k, k, c), (st[0], s * st[1], s * st[2], st[1], st[2], st[3]))
        patches = patches.reshape(n * oh * ow, k * k * c)
        weight = first.weight.permute(0, 2, 3, 1).reshape(first.out_channels, k * k * c)
        if uint8 and self.scale != 1.0:
            weight = weight * self.scale
        h = th.relu(th.addmm(_bias(first), patches, weight.t())).view(n, oh, ow, first.out_channels)
        for conv in self._convs[1:]:
            kh, kw = conv.kernel_size
            if (kh, kw) == tuple(h.shape[1:3]):  # the kernel covers the map: a linear layer
                wt = conv.weight.permute(0, 2, 3, 1).reshape(conv.out_channels, -1)
                h = th.relu(th.addmm(_bias(conv), h.reshape(n, -1), wt.t())).view(n, 1, 1, conv.out_channels)
            else:
                h = th.relu(conv(h.permute(0, 3, 1, 2))).permute(0, 2, 3, 1)
        # flatten in the (C, H, W) order of nn.Flatten on NCHW maps, as the FC layer expects
        h = h.permute(0, 3, 1, 2).reshape(b, -1)
        return self.fc(h)

    def reference_forward(self, x: th.Tensor) -> th.Tensor:
        """The same function as a plain ``nn.Conv2d`` stack over the full views (for tests)."""
        b = x.shape[0]
        x = x.float() * self.scale if x.dtype == th.uint8 else x.float()
        x = x.reshape(b * self.views, *x.shape[-3:]).permute(0, 3, 1, 2)
        return self.fc(self.cnn(x).reshape(b, -1))


class GoalPairExtractor(BaseFeaturesExtractor):
    """Encodes ``observation`` and ``desired_goal`` with one shared encoder; returns both codes.

    Args:
        observation_space: a goal-conditioned ``Dict`` space.
        encoder: ``"auto"`` (CNN for image observations, MLP otherwise), ``"mlp"`` or ``"cnn"``.
        net_arch: hidden widths of the MLP encoder.
        features_dim: code size of the CNN encoder.
        conv_layers: ``(filters, kernel, stride)`` of the CNN encoder.
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        encoder: str = "auto",
        net_arch: Sequence[int] = (64, 64),
        features_dim: int = 256,
        conv_layers: Sequence[Tuple[int, int, int]] = ((16, 8, 4), (32, 4, 4)),
    ) -> None:
        check_goal_space(observation_space)
        obs_space, goal_space = observation_space["observation"], observation_space["desired_goal"]
        assert obs_space.shape is not None  # check_goal_space: Box observations
        if obs_space.shape != goal_space.shape:
            raise ValueError("observation and desired_goal must share one encoder, so they need the same shape; got "
                             f"{obs_space.shape} and {goal_space.shape}")
        if encoder == "auto":
            encoder = "cnn" if is_image_space(obs_space) else "mlp"
        if encoder == "cnn":
            scale = 1.0 / 255.0 if obs_space.dtype == np.uint8 else 1.0
            net: Union[PanoramaEncoder, MlpEncoder] = PanoramaEncoder(
                obs_space.shape, features_dim=features_dim, conv_layers=conv_layers, scale=scale)
        elif encoder == "mlp":
            net = MlpEncoder(int(np.prod(obs_space.shape)), net_arch)
        else:
            raise ValueError(f"encoder must be 'auto', 'mlp' or 'cnn', got {encoder!r}")
        code_dim = int(net.output_dim)
        super().__init__(observation_space, features_dim=2 * code_dim)
        self.encoder = net
        self.code_dim = code_dim

    def encode(self, x: th.Tensor) -> th.Tensor:
        """Codes of a batch of raw observations (or goals): ``(B, *obs_shape) -> (B, code_dim)``."""
        return self.encoder(x)

    def forward(self, observations: Dict[str, th.Tensor]) -> th.Tensor:
        obs, goal = observations["observation"], observations["desired_goal"]
        codes = self.encoder(th.cat([obs, goal], 0))
        return th.cat(codes.split([obs.shape[0], goal.shape[0]]), 1)


# --------------------------------------------------------------------------- ensemble MLPs
class EnsembleLinear(nn.Module):
    """``E`` independent linear layers applied as one batched matmul: ``(E, B, in) -> (E, B, out)``."""

    def __init__(self, n_members: int, in_features: int, out_features: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(th.empty(n_members, in_features, out_features))
        self.bias = nn.Parameter(th.empty(n_members, 1, out_features))
        bound = 1.0 / math.sqrt(in_features)  # the default initialisation of nn.Linear
        nn.init.uniform_(self.weight, -bound, bound)
        nn.init.uniform_(self.bias, -bound, bound)

    def forward(self, x: th.Tensor) -> th.Tensor:
        return th.baddbmm(self.bias, x, self.weight)


class EnsembleHead(nn.Module):
    """``E`` MLPs ``in_dim -> hidden... -> out_dim`` evaluated together."""

    def __init__(self, n_members: int, in_dim: int, net_arch: Sequence[int], out_dim: int,
                 activation_fn: Type[nn.Module] = nn.ReLU) -> None:
        super().__init__()
        if n_members < 1:
            raise ValueError(f"an ensemble needs at least one member, got {n_members}")
        if not net_arch:
            raise ValueError("a head needs at least one hidden layer, got net_arch=[]")
        dims = [in_dim, *[int(w) for w in net_arch], out_dim]
        self.n_members = n_members
        self.layers = nn.ModuleList(EnsembleLinear(n_members, dims[i], dims[i + 1]) for i in range(len(dims) - 1))
        self.act = activation_fn()

    def forward(self, x: th.Tensor) -> th.Tensor:
        """``(B, in)`` (shared by every member) or ``(E, B, in)`` -> ``(E, B, out)``."""
        if x.dim() == 2:
            x = x.unsqueeze(0).expand(self.n_members, -1, -1)
        return self.from_first_preactivation(self.layers[0](x))

    def from_first_preactivation(self, h: th.Tensor) -> th.Tensor:
        """Finish the forward pass from the first layer's pre-activation ``(E, B, hidden0)``."""
        for layer in self.layers[1:]:
            h = layer(self.act(h))
        return h

    def linear(self, i: int) -> EnsembleLinear:
        """The ``i``-th layer (typed)."""
        return cast(EnsembleLinear, self.layers[i])

    def first_layer_parts(self, sizes: Sequence[int]) -> Tuple[List[th.Tensor], th.Tensor]:
        """The first layer's weight split into row blocks of ``sizes`` (``(E, size, hidden0)`` each) and its bias."""
        first = self.linear(0)
        return list(first.weight.split(list(sizes), dim=1)), first.bias


# --------------------------------------------------------------------------- actor / critics
class GoalActor(BasePolicy):
    """Deterministic goal-conditioned actor ``pi(obs, goal) -> action in [-1, 1]^A``.

    ``input_norm`` puts a LayerNorm on the features before the MLP (after the actor trunk of
    DrQ-v2): features of a shared image encoder, trained by the critics alone, grow in scale,
    and an actor fed them directly drives ``tanh`` into saturation, where it stops learning.
    The observation's and the goal's codes (the two halves of the features) are normalised
    separately by one LayerNorm, so the first layer stays linear in each code and the
    planner's pairwise matrices keep their one-encoding-per-node shortcut.
    """

    features_extractor: GoalPairExtractor
    optimizer: th.optim.Optimizer

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, net_arch: Sequence[int],
                 features_extractor: GoalPairExtractor, features_dim: int,
                 activation_fn: Type[nn.Module] = nn.ReLU, normalize_images: bool = False,
                 input_norm: bool = False) -> None:
        super().__init__(observation_space, action_space, features_extractor=features_extractor,
                         normalize_images=normalize_images, squash_output=True)
        self.net_arch = list(net_arch)
        self.features_dim = features_dim
        self.activation_fn = activation_fn
        self.action_dim = int(np.prod(action_space.shape))
        self.input_norm = bool(input_norm)
        if self.input_norm and features_dim % 2:
            raise ValueError(f"input_norm needs features made of two codes of equal size, got {features_dim}")
        self.norm = nn.LayerNorm(features_dim // 2) if self.input_norm else nn.Identity()
        self.mu = EnsembleHead(1, features_dim, net_arch, self.action_dim, activation_fn)

    def _get_constructor_parameters(self) -> Dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(dict(net_arch=self.net_arch, features_dim=self.features_dim, activation_fn=self.activation_fn,
                         features_extractor=self.features_extractor, input_norm=self.input_norm))
        return data

    def extract_features(self, obs: PyTorchObs,
                         features_extractor: Optional[BaseFeaturesExtractor] = None) -> th.Tensor:
        return (features_extractor or self.features_extractor)(obs)

    def normalize_features(self, features: th.Tensor) -> th.Tensor:
        """The MLP's input: ``[norm(code(obs)), norm(code(goal))]`` (identity without ``input_norm``)."""
        if not self.input_norm:
            return features
        return self.norm(features.unflatten(-1, (2, -1))).flatten(-2)

    def preactivation(self, features: th.Tensor) -> th.Tensor:
        """The action before ``tanh``."""
        return self.mu(self.normalize_features(features))[0]

    def action_from_features(self, features: th.Tensor) -> th.Tensor:
        return th.tanh(self.preactivation(features))

    def forward(self, obs: PyTorchObs) -> th.Tensor:
        return self.action_from_features(self.extract_features(obs))

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self(observation)


class CategoricalCritic(BaseModel):
    """An ensemble of categorical Q-functions ``Z(obs, action, goal)`` over a fixed support.

    ``forward`` returns logits of shape ``(n_members, B, n_bins)``; :meth:`expected` turns
    logits into the expected value per member (distance in steps, or cumulative cost).
    """

    features_extractor: GoalPairExtractor
    optimizer: th.optim.Optimizer
    support: th.Tensor

    def __init__(self, observation_space: spaces.Dict, action_space: spaces.Box, net_arch: Sequence[int],
                 features_extractor: GoalPairExtractor, features_dim: int, support: th.Tensor,
                 n_members: int = 3, activation_fn: Type[nn.Module] = nn.ReLU,
                 normalize_images: bool = False) -> None:
        super().__init__(observation_space, action_space, features_extractor=features_extractor,
                         normalize_images=normalize_images)
        self.action_dim = int(np.prod(action_space.shape))
        self.n_members = n_members
        self.head = EnsembleHead(n_members, features_dim + self.action_dim, net_arch, len(support), activation_fn)
        self.register_buffer("support", support.clone().float())

    def extract_features(self, obs: PyTorchObs,
                         features_extractor: Optional[BaseFeaturesExtractor] = None) -> th.Tensor:
        return (features_extractor or self.features_extractor)(obs)

    def logits_from_features(self, features: th.Tensor, actions: th.Tensor) -> th.Tensor:
        return self.head(th.cat([features, actions], dim=1))

    def forward(self, obs: PyTorchObs, actions: th.Tensor) -> th.Tensor:
        return self.logits_from_features(self.extract_features(obs), actions)

    def expected(self, logits: th.Tensor) -> th.Tensor:
        """Expected value of each member's distribution: ``(..., K) -> (...)``."""
        return th.softmax(logits, dim=-1) @ self.support


def aggregate_ensemble(values: th.Tensor, aggregate: str) -> th.Tensor:
    """Combine ensemble members (axis 0)."""
    if aggregate == "max":
        return values.max(0).values
    if aggregate == "mean":
        return values.mean(0)
    if aggregate == "min":
        return values.min(0).values
    if aggregate == "none":
        return values
    raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")


# --------------------------------------------------------------------------- the policy
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
        return EncodedObservations(self, {id(fe): _encode_chunked(fe, x) for fe in self._extractors()}, x.shape[0])

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
        """
        self._check_quantities(quantities)
        if aggregate not in AGGREGATES:
            raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")
        if int(chunk_size) < 1:
            raise ValueError(f"chunk_size must be >= 1, got {chunk_size!r}")
        a, b = self._pair_input(obs_a, "obs_a"), self._pair_input(obs_b, "obs_b")
        n, m = len(a), len(b)
        critics = {q: (self.critic if q == "distance" else self.cost_critic) for q in quantities}
        codes: Dict[int, Tuple[th.Tensor, th.Tensor]] = {}  # a shared encoder encodes once

        def code(fe: GoalPairExtractor, x: Union[th.Tensor, EncodedObservations]) -> th.Tensor:
            return x.codes[id(fe)] if isinstance(x, EncodedObservations) else _encode_chunked(fe, x)

        def encoded(fe: GoalPairExtractor) -> Tuple[th.Tensor, th.Tensor]:
            if id(fe) not in codes:
                codes[id(fe)] = (code(fe, a), code(fe, b))
            return codes[id(fe)]

        code_a, code_b = encoded(self.actor.features_extractor)
        actor_parts = _first_layer_products((self.actor.norm(code_a), self.actor.norm(code_b)), self.actor.mu)
        critic_parts = {q: _first_layer_products(encoded(c.features_extractor), c.head) for q, c in critics.items()}
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
                actions = th.tanh(_pair_head(self.actor.mu, actor_parts, i0, i1, j0, j1))  # (1, P, A)
                for q, c in critics.items():
                    v = c.expected(_pair_head(c.head, critic_parts[q], i0, i1, j0, j1, actions))  # (E, P)
                    v = aggregate_ensemble(v, aggregate)
                    if aggregate == "none":
                        views[q][:, i0:i1, j0:j1] = v.reshape(c.n_members, i1 - i0, j1 - j0)
                    else:
                        views[q][i0:i1, j0:j1] = v.reshape(i1 - i0, j1 - j0)
        if bar is not None:
            bar.close()
        return out


def _pair_progress(total: int, progress: Optional[bool]):
    """A ``tqdm`` bar over ``total`` pairs, or ``None`` for ``progress=False`` (see ``pairwise``)."""
    if progress is False:
        return None
    from tqdm.auto import tqdm

    if progress is None:  # only on a terminal, and only once the build has taken 2 s
        return tqdm(total=total, unit="pair", unit_scale=True, desc="pairwise", delay=2.0, disable=None,
                    mininterval=0.5, leave=False)
    return tqdm(total=total, unit="pair", unit_scale=True, desc="pairwise", mininterval=0.5)


def _encode_chunked(fe: GoalPairExtractor, x: th.Tensor, chunk: int = 1024) -> th.Tensor:
    """Codes of ``x`` in blocks of ``chunk`` observations (bounded memory for image batches)."""
    if x.shape[0] <= chunk:
        return fe.encode(x)
    return th.cat([fe.encode(x[i:i + chunk]) for i in range(0, x.shape[0], chunk)], 0)


def _first_layer_products(codes: Tuple[th.Tensor, th.Tensor], head: EnsembleHead):
    """First-layer pre-activations of the codes ``a`` as observations ``(E, N, H)`` and ``b`` as
    goals ``(E, M, H)`` (bias included), plus the action block of the weight (``None`` for the actor)."""
    code_a, code_b = codes
    d = code_a.shape[1]
    in_dim = head.linear(0).weight.shape[1]
    sizes = [d, d] + ([in_dim - 2 * d] if in_dim > 2 * d else [])
    (w_obs, w_goal, *w_act), bias = head.first_layer_parts(sizes)
    pre_a = th.matmul(code_a.unsqueeze(0), w_obs).contiguous()
    pre_b = th.baddbmm(bias, code_b.unsqueeze(0).expand(head.n_members, -1, -1), w_goal).contiguous()
    return pre_a, pre_b, (w_act[0] if w_act else None)


def _pair_head(head: EnsembleHead, parts, i0: int, i1: int, j0: int, j1: int,
               actions: Optional[th.Tensor] = None) -> th.Tensor:
    """Outputs ``(E, P, out)`` of ``head`` for the pairs ``[i0, i1) x [j0, j1)`` (row-major)."""
    pre_a, pre_b, w_act = parts
    e = head.n_members
    h = th.add(pre_a[:, i0:i1, None, :], pre_b[:, None, j0:j1, :]).view(e, (i1 - i0) * (j1 - j0), -1)
    if w_act is not None:
        assert actions is not None, "the critics' heads need the actions"
        h.baddbmm_(actions.expand(e, -1, -1), w_act)
    h = _activate_(h, head.act)
    n_layers = len(head.layers)
    for k in range(1, n_layers):
        layer = head.linear(k)
        h = th.baddbmm(layer.bias, h, layer.weight)
        if k < n_layers - 1:
            h = _activate_(h, head.act)
    return h


def _bias(conv: nn.Conv2d) -> th.Tensor:
    """The bias of a convolution built with one (every layer of :class:`PanoramaEncoder`)."""
    assert conv.bias is not None
    return conv.bias


def _activate_(h: th.Tensor, act: nn.Module) -> th.Tensor:
    """Apply ``act`` in place where it is a ReLU (no extra buffer), out of place otherwise."""
    return h.relu_() if isinstance(act, nn.ReLU) else act(h)


MultiInputPolicy = SafeGoalPolicy

__all__ = [
    "AGGREGATES",
    "aggregate_ensemble",
    "CategoricalCritic",
    "EnsembleHead",
    "EnsembleLinear",
    "GoalActor",
    "GoalPairExtractor",
    "MlpEncoder",
    "is_image_space",
    "MultiInputPolicy",
    "PanoramaEncoder",
    "SafeGoalPolicy",
]
