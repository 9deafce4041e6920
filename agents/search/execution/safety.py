"""The safety layer: a filter between the controller and the environment that keeps agents apart.

Plans keep agents apart on the graph, but agents run late or early, yield, escape and take
detours, and in the pymunk world two discs that meet touch. The layer looks at the joint action
of one step and changes it as little as it can so that no two agents come into contact:

1. **Barrier filter.** Agents are single integrators: an action ``u`` moves an agent by
   ``step_length * u`` in one step. For every pair of agents within reach of each other in one
   step, with ``h`` their distance minus ``2 * agent_radius + clearance``, the joint action must
   keep ``step_length * n . (u_i - u_j) >= -gamma * h`` (``n`` the unit vector from ``j`` to ``i``):
   the discrete control barrier condition ``h' >= (1 - gamma) h``, linearised on the safe side
   (the distance is convex, so the linear bound underestimates it). The joint action closest to the
   controller's (least squares) under these constraints is found by Hildreth's dual ascent; an
   agent parked at its goal, or not driven by this team, is a fixed disc (``u_j = 0``). Where a
   constraint binds, each of the two agents also turns aside by ``bias`` of its correction, both
   to their right, so that two agents meeting head on pass each other instead of stopping nose
   to nose.
2. **Walls.** The filter starts from what the walls let each agent do: the disc is moved over the
   world's sub-steps and pushed out of the map's boxes after each, so that it slides along a wall and
   round a corner as the world moves it. An agent beside a parked agent turns to the side the walls
   leave open.
3. **Guard.** What the filter leaves is checked exactly: two discs moving in straight lines
   over the step, as asked and as the walls let them, come no closer than ``2 * agent_radius``
   plus half the clearance at any moment (unless they are closer already and separate). A pair
   that would is stopped, both agents, and the check repeats with the stopped agents (at most once
   per agent). Standing agents do not approach anybody, so after the guard no pair starts a contact.
4. **Deadlocks.** An agent the layer keeps from moving as asked on ``patience`` of its last
   ``2 * patience`` steps is reported (:attr:`SafetyState.deadlocked`), so that the controller
   counts it stuck and it escapes and replans like any stuck agent.

What the layer reads is the **team's shared positions**, each agent's position in world units,
as a team whose members share their localisation would have (the vector agents observe exactly
that; panorama agents are given them), and the map's walls. It reads no plan.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Deque, Dict, List, Mapping, Optional, Tuple

import numpy as np
from scipy.spatial import cKDTree


@dataclass
class SafetyState:
    """The layer's episode: what it did, and which agents it has kept from moving lately."""

    #: agent-steps whose action the layer changed
    steered: int = 0
    #: agent-steps its guard stopped
    stopped: int = 0
    #: times an agent was reported in a deadlock (:attr:`deadlocked`)
    deadlocks: int = 0
    #: per agent, for its last ``2 * patience`` steps, whether the layer kept it from moving as asked
    held: Dict[str, Deque[bool]] = field(default_factory=dict)
    #: the agents the last step found in a deadlock: held on ``patience`` of their last ``2 * patience``
    #: steps (their record starts anew)
    deadlocked: List[str] = field(default_factory=list)


