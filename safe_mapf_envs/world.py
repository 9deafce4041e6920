"""The pymunk collision world shared by the single- and multi-agent environments.

Agents are circle bodies that do not rotate; obstacles are static boxes; four thick boxes
just outside the world confine the agents. An action is the intended displacement over one
environment step. It is applied as a velocity over ``substeps`` physics sub-steps, and the
velocity is set again before every sub-step, so an agent that hits a wall slides along it
instead of bouncing, and no sub-step moves an agent further than about a third of its radius
(no tunnelling). Contacts are resolved at the start of the next physics step, so every
environment step ends with settling steps at rest that push agents out of walls and out of
each other (a crowd pushing into itself needs several) before the final positions are read.

A new :class:`pymunk.Space` is built for every episode of several agents: reusing such a space
across resets is not deterministic, rebuilding it is (same start + same actions = same
trajectory, bit for bit). A world of one agent restarts in place (:meth:`World.restart`), which
gives the same trajectories as a new space at a fraction of the cost.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple, Union

import numpy as np
import pymunk
from pymunk import batch as _batch  # batched body access (pymunk >= 6.6, a declared requirement)

from .cost import INDEX_MIN_BOXES, BoxIndex

_cp = pymunk.cp  # the Chipmunk library pymunk wraps
_CDATA = pymunk.ffi.CData  # cffi pointers

Box = Tuple[float, float, float, float]

_AGENT_TYPE = 1
_AGENT_GROUP = 1
_WALL_THICKNESS = 10.0
_BATCH_MIN_AGENTS = 4
_MAX_EXTRA_SETTLE = 30  # settling steps at most on top of the first (jammed crowds)
#: :meth:`World._wall_index` results by walls, agent radius and world size
_WALL_INDEXES: Dict[Tuple[Any, ...], BoxIndex] = {}


def _raw_handles(space: pymunk.Space, body: pymunk.Body) -> Optional[Tuple[Any, Any]]:
    """The Chipmunk pointers of ``space`` and ``body`` for :data:`pymunk.cp` calls, or ``None`` where
    this pymunk keeps them elsewhere (the public API is used then)."""
    sp, bd = getattr(space, "_space", None), getattr(body, "_body", None)
    if not (isinstance(sp, _CDATA) and isinstance(bd, _CDATA)):
        return None
    return sp, bd


class World:
    """A pymunk space holding static boxes and ``len(positions)`` circular agents.

    Args:
        size: world extent ``(width, height)``.
        boxes: static obstacles ``(x0, y0, x1, y1)``.
        positions: initial agent centres, shape ``(N, 2)``.
        agent_radius: radius of every agent.
        substeps: physics sub-steps per environment step.
        agent_collisions: ``False`` lets agents pass through each other (they still collide
            with walls and obstacles); no contacts between agents are then reported.
    """

    def __init__(
        self,
        size: Tuple[float, float],
        boxes: Sequence[Box],
        positions: np.ndarray,
        agent_radius: float,
        substeps: int,
        agent_collisions: bool = True,
    ) -> None:
        self.size = (float(size[0]), float(size[1]))
        self.agent_radius = float(agent_radius)
        self.substeps = int(substeps)
        self.agent_collisions = bool(agent_collisions)
        self._dt = 1.0 / self.substeps
        w, h = self.size
        t = _WALL_THICKNESS
        self._walls = list(boxes) + [(-t, -t, w + t, 0.0), (-t, h, w + t, h + t), (-t, 0.0, 0.0, h), (w, 0.0, w + t, h)]
        self._wall_lo = np.array([b[:2] for b in self._walls], dtype=np.float64)
        self._wall_hi = np.array([b[2:] for b in self._walls], dtype=np.float64)
        self._build(positions)

    def _build(self, positions: np.ndarray) -> None:
        """A new space: the walls, then one body and disc per agent, at rest at ``positions``."""
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.collision_slop = 0.005 * self.agent_radius
        space.collision_bias = 0.0  # resolve overlap immediately: contacts are hard
        space.iterations = 10
        self.space = space
        for x0, y0, x1, y1 in self._walls:
            wall = pymunk.Poly(space.static_body, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
            wall.elasticity = 0.0
            wall.friction = 0.0
            space.add(wall)
        self.bodies: List[pymunk.Body] = []
        self._discs: List[pymunk.Circle] = []
        for x, y in np.asarray(positions, dtype=np.float64).reshape(-1, 2).tolist():
            body, disc = self._new_agent(x, y, len(self.bodies))
            space.add(body, disc)
            self.bodies.append(body)
            self._discs.append(disc)
        n = len(self.bodies)
        self.parked = np.zeros(n, dtype=bool)
        self._contacts: Set[Tuple[int, int]] = set()
        self._recent: Set[Tuple[int, int]] = set()  # contacts of the latest physics step
        # resting contacts keep about collision_slop of overlap; settle until within twice that
        self._settle_tol = 2.0 * space.collision_slop
        if n > 1 and self.agent_collisions:
            space.on_collision(_AGENT_TYPE, _AGENT_TYPE, pre_solve=self._record_contact)
        # With many agents, setting velocities and reading positions body by body dominates
        # the step; pymunk's batch API does both for all bodies in one call each (its fixed
        # overhead only pays off from a few agents on).
        self._batched = n >= _BATCH_MIN_AGENTS
        if self._batched:
            self._get_buf = _batch.Buffer()
            self._set_buf = _batch.Buffer()
            self._index_bodies()

    def _new_agent(self, x: float, y: float, index: int) -> Tuple[pymunk.Body, pymunk.Circle]:
        """The body and disc of agent ``index`` at rest at ``(x, y)``, not yet in the space."""
        body = pymunk.Body(1.0, float("inf"))
        body.position = (x, y)
        disc = pymunk.Circle(body, self.agent_radius)
        disc.elasticity = 0.0
        disc.friction = 0.0
        disc.collision_type = _AGENT_TYPE
        disc.agent_index = index  # read back in _record_contact
        if not self.agent_collisions:  # shapes of one non-zero group never collide with each other
            disc.filter = pymunk.ShapeFilter(group=_AGENT_GROUP)
        return body, disc

    def restart(self, positions: np.ndarray) -> bool:
        """Start a new episode in this space with the agents at rest at ``positions``, if that is
        exactly a new :class:`World`; return whether it was done.

        Only a world of one agent that was never parked restarts in place: the agent's body and
        disc leave the space, which drops their cached contacts, and a new body and disc take
        their place (a body keeps the push out of walls its last step solved for, to apply at its
        next one). Other worlds return ``False`` untouched, and the caller builds a new one: with
        several agents the order in which pymunk finds contacts depends on the history of its
        spatial index, and so do the results.
        """
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        if len(self.bodies) != 1 or len(p) != 1 or self.parked[0]:
            return False
        self.space.remove(self.bodies[0], self._discs[0])
        body, disc = self._new_agent(float(p[0, 0]), float(p[0, 1]), 0)
        self.space.add(body, disc)
        self.bodies[0], self._discs[0] = body, disc
        self._contacts = set()
        self._recent = set()
        return True

    def _index_bodies(self) -> None:
        """Find where each agent sits in pymunk's body iteration order (used by the batch API)."""
        buf = self._get_buf
        buf.clear()
        _batch.get_space_bodies(self.space, _batch.BodyFields.BODY_ID, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp)
        where = {int(b): k for k, b in enumerate(ids)}
        self._rows = np.array([where[b.id] for b in self.bodies], dtype=np.intp)
        # velocities of every body pymunk iterates over (the static body's row stays 0)
        self._vel = np.zeros((len(ids), 2), dtype=np.float64)
        self._set_buf.set_float_buf(self._vel)

    def _read_positions(self) -> np.ndarray:
        buf = self._get_buf
        buf.clear()
        _batch.get_space_bodies(self.space, _batch.BodyFields.POSITION, buf)
        return np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(-1, 2)[self._rows]

    def _record_contact(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data) -> None:
        a, b = arbiter.shapes
        i, j = a.agent_index, b.agent_index
        pair = (i, j) if i < j else (j, i)
        self._contacts.add(pair)
        self._recent.add(pair)

    @property
    def n_agents(self) -> int:
        return len(self.bodies)

    def positions(self) -> np.ndarray:
        """Current agent centres, shape ``(N, 2)``."""
        if self._batched:
            return self._read_positions()
        return np.array([tuple(b.position) for b in self.bodies], dtype=np.float64).reshape(-1, 2)

    def park(self, index: int) -> None:
        """Freeze agent ``index`` where it stands: it becomes an immovable obstacle for the others."""
        body = self.bodies[index]
        body.velocity = (0.0, 0.0)
        # Static, not kinematic: pymunk still integrates a kinematic body, and the position
        # correction left over from its last contact would move it once more.
        body.body_type = pymunk.Body.STATIC
        self.parked[index] = True
        if self._batched:
            self._index_bodies()

    def place(self, index: int, position: np.ndarray) -> None:
        """Put agent ``index`` at ``position`` at rest (a new episode of one agent in a shared space)."""
        body = self.bodies[index]
        body.position = (float(position[0]), float(position[1]))
        body.velocity = (0.0, 0.0)
        self.space.reindex_shapes_for_body(body)

    def step_single(self, dx: float, dy: float) -> np.ndarray:
        """:meth:`step` of a world of one agent that is not parked, moving by ``(dx, dy)``.

        Returns the agent's centre after every sub-step, shape ``(substeps, 2)`` (there are no
        contacts between agents to report). One agent alone settles in one step at rest.
        """
        if len(self.bodies) != 1 or self.parked[0]:
            raise ValueError("step_single needs a world of one agent that is not parked")
        self._contacts = set()
        raw = _raw_handles(self.space, self.bodies[0])
        if raw is None:
            return self._step_single_api(dx, dy)
        # The calls pymunk's Body.velocity, Space.step and Body.position make, without their
        # Python wrappers. Space.step adds bookkeeping around cpSpaceStep (objects added or
        # removed during a step, post-step callbacks, and releasing the shapes removed since the
        # last step, which restart() removes): the first physics step goes through it.
        space_ptr, body_ptr = raw
        set_velocity, space_step, get_position = _cp.cpBodySetVelocity, _cp.cpSpaceStep, _cp.cpBodyGetPosition
        dt = self._dt
        v = (dx, dy)
        pts = []
        for s in range(self.substeps):
            set_velocity(body_ptr, v)
            if s:
                space_step(space_ptr, dt)
            else:
                self.space.step(dt)
            p = get_position(body_ptr)
            pts.append((p.x, p.y))
        set_velocity(body_ptr, (0.0, 0.0))
        space_step(space_ptr, dt)
        p = get_position(body_ptr)
        pts[-1] = (p.x, p.y)
        set_velocity(body_ptr, (0.0, 0.0))
        return np.array(pts, dtype=np.float64)

    def _step_single_api(self, dx: float, dy: float) -> np.ndarray:
        """:meth:`step_single` through pymunk's public API (the same arithmetic, slower)."""
        body, space, dt = self.bodies[0], self.space, self._dt
        v = (dx, dy)
        pts = []
        for _ in range(self.substeps):
            body.velocity = v
            space.step(dt)
            pts.append(body.position)
        body.velocity = (0.0, 0.0)
        space.step(dt)
        pts[-1] = body.position
        body.velocity = (0.0, 0.0)
        return np.array(pts, dtype=np.float64)

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
        if n == 1 and not self.parked[0]:
            trace1 = self.step_single(float(vel[0, 0]), float(vel[0, 1]))
            return trace1.reshape(self.substeps, 1, 2), self._contacts
        trace = np.empty((self.substeps, n, 2), dtype=np.float64)
        space, dt = self.space, self._dt
        read: Callable[[], Union[np.ndarray, List[pymunk.Vec2d]]]
        if self._batched:
            buf, fields, set_bodies = self._set_buf, _batch.BodyFields.VELOCITY, _batch.set_space_bodies
            self._vel[self._rows] = np.where(self.parked[:, None], 0.0, vel)

            def push() -> None:
                set_bodies(space, fields, buf)

            def halt() -> None:
                self._vel[:] = 0.0
                set_bodies(space, fields, buf)

            read = self._read_positions
        else:
            moving = [(b, (float(v[0]), float(v[1]))) for b, v, p in zip(self.bodies, vel, self.parked) if not p]
            bodies = self.bodies

            def push() -> None:
                for body, v in moving:
                    body.velocity = v

            def halt() -> None:
                for body, _ in moving:
                    body.velocity = (0.0, 0.0)

            def read_bodies() -> List[pymunk.Vec2d]:
                return [body.position for body in bodies]

            read = read_bodies

        self._contacts = set()
        for s in range(self.substeps):
            push()
            space.step(dt)
            trace[s] = read()
        # Contacts found in a sub-step are resolved at the start of the next one, so the
        # last sub-step may end slightly inside a wall or another agent: settling steps at
        # rest push the agents apart before the final positions are read. One is enough
        # against walls; a crowd pushing into itself needs more: each settling step applies
        # the corrections the previous one solved for, until the deepest overlap of an agent
        # that touched another is within twice the collision slop.
        for k in range(1 + _MAX_EXTRA_SETTLE):
            if k and self._overlap(trace[-1]) <= self._settle_tol:
                break
            halt()
            self._recent = set()
            space.step(dt)
            trace[-1] = read()
        halt()
        return trace, self._contacts

    def _overlap(self, pos: np.ndarray) -> float:
        """Deepest overlap of an agent pushed by others this step, with another agent or a wall
        (exact wherever it is positive, the only case the settling loop acts on).

        An agent on its own is always out of the walls after one settling step; only agents
        that touched another one need checking, and only against the walls within one radius.
        """
        if not self._contacts:
            return 0.0
        r = self.agent_radius
        worst = 0.0
        if self._recent:
            pairs = np.array(list(self._recent), dtype=np.intp)
            d = pos[pairs[:, 0]] - pos[pairs[:, 1]]
            worst = 2.0 * r - float(np.sqrt((d * d).sum(-1)).min())
        touched = np.zeros(len(self.bodies), dtype=bool)
        touched[np.array(list(self._contacts), dtype=np.intp).ravel()] = True
        p = pos[touched & ~self.parked]  # parked agents cannot be pushed out of anything
        if len(p) == 0:
            return worst
        index = self._wall_index() if len(self._walls) >= INDEX_MIN_BOXES else None
        if index is not None and 4 * index.width <= len(self._walls):  # walls within r: r - d > 0 there only
            lo, hi = index.near(p)
        else:
            lo, hi = self._wall_lo[None], self._wall_hi[None]
        gap = np.maximum(np.maximum(lo - p[:, None], p[:, None] - hi), 0.0)
        return max(worst, r - float(np.sqrt((gap * gap).sum(-1)).min()))

    def _wall_index(self) -> BoxIndex:
        """The walls bucketed by grid cells for :meth:`_overlap` (shared by worlds on one map)."""
        key = (self._wall_lo.tobytes(), self._wall_hi.tobytes(), self.size, self.agent_radius)
        index = _WALL_INDEXES.get(key)
        if index is None:
            if len(_WALL_INDEXES) >= 8:
                _WALL_INDEXES.pop(next(iter(_WALL_INDEXES)))
            index = _WALL_INDEXES[key] = BoxIndex(self._wall_lo, self._wall_hi, self.size, self.agent_radius)
        return index


__all__ = ["World"]
