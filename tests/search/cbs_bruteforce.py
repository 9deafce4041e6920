"""An independent brute-force MAPF solver for tiny instances: Dijkstra over joint states.

Shares no code with the CBS solver. A joint state holds, per agent, where it is (a node, or an
edge in progress under the durative model) and whether it has finished (made its final
arrival; it then stays at its goal for good). Every step each unfinished agent pays 1, so the
cheapest path to "all finished" is the optimal sum of final arrival times.

Unit time: vertex conflicts at every time, swap conflicts, proximity at every time.
Durative: during a step an agent occupies its node (waiting) or both ends of the edge it is on;
two agents conflict when occupied nodes coincide or are near.
"""
from __future__ import annotations

import heapq
import itertools
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

Edges = Dict[Tuple[int, int], int]


def brute_force_soc(n: int, edges: Edges, starts: Sequence[int], goals: Sequence[int], unit: bool = True,
                    near=None, max_states: int = 400_000) -> Optional[int]:
    """Optimal sum of costs, or ``None`` if no solution exists (raises if the state space is too big)."""
    k = len(starts)
    out: List[List[Tuple[int, int]]] = [[(v, 1)] for v in range(n)]
    for (u, v), d in sorted(edges.items()):
        if u != v:
            out[u].append((v, 1 if unit else d))

    def is_near(x: int, y: int) -> bool:
        return near is not None and x != y and bool(near[x][y])

    if unit and any(is_near(a, b) for a in starts for b in starts):
        return None  # agents start in proximity conflict
    # agent state: (node, target, remaining, done); at a node: (v, v, 0, done)
    start = tuple((s, s, 0, False) for s in starts)
    best = {start: 0}
    heap = [(0, 0, start)]
    counter = itertools.count(1)
    while heap:
        cost, _, state = heapq.heappop(heap)
        if best.get(state, None) != cost:
            continue
        if all(a[3] for a in state):
            return cost
        if len(best) > max_states:
            raise RuntimeError("state space too large for the brute force")
        # options per agent: finish now (if at goal), or an action for the next step
        per_agent = []
        for i, (v, w, rem, done) in enumerate(state):
            opts = []
            if done:
                opts.append(("done", (v,), (v, v, 0, True)))
            elif rem > 0:
                occ = (v, w)
                nxt = (w, w, 0, False) if rem == 1 else (v, w, rem - 1, False)
                opts.append(("go", occ, nxt))
            else:
                if v == goals[i]:
                    opts.append(("done", (v,), (v, v, 0, True)))
                for x, d in out[v]:
                    if x == v:
                        opts.append(("go", (v,), (v, v, 0, False)))
                    else:
                        occ = (v, x)
                        nxt = (x, x, 0, False) if d == 1 else (v, x, d - 1, False)
                        opts.append(("go", occ, nxt))
            per_agent.append(opts)
        for combo in itertools.product(*per_agent):
            ok = True
            for i in range(k):
                for j in range(i + 1, k):
                    if not _compatible(state[i], combo[i], state[j], combo[j], unit, is_near):
                        ok = False
                        break
                if not ok:
                    break
            if not ok:
                continue
            nstate = tuple(c[2] for c in combo)
            # finishing costs nothing; every agent still running pays one step
            pay = sum(1 for c in combo if c[0] == "go")
            if all(c[0] == "done" for c in combo):
                ncost = cost
            else:
                ncost = cost + pay
            if ncost < best.get(nstate, 1 << 60):
                best[nstate] = ncost
                heapq.heappush(heap, (ncost, next(counter), nstate))
    return None


def _compatible(si, ci, sj, cj, unit: bool, is_near) -> bool:
    if unit:
        # positions after the step, and the move itself
        pi_from, pj_from = si[0], sj[0]
        pi_to, pj_to = ci[2][0], cj[2][0]
        if pi_to == pj_to or is_near(pi_to, pj_to):
            return False
        if pi_from != pi_to and pi_from == pj_to and pj_from == pi_to:
            return False
        return True
    oi, oj = ci[1], cj[1]
    for x in oi:
        for y in oj:
            if x == y or is_near(x, y):
                return False
    # after the step both are at nodes or on edges; a finished agent occupies its goal for ever,
    # which the next step's occupancy check covers
    return True


def random_grid(rng, h: int, w: int, p_block: float):
    """A random 4-connected grid: ``(n, {(u, v): 1}, cells)``, each cell blocked with ``p_block``;
    the edges of every cell are listed down, up, right, left."""
    free = rng.random((h, w)) >= p_block
    idx = -np.ones((h, w), int)
    cells = []
    for r in range(h):
        for c in range(w):
            if free[r, c]:
                idx[r, c] = len(cells)
                cells.append((r, c))
    edges = {}
    for r, c in cells:
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            r2, c2 = r + dr, c + dc
            if 0 <= r2 < h and 0 <= c2 < w and free[r2, c2]:
                edges[(int(idx[r, c]), int(idx[r2, c2]))] = 1
    return len(cells), edges, np.array(cells)
