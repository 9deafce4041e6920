"""The pymunk collision world shared by the single- and multi-agent environments.

Agents are circle bodies that do not rotate; obstacles are static boxes; four thick boxes
just outside the world confine the agents. An action is the intended displacement over one
environment step. It is applied as a velocity over ``substeps`` physics sub-steps, and the
velocity is set again before every sub-step, so an agent that hits a wall slides along it
instead of bouncing, and no sub-step moves an agent further than about a third of its radius
(no tunnelling).

A new :class:`pymunk.Space` is built for every episode: reusing a space across resets is not
deterministic, rebuilding it is (same start + same actions = same trajectory, bit for bit).
"""
from __future__ import annotations

from typing import List, Sequence, Set, Tuple

import numpy as np
import pymunk

Box = Tuple[float, float, float, float]

_AGENT_TYPE = 1
_WALL_THICKNESS = 10.0


class World:
    """A pymunk space holding static boxes and ``len(positions)`` circular agents.

    Args:
        size: world extent ``(width, height)``.
        boxes: static obstacles ``(x0, y0, x1, y1)``.
        positions: initial agent centres, shape ``(N, 2)``.
        agent_radius: radius of every agent.
        substeps: physics sub-steps per environment step.
    """

    def __init__(
        self,
        size: Tuple[float, float],
        boxes: Sequence[Box],
        positions: np.ndarray,
        agent_radius: float,
        substeps: int,
    ) -> None:
        self.size = (float(size[0]), float(size[1]))
        self.agent_radius = float(agent_radius)
        self.substeps = int(substeps)
        self._dt = 1.0 / self.substeps
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.collision_slop = 0.005 * self.agent_radius
        space.collision_bias = 0.0  # resolve overlap immediately: contacts are hard
        space.iterations = 10
        self.space = space
        w, h = self.size
        t = _WALL_THICKNESS
        walls = list(boxes) + [(-t, -t, w + t, 0.0), (-t, h, w + t, h + t), (-t, 0.0, 0.0, h), (w, 0.0, w + t, h)]
        for x0, y0, x1, y1 in walls:
            shape = pymunk.Poly(space.static_body, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
            shape.elasticity = 0.0
            shape.friction = 0.0
            space.add(shape)
        self.bodies: List[pymunk.Body] = []
        for i, (x, y) in enumerate(np.asarray(positions, dtype=np.float64).reshape(-1, 2)):
            body = pymunk.Body(1.0, float("inf"))
            body.position = (float(x), float(y))
            shape = pymunk.Circle(body, self.agent_radius)
            shape.elasticity = 0.0
            shape.friction = 0.0
            shape.collision_type = _AGENT_TYPE
            shape.agent_index = i  # type: ignore[attr-defined]
            space.add(body, shape)
            self.bodies.append(body)
        self.parked = np.zeros(len(self.bodies), dtype=bool)
        self._contacts: Set[Tuple[int, int]] = set()
        if len(self.bodies) > 1:
            space.on_collision(_AGENT_TYPE, _AGENT_TYPE, pre_solve=self._record_contact)

    def _record_contact(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        a, b = arbiter.shapes
        i, j = a.agent_index, b.agent_index  # type: ignore[attr-defined]
        self._contacts.add((i, j) if i < j else (j, i))

    @property
    def n_agents(self) -> int:
        return len(self.bodies)

    def positions(self) -> np.ndarray:
        """Current agent centres, shape ``(N, 2)``."""
        return np.array([tuple(b.position) for b in self.bodies], dtype=np.float64).reshape(-1, 2)

    def park(self, index: int) -> None:
        """Freeze agent ``index`` where it stands: it becomes an immovable obstacle for the others."""
        body = self.bodies[index]
        body.velocity = (0.0, 0.0)
        body.body_type = pymunk.Body.KINEMATIC
        self.parked[index] = True

    def step(self, displacements: np.ndarray) -> Tuple[np.ndarray, Set[Tuple[int, int]]]:
        """Advance one environment step.

        Args:
            displacements: intended displacement of every agent, shape ``(N, 2)``; rows of
                parked agents are ignored.

        Returns:
            ``(trace, contacts)``: agent centres after every sub-step, shape
            ``(substeps, N, 2)``, and the set of agent pairs ``(i, j)``, ``i < j``, that
            touched during the step.
        """
        vel = np.asarray(displacements, dtype=np.float64).reshape(-1, 2)
        n = len(self.bodies)
        trace = np.empty((self.substeps, n, 2), dtype=np.float64)
        self._contacts = set()
        moving = [(b, (float(v[0]), float(v[1]))) for b, v, p in zip(self.bodies, vel, self.parked) if not p]
        dt = self._dt
        step = self.space.step
        bodies = self.bodies
        for s in range(self.substeps):
            for body, v in moving:
                body.velocity = v
            step(dt)
            row = trace[s]
            for i, body in enumerate(bodies):
                row[i] = body.position
        # Contacts found in a sub-step are resolved at the start of the next one, so the
        # last sub-step may end slightly inside a wall: one settling step at rest pushes the
        # agents out before the final positions are read.
        for body, _ in moving:
            body.velocity = (0.0, 0.0)
        step(dt)
        row = trace[-1]
        for i, body in enumerate(bodies):
            row[i] = body.position
        for body, _ in moving:
            body.velocity = (0.0, 0.0)
        return trace, self._contacts


__all__ = ["World"]
