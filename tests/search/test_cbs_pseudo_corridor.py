"""Pseudo-corridor reasoning: head-on conflicts in open space split like a corridor of one cell.

Optimality against the independent brute force of :mod:`cbs_bruteforce` with the option on and
off, the split's bounds on a hand-checked instance, and that the split fires where it should.
"""
import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid

from agents.search.mapf import (
    EDGE,
    EMPTY,
    VERTEX,
    CBSSolver,
    Conflict,
    MapfInstance,
    RangeConstraint,
    compile_constraints,
    solve_cbs,
    validate,
)
from agents.search.mapf.mdd import build_mdd
from agents.search.mapf.symmetry import Corridors


def adjacency(n, edges):
    adj = [[] for _ in range(n)]
    for (u, v), d in sorted(edges.items()):
        adj[u].append((v, d))
    return adj


def open_grid(h, w):
    """An obstacle-free ``h x w`` 4-connected grid: ``(n, edges, cells, index)``."""
    n, edges, cells = random_grid(np.random.default_rng(0), h, w, 0.0)
    index = {tuple(c): i for i, c in enumerate(cells.tolist())}
    return n, edges, cells, index


def solve_both(n, edges, cells, starts, goals, **kw):
    """Solve with pseudo-corridor reasoning on and off; both must be optimal and valid and
    agree with the brute force. Returns the two results."""
    adj = adjacency(n, edges)
    expected = brute_force_soc(n, edges, starts, goals)
    out = []
    for on in (True, False):
        res = solve_cbs(adj, starts, goals, grid_coords=cells, time_limit=30, pseudo_corridors=on, **kw)
        if expected is None:
            assert res.status in ("infeasible", "timeout"), (on, res.status, res.soc)
        else:
            assert res.status == "optimal", (on, res.status, res.message, expected)
            assert res.soc == expected, (on, starts, goals, edges, res.paths)
            assert validate(adj, starts, goals, res.paths) == []
        if not on:
            assert res.stats.pseudo_corridor_splits == 0
        out.append(res)
    return out


@pytest.mark.parametrize("h, w, kind", [(3, 5, "vertex"), (3, 4, "edge"), (3, 7, "vertex"), (5, 6, "edge")])
def test_head_on_in_an_open_row_is_split_as_a_pseudo_corridor(h, w, kind):
    """Two agents swap the ends of the middle row of an open grid: a forced head-on vertex
    (odd width) or swap (even width) conflict, in no corridor; one of them steps aside (+2)."""
    n, edges, cells, index = open_grid(h, w)
    r = h // 2
    starts, goals = [index[(r, 0)], index[(r, w - 1)]], [index[(r, w - 1)], index[(r, 0)]]
    on, off = solve_both(n, edges, cells, starts, goals)
    assert on.soc == 2 * (w - 1) + 2
    assert on.stats.pseudo_corridor_splits > 0
    assert on.stats.corridor_splits == 0 and off.stats.corridor_splits == 0
    # one pseudo-corridor split resolves the meeting: it needs no more nodes than plain splits
    assert on.stats.hl_expanded <= off.stats.hl_expanded


def test_pseudo_corridor_bounds_on_a_hand_checked_instance():
    """3 x 5 open grid, agents swapping the ends of the middle row: they meet at (1, 2) at t = 2.

    A = (1, 1), B = (1, 3). Agent 0 reaches B through the pseudo-corridor at 3 at the earliest
    (L1 = 3) and any other way at 5 (from (0, 3), (2, 3), (1, 4) at 4, or through (0, 2) /
    (2, 2) at 3 then x: E1 = 5); the same for agent 1. U1 = min(L2 + 2, E1 - 1) = 4 = U2.
    """
    n, edges, cells, index = open_grid(3, 5)
    starts, goals = [index[(1, 0)], index[(1, 4)]], [index[(1, 4)], index[(1, 0)]]
    inst = MapfInstance(adjacency(n, edges), starts, goals)
    mdds = [build_mdd(inst, a, compile_constraints(EMPTY, n, goals[a]), 4) for a in range(2)]
    A, x, B = index[(1, 1)], index[(1, 2)], index[(1, 3)]
    corridors = Corridors(inst)
    conflict = Conflict(VERTEX, 0, 1, 2, x, x)
    assert corridors.split(conflict, 0, None, 1, None) is None  # no corridor here
    branches = corridors.pseudo_split(conflict, 0, mdds[0], 1, mdds[1])
    assert branches == [(0, (RangeConstraint(0, B, 0, 4),)), (1, (RangeConstraint(1, A, 0, 4),))]
    # the agents' roles swapped: the same split, mirrored
    mirrored = corridors.pseudo_split(Conflict(VERTEX, 1, 0, 2, x, x), 1, mdds[1], 0, mdds[0])
    assert mirrored == [(1, (RangeConstraint(1, A, 0, 4),)), (0, (RangeConstraint(0, B, 0, 4),))]
    # not head-on: agent 1's cheapest paths do not come from B
    assert corridors.pseudo_split(Conflict(VERTEX, 0, 0, 2, x, x), 0, mdds[0], 0, mdds[0]) is None
    # a swap conflict on an edge of the row: A = (1, 1) -> B = (1, 2) at t = 1 is not in the
    # agents' MDDs the right way round (agent 1 is at (1, 3) at t = 1)
    assert corridors.pseudo_split(Conflict(EDGE, 0, 1, 1, A, x), 0, mdds[0], 1, mdds[1]) is None


