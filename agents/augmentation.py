"""Image augmentation for the panorama agents' updates (DrQ's random shift)."""
from __future__ import annotations

from typing import Optional

import torch as th


class RandomShift:
    """DrQ's random-shift augmentation for batches of image stacks ``(B, ..., H, W, C)``.

    Each sample is padded by ``pad`` pixels (edge values repeated) and cropped back to ``H x W``
    at a random offset, the same offset for all of a sample's views.
    """

    def __init__(self, pad: int = 2, generator: Optional[th.Generator] = None) -> None:
        self.pad = int(pad)
        self.generator = generator

    def __call__(self, x: th.Tensor) -> th.Tensor:
        if self.pad == 0:
            return x
        b, h, w = x.shape[0], x.shape[-3], x.shape[-2]
        p = self.pad
        rows = (th.arange(h + 2 * p) - p).clamp_(0, h - 1)  # edge padding by index
        cols = (th.arange(w + 2 * p) - p).clamp_(0, w - 1)
        padded = x.index_select(-3, rows).index_select(-2, cols)
        dy = th.randint(0, 2 * p + 1, (b,), generator=self.generator).tolist()
        dx = th.randint(0, 2 * p + 1, (b,), generator=self.generator).tolist()
        return th.stack([padded[i, ..., dy[i]:dy[i] + h, dx[i]:dx[i] + w, :] for i in range(b)])


__all__ = ["RandomShift"]
