"""Meta-agents (MA-CBS), the disjoint target split and the coupled search, against the brute force.

The instances are tiny, tightly coupled grids shipped beside the MovingAI benchmark files
(``examples/data/movingai/tiny``, which ``examples/bench_cbs.py --tiny`` runs): corridors with
pockets, dead ends, agents parked in the way, and instances with no solution although every pair
of agents alone has one (named ``infeasible-*``).
"""
import time
from pathlib import Path

import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid

from agents.search.mapf import (
    EMPTY,
    DeadlineConstraint,
    MapfInstance,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
    load_instance,
    solve_cbs,
    validate,
)
from agents.search.mapf.coupled import CoupledLimit, coupled_astar
from agents.search.mapf.lowlevel import Counter
from agents.search.mapf.paths import AgentPath, satisfies


def grid(text):
    """``(n, edges, index)`` of a 4-connected grid string; ``index[(row, col)]`` is the node."""
    rows = [r for r in text.strip("\n").split("\n")]
    index = {}
    for r, line in enumerate(rows):
        for c, ch in enumerate(line):
            if ch == ".":
                index[(r, c)] = len(index)
    edges = {}
    for (r, c), u in index.items():
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            v = index.get((r + dr, c + dc))
            if v is not None:
                edges[(u, v)] = 1
    return len(index), edges, index


def adjacency(n, edges):
    adj = [[] for _ in range(n)]
    for (u, v) in sorted(edges):
        adj[u].append(v)
    return adj


TINY = Path(__file__).resolve().parents[2] / "examples" / "data" / "movingai" / "tiny"
NAMES = sorted(p.stem for p in TINY.glob("*.map"))
#: pocket: two agents swap the ends of a corridor, the third sits in the pocket; pocket-rotate:
#: the pocket agent must end at a corridor end; dead-end: a dead end of length two off a
#: corridor; two-pockets: three agents through one corridor; parked: the pocket agent parks in
#: the corridor the others pass (and four more for the group bounds' tests)
TIGHT = [n for n in NAMES if not n.startswith("infeasible-")]
#: every pair of agents alone has a solution, the three together none: a star (three agents on
#: its leaves), a tree (a corridor with a pocket next to its end), an agent parked in the
#: corridor the two others must swap through, a ring (it keeps the agents' cyclic order)
INFEASIBLE = [n for n in NAMES if n.startswith("infeasible-")]


def test_the_tiny_instances_are_shipped():
    assert {"pocket", "pocket-rotate", "dead-end", "two-pockets", "parked", "two-pockets-four", "dead-end-two",
            "tee-rotate", "parked-middle"} <= set(TIGHT)
    assert {"infeasible-star", "infeasible-tree", "infeasible-parked", "infeasible-ring"} <= set(INFEASIBLE)


def build(name):
    """``(n, edges, starts, goals)`` of a shipped tiny instance (all the agents of its scenario)."""
    inst = load_instance(TINY / f"{name}.map", TINY / f"{name}.scen")
    rows, cols = inst.graph.nonzero()
    edges = {(int(u), int(v)): 1 for u, v in zip(rows, cols) if u != v}
    return inst.graph.shape[0], edges, inst.starts, inst.goals


@pytest.mark.parametrize("name", TIGHT)
def test_tightly_coupled_tiny_instances_are_solved_optimally_and_fast(name):
    n, edges, starts, goals = build(name)
    expected = brute_force_soc(n, edges, starts, goals)
    assert expected is not None
    adj = adjacency(n, edges)
    t0 = time.perf_counter()
    res = solve_cbs(adj, starts, goals, time_limit=10)
    assert time.perf_counter() - t0 < 3.0, name  # about 0.3 s for pocket; slack for a loaded machine
    assert res.status == "optimal" and res.soc == expected, (name, res.status, res.soc, expected)
    assert validate(adj, starts, goals, res.paths) == []
    for kw in ({"merge_threshold": 0}, {"merge_threshold": 1, "disjoint_target": False},
               {"merge_threshold": 3, "heuristic": "none", "bypass": False}):
        res = solve_cbs(adj, starts, goals, time_limit=10, **kw)
        assert res.status == "optimal" and res.soc == expected, (name, kw, res.status, res.soc)
        assert validate(adj, starts, goals, res.paths) == []