def test_pseudo_corridor_bounds_of_a_swap_conflict():
    """3 x 4 open grid, middle row swapped: agent 0 moves (1, 1) -> (1, 2) while agent 1 moves
    back at t = 1. k = 1: L1 = max(d1(B), d1(A) + 1) = 2; E1 = 1 + min(d1(y) for y entering B
    other than A: (0, 2), (2, 2) and (1, 3) at 3) = 4; U1 = min(L2 + 1, E1 - 1) = 3."""
    n, edges, cells, index = open_grid(3, 4)
    starts, goals = [index[(1, 0)], index[(1, 3)]], [index[(1, 3)], index[(1, 0)]]
    inst = MapfInstance(adjacency(n, edges), starts, goals)
    mdds = [build_mdd(inst, a, compile_constraints(EMPTY, n, goals[a]), 3) for a in range(2)]
    A, B = index[(1, 1)], index[(1, 2)]
    branches = Corridors(inst).pseudo_split(Conflict(EDGE, 0, 1, 1, A, B), 0, mdds[0], 1, mdds[1])
    assert branches == [(0, (RangeConstraint(0, B, 0, 3),)), (1, (RangeConstraint(1, A, 0, 3),))]


@pytest.mark.parametrize("seed", range(40))
def test_open_grids_with_head_on_agents_match_brute_force(seed):
    """Small open (or nearly open) grids, agents sent head-on along rows and columns (each
    agent's goal is another's start), some with a third agent: the sums of costs with the
    option on and off equal the brute force's, every solution is valid."""
    rng = np.random.default_rng(7000 + seed)
    shapes = [(3, 5), (3, 4), (4, 4), (2, 5), (3, 6), (4, 5)]
    h, w = shapes[seed % len(shapes)]
    n, edges, cells = random_grid(rng, h, w, 0.0 if seed % 3 else 0.15)
    if n < 5:
        return
    index = {tuple(c): i for i, c in enumerate(cells.tolist())}
    if seed % 2:
        r = int(rng.integers(0, h))
        ends = [(r, 0), (r, w - 1)]
    else:
        c = int(rng.integers(0, w))
        ends = [(0, c), (h - 1, c)]
    if any(e not in index for e in ends):
        ends = [tuple(x) for x in cells[rng.choice(n, 2, replace=False)].tolist()]
    starts = [index[ends[0]], index[ends[1]]]
    goals = [starts[1], starts[0]]
    if seed % 4 == 0 and n <= 16:  # a third agent crossing the others
        free = [v for v in range(n) if v not in starts]
        s3, g3 = (int(v) for v in rng.choice(free, 2, replace=False))
        starts.append(s3)
        goals.append(g3)
    kw = {} if seed % 5 else {"heuristic": "cg", "bypass": False}
    solve_both(n, edges, cells, starts, goals, **kw)


@pytest.mark.parametrize("seed", range(30))
def test_random_small_grids_match_brute_force_with_pseudo_corridors(seed):
    """Random grids with obstacles (corridors and open cells mixed) and 2-3 agents whose goals
    are each other's starts: the option changes the search, never the optimal cost."""
    rng = np.random.default_rng(8000 + seed)
    h, w = (3, 5) if seed % 2 else (4, 4)
    n, edges, cells = random_grid(rng, h, w, 0.25)
    if n < 5:
        return
    k = 3 if (seed % 3 == 0 and n <= 10) else 2
    starts = [int(v) for v in rng.choice(n, size=k, replace=False)]
    goals = starts[1:] + starts[:1]
    solve_both(n, edges, cells, starts, goals)


def test_vanilla_and_no_symmetry_turn_pseudo_corridors_off():
    n, edges, cells, index = open_grid(3, 5)
    adj = adjacency(n, edges)
    starts, goals = [index[(1, 0)], index[(1, 4)]], [index[(1, 4)], index[(1, 0)]]
    assert CBSSolver(adj, starts, goals).pseudo_corridors
    assert not CBSSolver(adj, starts, goals, vanilla=True).pseudo_corridors
    assert not CBSSolver(adj, starts, goals, symmetry=False).pseudo_corridors
    for kw in ({"vanilla": True}, {"symmetry": False}):
        res = solve_cbs(adj, starts, goals, grid_coords=cells, **kw)
        assert res.status == "optimal" and res.soc == 10
        assert res.stats.pseudo_corridor_splits == 0


