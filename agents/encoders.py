"""Encoders of the goal-conditioned agent: observations (vectors or panoramas) to codes.

:class:`GoalPairExtractor` encodes the ``observation`` and the ``desired_goal`` with the
**same** encoder (an MLP for vectors, :class:`PanoramaEncoder` for stacks of images) and
concatenates the two codes; actor and critics read these features.
"""
from __future__ import annotations

from typing import Dict, List, Sequence, Tuple, Type, Union

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from .buffers import check_goal_space


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


def encode_chunked(fe: GoalPairExtractor, x: th.Tensor, chunk: int = 1024) -> th.Tensor:
    """Codes of ``x`` in blocks of ``chunk`` observations (bounded memory for image batches)."""
    if x.shape[0] <= chunk:
        return fe.encode(x)
    return th.cat([fe.encode(x[i:i + chunk]) for i in range(0, x.shape[0], chunk)], 0)


def _bias(conv: nn.Conv2d) -> th.Tensor:
    """The bias of a convolution built with one (every layer of :class:`PanoramaEncoder`)."""
    assert conv.bias is not None
    return conv.bias


__all__ = ["GoalPairExtractor", "MlpEncoder", "PanoramaEncoder", "encode_chunked", "is_image_space"]