@pytest.mark.parametrize("name", INFEASIBLE)
def test_jointly_infeasible_tiny_instances_are_reported_infeasible(name):
    n, edges, starts, goals = build(name)
    assert brute_force_soc(n, edges, starts, goals) is None
    adj = adjacency(n, edges)
    for a in range(3):  # every pair alone has a solution: the pair check cannot tell
        for b in range(a + 1, 3):
            assert brute_force_soc(n, edges, [starts[a], starts[b]], [goals[a], goals[b]]) is not None
    for kw in ({}, {"joint_check_states": 0}, {"merge_threshold": 0, "disjoint_target": False}):
        t0 = time.perf_counter()
        res = solve_cbs(adj, starts, goals, time_limit=10, **kw)
        assert res.status == "infeasible", (name, kw, res.status, res.message)
        if not kw:  # the exhaustive check before the search decides it at once
            assert "joint configurations" in res.message, res.message
        if kw == {"joint_check_states": 0}:  # merged, the group's search proves it: the message says why
            assert "collide" in res.message and "alone" in res.message, res.message
        assert time.perf_counter() - t0 < 3.0
    # without merging (and without the exhaustive check before the search, which decides these
    # tiny instances at once) the search cannot prove it and runs into its limit
    res = solve_cbs(adj, starts, goals, time_limit=10, node_limit=100, merge_threshold=None, joint_check_states=0)
    assert res.status == "timeout"
    res = solve_cbs(adj, starts, goals, time_limit=10, node_limit=100, merge_threshold=None)
    assert res.status == "infeasible" and "joint configurations" in res.message


@pytest.mark.parametrize("seed", range(12))
def test_random_tiny_grids_with_merging_match_brute_force(seed):
    rng = np.random.default_rng(7000 + seed)
    n, edges, cells = random_grid(rng, 2 + seed % 2, 4, 0.15)
    if n < 5:
        return
    starts = [int(x) for x in rng.choice(n, 3, replace=False)]
    goals = starts[1:] + starts[:1] if seed % 2 else [int(x) for x in rng.choice(n, 3, replace=False)]
    expected = brute_force_soc(n, edges, starts, goals)
    adj = adjacency(n, edges)
    for kw in ({"merge_threshold": 0}, {"merge_threshold": 2, "grid_coords": cells},
               {"merge_threshold": None, "disjoint_target": True, "node_limit": 3000}):
        res = solve_cbs(adj, starts, goals, time_limit=10, **kw)
        if expected is None:
            assert res.status in ("infeasible", "timeout")
            if kw["merge_threshold"] is not None:
                assert res.status == "infeasible", (seed, kw)
            continue
        if res.status == "timeout" and kw["merge_threshold"] is None:
            continue
        assert res.status == "optimal" and res.soc == expected, (seed, kw, res.status, res.soc, expected)
        assert validate(adj, starts, goals, res.paths) == []


def test_disjoint_target_split_matches_the_overlapping_one():
    # agent 2 parks in the corridor that agents 0 and 1 pass through
    n, edges, starts, goals = build("parked")
    adj = adjacency(n, edges)
    expected = brute_force_soc(n, edges, starts, goals)
    for disjoint in (True, False):
        res = solve_cbs(adj, starts, goals, time_limit=10, disjoint_target=disjoint)
        assert res.status == "optimal" and res.soc == expected
        assert validate(adj, starts, goals, res.paths) == []


def test_coupled_search_meets_constraints_and_proves_infeasibility():
    n, edges, index = grid("@@.@@\n.....")
    inst = MapfInstance(adjacency(n, edges), [index[(1, 0)], index[(1, 4)]], [index[(1, 4)], index[(1, 0)]])
    counter = Counter()
    ccs = [compile_constraints(EMPTY, n, g) for g in inst.goals]
    out = coupled_astar(inst, [0, 1], ccs, None, time.perf_counter() + 10, counter)
    assert out is not None
    paths = [AgentPath(ev, inst) for ev in out]
    assert sum(p.cost for p in paths) == brute_force_soc(n, edges, inst.starts, inst.goals)
    assert validate(inst, None, None, out) == []
    # agent 0 may not be at the pocket's mouth at 1 or 2, and must arrive by time 4
    extra = [VertexConstraint(0, index[(1, 1)], 1), DeadlineConstraint(0, 4)]
    cs = EMPTY.add(*extra)
    ccs0 = [compile_constraints(cs, n, inst.goals[0]), ccs[1]]
    out = coupled_astar(inst, [0, 1], ccs0, None, time.perf_counter() + 10, counter)
    assert out is None  # arriving by 4 needs the mouth free at 1
    cs = EMPTY.add(RangeConstraint(1, index[(0, 2)], 0, 20))  # the pocket closed to agent 1 for long
    ccs1 = [compile_constraints(EMPTY.add(RangeConstraint(0, index[(0, 2)], 0, 20)), n, inst.goals[0]),
            compile_constraints(cs, n, inst.goals[1])]
    assert coupled_astar(inst, [0, 1], ccs1, None, time.perf_counter() + 10, counter) is not None
    with pytest.raises(CoupledLimit):
        coupled_astar(inst, [0, 1], ccs1, None, time.perf_counter() + 10, counter, max_states=5)
    p = AgentPath([(0, 0), (1, 1)], MapfInstance([[1], [0]], [0], [1]))
    assert satisfies(p, DeadlineConstraint(0, 1)) and not satisfies(p, DeadlineConstraint(0, 0))


def test_merge_options_are_checked():
    adj = [[1], [0]]
    with pytest.raises(ValueError, match="merge_threshold"):
        solve_cbs(adj, [0], [1], merge_threshold=-1)
    with pytest.raises(ValueError, match="merge_max_agents"):
        solve_cbs(adj, [0], [1], merge_max_agents=1)