@dataclass(frozen=True)
class SafetyLayer:
    """Keeps agents from touching each other by filtering the joint action of every step.

    Args:
        agent_radius: radius of the agents' discs (world units).
        step_length: world units an agent moves per unit of action in one step (the env's
            ``action_scale``).
        clearance: gap kept between two moving discs, as a share of ``agent_radius`` (the guard keeps
            half of it).
        gamma: rate of the barrier condition in ``(0, 1]``: the share of the remaining gap two
            agents may close in one step.
        bias: share of a correction by which each agent of a binding pair also turns to its right.
        iterations: dual ascent sweeps of the barrier filter.
        patience: an agent the layer keeps from moving (to less than half of what it asked) on this
            many of its last ``2 * patience`` steps is in a deadlock (:attr:`SafetyState.deadlocked`): a
            :class:`~agents.search.policy.SearchPolicy` then counts it stuck, so that it escapes and
            replans.
        substeps: the world's physics sub-steps per step: the layer follows a disc along a wall and
            round a corner in as many (:meth:`for_env` reads the env's).
        walls: static boxes ``(x0, y0, x1, y1)`` that stop the agents (``None``: none); :meth:`for_env`
            gives the map's boxes and the world's border.

    Use :meth:`for_env` to read the geometry off a parallel env.
    """

    agent_radius: float = 0.5
    step_length: float = 1.0
    clearance: float = 0.2
    gamma: float = 0.5
    bias: float = 0.5
    iterations: int = 200
    patience: int = 8
    substeps: int = 4
    walls: Optional[np.ndarray] = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(f"substeps must be an int >= 1, got {self.substeps!r}")
        for name in ("agent_radius", "step_length"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if not (isinstance(self.clearance, (int, float)) and 0 <= self.clearance < 10):
            raise ValueError(f"clearance must be a share of the radius in [0, 10), got {self.clearance!r}")
        if not (isinstance(self.gamma, (int, float)) and 0 < self.gamma <= 1):
            raise ValueError(f"gamma must be in (0, 1], got {self.gamma!r}")
        if not (isinstance(self.bias, (int, float)) and 0 <= self.bias <= 2):
            raise ValueError(f"bias must be in [0, 2], got {self.bias!r}")
        if not (isinstance(self.iterations, int) and self.iterations >= 1):
            raise ValueError(f"iterations must be an int >= 1, got {self.iterations!r}")
        if not (isinstance(self.patience, int) and self.patience >= 1):
            raise ValueError(f"patience must be an int >= 1, got {self.patience!r}")
        if self.walls is not None:
            walls = np.asarray(self.walls, dtype=np.float64)
            if walls.ndim != 2 or walls.shape[1] != 4 or not np.isfinite(walls).all():
                raise ValueError(f"walls must be finite boxes (x0, y0, x1, y1), shape (B, 4), got {walls.shape}")
            walls.setflags(write=False)
            object.__setattr__(self, "walls", walls)

    @classmethod
    def for_env(cls, env: Any, **options: Any) -> "SafetyLayer":
        """The layer for a parallel env of this package: its agents' radius, its ``action_scale``, its
        physics sub-steps, and its walls (the map's boxes and the world's border)."""
        base = getattr(env, "unwrapped", env)
        scenario = getattr(base, "scenario", None)
        if scenario is None or not hasattr(scenario, "agent_radius"):
            raise TypeError(f"{type(env).__name__} is not a safe-navigation env (no scenario.agent_radius)")
        w, h = scenario.size
        t = 1.0 + float(scenario.agent_radius)
        border = [(-t, -t, w + t, 0.0), (-t, h, w + t, h + t), (-t, 0.0, 0.0, h), (w, 0.0, w + t, h)]
        walls = np.array(list(scenario.boxes) + border, dtype=np.float64).reshape(-1, 4)
        options.setdefault("walls", walls)
        options.setdefault("substeps", int(getattr(base, "substeps", 4)))
        return cls(agent_radius=float(scenario.agent_radius),
                   step_length=float(getattr(base, "action_scale", 1.0)), **options)

    # ------------------------------------------------------------------ the filter
    @property
    def contact(self) -> float:
        """Centre distance at which two discs touch."""
        return 2.0 * self.agent_radius

    def filter(self, positions: np.ndarray, actions: np.ndarray,
               movable: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The safe joint action.

        Args:
            positions: every team agent's centre, ``(N, 2)`` world units (parked agents too).
            actions: the actions asked for, ``(N, 2)`` in ``[-1, 1]`` (rows of agents that are not
                ``movable`` are ignored).
            movable: ``(N,)`` which agents act on this step.

        Returns:
            ``(actions, steered, stopped)``: the filtered actions (``float32``; zero for agents that
            do not move), and per agent whether the layer changed its action and whether the guard
            stopped it.
        """
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
        n = len(p)
        u0 = np.asarray(actions, dtype=np.float64).reshape(n, 2).copy()
        mov = np.asarray(movable, dtype=bool).reshape(n)
        if not np.isfinite(p).all():
            raise ValueError("positions must be finite")
        u0[~mov] = 0.0
        u0 = np.clip(np.nan_to_num(u0), -1.0, 1.0)
        steered = np.zeros(n, dtype=bool)
        stopped = np.zeros(n, dtype=bool)
        gap = self.clearance * self.agent_radius
        reach = self.contact + gap + 2.0 * math.sqrt(2.0) * self.step_length
        i, j = self._pairs(p, reach, mov)
        if len(i) == 0:
            return u0.astype(np.float32), steered, stopped
        d = p[i] - p[j]
        dist = np.sqrt((d * d).sum(-1))
        unit = np.where(dist[:, None] > 1e-12, d / np.maximum(dist, 1e-12)[:, None], _tiebreak(i, j))
        # a disc that stands for good (parked) keeps only a tenth of the gap: the narrow way between it
        # and a wall stays open; the filter starts from what the walls let the agents do of what they ask
        pair_gap = np.where(mov[i] & mov[j], gap, 0.1 * gap)
        u = self._barrier(p, self._slide(p, u0), i, j, unit, dist - self.contact - pair_gap, mov)
        u = np.clip(u, -1.0, 1.0)
        u[~mov] = 0.0
        u, stopped = self._guard(p, u, i, j, d, dist, mov, self.contact + 0.5 * pair_gap)
        steered = mov & (np.abs(u - u0).max(-1) > 1e-6)
        return u.astype(np.float32), steered, stopped

    def _slide(self, p: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The actions ``u`` as the walls let each agent carry them out from ``p``: the disc is moved over
        ``substeps`` sub-steps, as the world moves it, and after each it is pushed out of every box it
        entered along the box's normal at the nearest point, so that it slides along a wall and round
        a corner. Returns the displacement per unit of ``step_length``, from where the disc rests now."""
        if self.walls is None or len(self.walls) == 0:
            return u
        r, s = self.agent_radius, self.step_length
        lo, hi = self.walls[:, :2], self.walls[:, 2:]
        # the boxes each agent can reach in one step
        out_of = np.maximum(np.maximum(lo[None] - p[:, None], p[:, None] - hi[None]), 0.0)
        a, b = np.nonzero((out_of * out_of).sum(-1) < (r + math.sqrt(2.0) * s + 1e-6) ** 2)
        if len(a) == 0:
            return u
        blo, bhi = lo[b], hi[b]
        # the pairs in rounds, each agent's k-th box in round k: boxes are resolved one after the other
        rank = np.arange(len(a)) - np.searchsorted(a, a)
        rounds = [np.flatnonzero(rank == k) for k in range(int(rank.max()) + 1)]

        def push_out(q: np.ndarray) -> np.ndarray:
            # Gauss-Seidel over the boxes: in a wedge (a wall and a corner) the pushes alternate
            # and shrink towards the point the disc cannot pass
            for _ in range(12):
                deepest = 0.0
                for k in rounds:
                    ak = a[k]
                    d = q[ak] - np.clip(q[ak], blo[k], bhi[k])
                    dist = np.sqrt((d * d).sum(-1))
                    depth = np.where(dist > 1e-12, r - dist, 0.0)  # a centre inside a box has no normal: left
                    hit = depth > 1e-9
                    if hit.any():
                        q[ak[hit]] += d[hit] / dist[hit, None] * depth[hit, None]
                        deepest = max(deepest, float(depth[hit].max()))
                if deepest < 1e-6:
                    break
            return q

        start = push_out(p.astype(np.float64).copy())  # a disc at rest sits a hair inside a wall it leans on
        q = start.copy()
        step = s * u / self.substeps
        for _ in range(self.substeps):
            q = push_out(q + step)
        out = (q - start) / s
        out[~np.any(u != 0.0, axis=-1)] = 0.0
        return out

    def _pairs(self, p: np.ndarray, reach: float, mov: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Pairs ``i < j`` within ``reach`` of each other of which at least one moves."""
        if len(p) < 2:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        pairs = cKDTree(p).query_pairs(reach, output_type="ndarray")
        if len(pairs) == 0:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        keep = mov[pairs[:, 0]] | mov[pairs[:, 1]]
        return pairs[keep, 0].astype(np.intp), pairs[keep, 1].astype(np.intp)

    def _barrier(self, p: np.ndarray, u0: np.ndarray, i: np.ndarray, j: np.ndarray, unit: np.ndarray,
                 h: np.ndarray, mov: np.ndarray) -> np.ndarray:
        """The joint action closest to ``u0`` that meets every pair's barrier condition; where a
        condition binds, the same from ``u0`` turned aside for the binding pairs: two moving agents
        both to their right, an agent beside a fixed disc to the side the walls leave open."""
        u, lam = self._project(u0, i, j, unit, h, mov)
        if self.bias > 0 and np.any(lam > 0):
            right = np.stack([unit[:, 1], -unit[:, 0]], axis=-1)  # n turned clockwise
            fixed = mov[i] != mov[j]
            if fixed.any() and self.walls is not None:
                # the moving one of the pair, and its turn (i's turn is +right, j's is -right)
                k = np.where(mov[i], i, j)[fixed]
                sign = np.where(mov[i], 1.0, -1.0)[fixed]
                t = right[fixed] * sign[:, None]
                room = [np.hypot(*self._slide(p[k], d).T) for d in (t, -t)]  # how far each side gets
                right[fixed] *= np.where(room[1] > room[0] + 1e-6, -1.0, 1.0)[:, None]
            turn = self.bias * lam[:, None] * right
            nominal = u0.copy()
            np.add.at(nominal, i, turn * mov[i, None])
            np.add.at(nominal, j, -turn * mov[j, None])  # the other one's n is -n, turned the same way
            u, _ = self._project(nominal, i, j, unit, h, mov)
        return u

    def _project(self, u0: np.ndarray, i: np.ndarray, j: np.ndarray, unit: np.ndarray, h: np.ndarray,
                 mov: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Least-squares projection of ``u0`` on the barrier conditions (Hildreth's dual ascent, all
        pairs at once, each step scaled by the busier agent's number of pairs); returns the action
        and the multipliers."""
        wi, wj = mov[i].astype(np.float64), mov[j].astype(np.float64)
        b = -self.gamma * h / self.step_length  # n . (u_i - u_j) >= b
        deg = np.bincount(np.concatenate([i[wi > 0], j[wj > 0]]), minlength=len(u0)).astype(np.float64)
        scale = 1.0 / ((wi + wj) * np.maximum(np.maximum(deg[i], deg[j]), 1.0))
        lam = np.zeros(len(i))
        u = u0.copy()
        ci, cj = unit * wi[:, None], unit * wj[:, None]
        for _ in range(self.iterations):
            slack = b - (ci * u[i]).sum(-1) + (cj * u[j]).sum(-1)
            new = np.maximum(0.0, lam + slack * scale)
            step = new - lam
            if not np.any(np.abs(step) > 1e-9):
                break
            lam = new
            np.add.at(u, i, step[:, None] * ci)
            np.subtract.at(u, j, step[:, None] * cj)
        return u, lam

    def _guard(self, p: np.ndarray, u: np.ndarray, i: np.ndarray, j: np.ndarray, d: np.ndarray,
               dist: np.ndarray, mov: np.ndarray, limit: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Stop both agents of every pair whose straight-line motion over the step, as asked or as the
        walls let it (:meth:`_slide`), brings them closer than ``limit`` (and closer than they are),
        until no pair does."""
        s = self.step_length
        stopped = np.zeros(len(p), dtype=bool)
        u = u.copy()
        for _ in range(len(p) + 1):
            bad = np.zeros(len(i), dtype=bool)
            for motion in (u, self._slide(p, u)) if self.walls is not None else (u,):
                v = s * (motion[i] - motion[j])
                vv = (v * v).sum(-1)
                t = np.clip(-(d * v).sum(-1) / np.maximum(vv, 1e-18), 0.0, 1.0)
                closest = d + t[:, None] * v
                dmin = np.sqrt((closest * closest).sum(-1))
                bad |= (dmin < limit) & (dmin < dist - 1e-9) & (vv > 0)
            if not bad.any():
                break
            hit = np.zeros(len(p), dtype=bool)
            hit[i[bad]] = True
            hit[j[bad]] = True
            hit &= mov & ~stopped
            if not hit.any():  # only fixed agents left in the way: nothing more to stop
                break
            stopped |= hit
            u[hit] = 0.0
        return u, stopped

    # ------------------------------------------------------------------ by agent name
    def filter_agents(self, actions: Mapping[str, np.ndarray], positions: Mapping[str, Any],
                      state: SafetyState | None = None) -> Dict[str, np.ndarray]:
        """:meth:`filter` by agent name: ``actions`` of the agents that act now, ``positions`` of the
        whole team (every agent of ``actions`` and those parked or standing still); ``state`` (one
        per episode) counts what the layer did.
        """
        missing = [a for a in actions if a not in positions]
        if missing:
            raise ValueError(f"the team's positions lack the acting agents {sorted(missing)}")
        names = list(positions)
        pos = np.array([np.asarray(positions[a], dtype=np.float64).reshape(2) for a in names])
        act = np.zeros((len(names), 2))
        mov = np.zeros(len(names), dtype=bool)
        first = next(iter(actions.values()), None)
        for k, a in enumerate(names):
            if a in actions:
                act[k] = np.asarray(actions[a], dtype=np.float64).reshape(2)
                mov[k] = True
        out, steered, stopped = self.filter(pos, act, mov)
        if state is not None:
            state.steered += int(steered.sum())
            state.stopped += int(stopped.sum())
            state.deadlocked = []
            for k, a in enumerate(names):
                if not mov[k]:
                    continue
                held = state.held.setdefault(a, deque(maxlen=2 * self.patience))
                held.append(bool(steered[k]) and float(np.hypot(*out[k])) < 0.5 * float(np.hypot(*act[k])))
                if sum(held) >= self.patience:
                    state.deadlocked.append(a)
                    held.clear()
            state.deadlocks += len(state.deadlocked)
        dtype = np.asarray(first).dtype if first is not None else np.float32
        return {a: out[k].astype(dtype) for k, a in enumerate(names) if mov[k]}


def _tiebreak(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """A direction for agents at exactly the same place (a fixed one, by index)."""
    sign = np.where(i < j, 1.0, -1.0)
    return np.stack([sign, np.zeros_like(sign)], axis=-1)


def team_positions(env: Any) -> Dict[str, np.ndarray]:
    """The shared positions of a parallel env's team: every agent's position (world units), by name,
    parked agents included."""
    base = getattr(env, "unwrapped", env)
    return {a: p for a, p in zip(base.possible_agents, np.asarray(base.positions, dtype=np.float64))}


__all__ = ["SafetyLayer", "SafetyState", "team_positions"]
