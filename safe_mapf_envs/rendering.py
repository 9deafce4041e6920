"""Top-down ``rgb_array`` views drawn with OpenCV (no pygame, no window needed).

The background (cost heat map and obstacles) is drawn once per renderer and copied for every
frame; agents, goals, trails, planned waypoints and collision markers are drawn on top.
"""
from __future__ import annotations

import warnings
from typing import Any, Optional, Sequence, Tuple, Union

import cv2
import numpy as np

from .cost import ObstacleField

#: Distinct agent colours (RGB), cycled for more agents.
PALETTE = np.array([
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
], dtype=np.uint8)


def agent_colour(i: int) -> tuple:
    """RGB colour of agent ``i``."""
    return tuple(int(c) for c in PALETTE[i % len(PALETTE)])


class TopDownRenderer:
    """Draws a world of obstacles seen from above.

    Args:
        field: obstacles, world size and cost function (the heat map shows the cost).
        image_size: length in pixels of the longer side of the image.
        agent_radius: drawn radius of agents, in world units.
    """

    def __init__(self, field: ObstacleField, image_size: int = 512, agent_radius: float = 0.5) -> None:
        self.field = field
        w, h = field.size
        self.scale = image_size / max(w, h)
        self.width = int(round(w * self.scale))
        self.height = int(round(h * self.scale))
        self.agent_radius = agent_radius
        self._background = self._draw_background()

    def _draw_background(self) -> np.ndarray:
        w, h = self.field.size
        xs = (np.arange(self.width) + 0.5) / self.scale
        ys = (np.arange(self.height) + 0.5) / self.scale
        gx, gy = np.meshgrid(xs, ys)
        cost = self.field.cost(np.stack([gx, gy], -1))
        level = np.clip(cost / 2.0, 0.0, 1.0)
        # white where safe, through yellow and orange to red where the cost is highest
        img = np.empty((self.height, self.width, 3), dtype=np.float64)
        img[..., 0] = 255.0
        img[..., 1] = 255.0 * (1.0 - 0.85 * level)
        img[..., 2] = 255.0 * (1.0 - level)
        img = img.astype(np.uint8)
        for x0, y0, x1, y1 in self.field.boxes:
            cv2.rectangle(img, self.px((x0, y0)), self.px((x1, y1)), (60, 60, 60), thickness=-1)
        cv2.rectangle(img, (0, 0), (self.width - 1, self.height - 1), (0, 0, 0), thickness=2)
        return img

    def px(self, point: Union[Sequence[float], np.ndarray]) -> Tuple[int, int]:
        """Pixel coordinates of a world point."""
        return (int(round(point[0] * self.scale)), int(round(point[1] * self.scale)))

    def render(
        self,
        positions: np.ndarray,
        goals: Optional[np.ndarray] = None,
        trails: Optional[Sequence[np.ndarray]] = None,
        waypoints: Optional[Sequence[Optional[np.ndarray]]] = None,
        collisions: Optional[Sequence[np.ndarray]] = None,
        parked: Optional[np.ndarray] = None,
    ) -> np.ndarray:
        """Draw one frame.

        Args:
            positions: agent centres, shape ``(N, 2)``.
            goals: goal positions, shape ``(N, 2)``.
            trails: per agent, the past centres ``(T, 2)``.
            waypoints: per agent, planned waypoints ``(K, 2)`` (or ``None``), drawn as a dashed
                route of small diamonds.
            collisions: points where agents touched, drawn as black crosses.
            parked: per agent, ``True`` if it has arrived (drawn with a black ring).

        Returns:
            An ``(H, W, 3)`` ``uint8`` RGB image.
        """
        img = self._background.copy()
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        r = max(2, int(round(self.agent_radius * self.scale)))
        if waypoints is not None:
            for i, wps in enumerate(waypoints):
                if wps is None or len(wps) == 0:
                    continue
                col = agent_colour(i)
                pts = [self.px(p) for p in np.asarray(wps).reshape(-1, 2)]
                for a, b in zip(pts[:-1], pts[1:]):
                    cv2.line(img, a, b, col, 1, cv2.LINE_AA)
                for p in pts:
                    d = max(3, r // 2)
                    poly = np.array([(p[0], p[1] - d), (p[0] + d, p[1]), (p[0], p[1] + d), (p[0] - d, p[1])], np.int32)
                    cv2.polylines(img, [poly], True, col, 1, cv2.LINE_AA)
        if trails is not None:
            for i, trail in enumerate(trails):
                path = np.asarray(trail).reshape(-1, 2)
                if len(path) > 1:
                    line = np.array([self.px(p) for p in path], np.int32)
                    cv2.polylines(img, [line], False, agent_colour(i), 2, cv2.LINE_AA)
        if goals is not None:
            for i, g in enumerate(np.asarray(goals).reshape(-1, 2)):
                c = self.px(g)
                d = r + 2
                cv2.line(img, (c[0] - d, c[1] - d), (c[0] + d, c[1] + d), agent_colour(i), 2, cv2.LINE_AA)
                cv2.line(img, (c[0] - d, c[1] + d), (c[0] + d, c[1] - d), agent_colour(i), 2, cv2.LINE_AA)
        for i, centre in enumerate(positions):
            c = self.px(centre)
            cv2.circle(img, c, r, agent_colour(i), -1, cv2.LINE_AA)
            ring = 2 if parked is not None and parked[i] else 1
            cv2.circle(img, c, r, (0, 0, 0), ring, cv2.LINE_AA)
        if collisions is not None:
            for point in collisions:
                c = self.px(point)
                cv2.drawMarker(img, c, (0, 0, 0), cv2.MARKER_TILTED_CROSS, 2 * r + 4, 2)
        return img


class HumanWindow:
    """Shows frames in a matplotlib window (``render_mode="human"``).

    OpenCV's headless build has no windows, so the human mode draws through matplotlib. It
    needs a display: without one (no ``DISPLAY``/``WAYLAND_DISPLAY``) the window warns once,
    naming the problem, and shows nothing, so that generic tools which try every render mode
    (Gymnasium's ``check_env``) run on headless machines.
    """

    def __init__(self, title: str) -> None:
        import os

        self.headless = os.name != "nt" and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        if self.headless:
            warnings.warn('render_mode="human" needs a display (DISPLAY is not set): frames are not shown; '
                          'use "rgb_array" to get them as images', UserWarning, stacklevel=4)
            return
        import matplotlib.pyplot as plt

        plt.ion()
        self._plt = plt
        # a figure of its own per window (a figure looked up by title would be shared, and
        # pyplot refuses to create a second one with the same title)
        self._fig, ax = plt.subplots()
        if self._fig.canvas.manager is not None:
            self._fig.canvas.manager.set_window_title(title)
        ax.set_axis_off()
        self._ax = ax
        self._im: Any = None  # the AxesImage, made on the first frame

    def show(self, frame: np.ndarray) -> None:
        if self.headless:
            return
        if self._im is None:
            self._im = self._ax.imshow(frame)
        else:
            self._im.set_data(frame)
        self._fig.canvas.draw_idle()
        self._plt.pause(0.001)

    def close(self) -> None:
        if not self.headless:
            self._plt.close(self._fig)


__all__ = ["HumanWindow", "PALETTE", "TopDownRenderer", "agent_colour"]