def random_graph(rng, n, p_edge):
    """A random connected undirected graph (a spanning path plus random chords, triangles
    included): ``{(u, v): 1}``."""
    edges = {}
    order = rng.permutation(n)
    for a, b in zip(order[:-1], order[1:]):
        edges[(int(a), int(b))] = edges[(int(b), int(a))] = 1
    for u in range(n):
        for v in range(u + 1, n):
            if rng.random() < p_edge:
                edges[(u, v)] = edges[(v, u)] = 1
    return edges


def both_branches_violated(inst, forbidden, branches):
    """Whether some conflict-free pair of timed walks of agents 0 and 1 (vertex constraints
    ``forbidden[a]`` = set of (node, time) met) violates both branches: agent ``a`` at its
    branch's node at a step of the branch's range, for both branches. Joint breadth-first
    search over (node 0, node 1, violated 0, violated 1) up to the later range end."""
    (a0, (rc0,)), (a1, (rc1,)) = branches
    assert (a0, a1) == (0, 1)
    succ = inst.succ
    horizon = max(rc0.end, rc1.end)
    s0, s1 = inst.starts[0], inst.starts[1]
    layer = {(s0, s1, s0 == rc0.node, s1 == rc1.node)}
    for t in range(horizon):
        nxt = set()
        for u0, u1, f0, f1 in layer:
            if f0 and f1:
                return True
            for w0 in succ[u0]:
                if (w0, t + 1) in forbidden[0]:
                    continue
                for w1 in succ[u1]:
                    if w1 == w0 or (w0 == u1 and w1 == u0) or (w1, t + 1) in forbidden[1]:
                        continue
                    nxt.add((w0, w1, f0 or (w0 == rc0.node and t + 1 <= rc0.end),
                             f1 or (w1 == rc1.node and t + 1 <= rc1.end)))
        layer = nxt
    return any(f0 and f1 for _, _, f0, f1 in layer)


def test_every_pseudo_corridor_split_keeps_every_conflict_free_pair_of_walks():
    """The split's soundness checked directly: on random small graphs and grids, with random
    vertex constraints on the agents (so that the bounds are sharpened with the earliest
    arrivals under them), every pseudo-corridor split found for a vertex or swap conflict of
    the agents' MDDs leaves no conflict-free pair of walks meeting the constraints that
    violates both branches (a stronger property than keeping every solution)."""
    from agents.search.mapf import VertexConstraint
    from agents.search.mapf.lowlevel import Counter, earliest_arrival, space_time_astar

    checked = sharpened = 0
    for seed in range(160):
        rng = np.random.default_rng(9000 + seed)
        if seed % 2:
            n, edges, _ = random_grid(rng, 3 + seed % 2, 4 + seed % 3, 0.1)
        else:
            n = int(rng.integers(6, 11))
            edges = random_graph(rng, n, 0.2)
        if n < 5:
            continue
        starts = [int(v) for v in rng.choice(n, 2, replace=False)]
        goals = [starts[1], starts[0]] if seed % 3 else [int(v) for v in rng.choice(n, 2, replace=False)]
        inst = MapfInstance(adjacency(n, edges), starts, goals)
        if inst.unreachable_agents():
            continue
        # constraints that delay the agents: block a random step of a cheapest path, a few times
        forbidden = [set(), set()]
        cons = [EMPTY, EMPTY]
        ccs = [compile_constraints(EMPTY, n, goals[a]) for a in range(2)]
        mdds = []
        for a in range(2):
            for _ in range(int(rng.integers(0, 4))):
                events = space_time_astar(inst, a, ccs[a], None, float("inf"), Counter())
                if events is None or events[-1][1] < 2:
                    break
                t = int(rng.integers(1, events[-1][1]))
                v = [node for node, time in events if time <= t][-1]
                forbidden[a].add((v, t))
                cons[a] = cons[a].add(VertexConstraint(a, v, t))
                ccs[a] = compile_constraints(cons[a], n, goals[a])
            events = space_time_astar(inst, a, ccs[a], None, float("inf"), Counter())
            if events is None:
                break
            mdds.append(build_mdd(inst, a, ccs[a], events[-1][1]))
        if len(mdds) < 2:
            continue
        calls = []

        def earliest(agent, node, cid, inst=inst, ccs=ccs, calls=calls):
            calls.append(node)
            return earliest_arrival(inst, agent, ccs[agent], node, frozenset(), float("inf"), Counter())

        corridors = Corridors(inst)
        horizon = min(mdds[0].cost, mdds[1].cost)
        for t in range(horizon):
            candidates = [Conflict(VERTEX, 0, 1, t, x, x) for x in mdds[0].levels[t] & mdds[1].levels[t]]
            candidates += [Conflict(EDGE, 0, 1, t, u, v) for u in mdds[0].levels[t] for v in mdds[0].levels[t + 1]]
            for c in candidates:
                before = len(calls)
                branches = corridors.pseudo_split(c, 0, mdds[0], 1, mdds[1], earliest)
                if branches is None:
                    continue
                checked += 1
                sharpened += len(calls) > before
                assert not both_branches_violated(inst, forbidden, branches), (seed, c, branches)
    assert checked >= 20 and sharpened >= 3, (checked, sharpened)
