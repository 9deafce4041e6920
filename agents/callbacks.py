"""Training callbacks of the agent: a progress bar that needs only ``tqdm``."""
from __future__ import annotations

from typing import Any

from stable_baselines3.common.callbacks import BaseCallback, ProgressBarCallback


class TqdmProgressBar(BaseCallback):
    """A plain ``tqdm`` progress bar over the environment steps of one ``learn`` call.

    Stable-Baselines3's own bar needs ``rich``; this one only needs ``tqdm``.
    """

    def __init__(self) -> None:
        super().__init__()
        self.pbar: Any = None  # a tqdm bar while training

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        self.pbar = tqdm(total=self.locals["total_timesteps"] - self.model.num_timesteps, unit="step",
                         dynamic_ncols=True, mininterval=1.0)

    def _on_step(self) -> bool:
        self.pbar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        if self.pbar is not None:
            self.pbar.close()


def _rich_available() -> bool:
    try:
        import rich  # noqa: F401
    except ImportError:
        return False
    return True


def progress_bar_callback() -> BaseCallback:
    """SB3's ``rich`` progress bar where ``rich`` is installed, else :class:`TqdmProgressBar`."""
    return ProgressBarCallback() if _rich_available() else TqdmProgressBar()


__all__ = ["TqdmProgressBar", "progress_bar_callback"]
