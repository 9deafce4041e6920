"""Group bounds in the WDG heuristic (``group_bounds``): admissible against the brute force.

The weighted conflict graph gets group constraints ``sum_{v in G} x_v >= D_G`` beside its pair
edges; the cover over all of them must stay a lower bound. Checked on tiny, tightly coupled
grids (pockets, dead ends, parked agents) where three agents together must pay more than any
two of them: the root's bound never exceeds the optimal sum of costs, the solutions stay
optimal and valid with the option on and off, and the option does fire there.
"""
import itertools
import random
import time

import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc, random_grid
from test_cbs_merge import TIGHT, adjacency, build

from agents.search.mapf import EMPTY, heuristics, solve_cbs, validate
from agents.search.mapf.cbs import CBSSearch
from agents.search.mapf.context import SearchContext
from agents.search.mapf.heuristics import min_vertex_cover
from agents.search.mapf.solver import CBSSolver

# the cases are the shipped tiny instances with solutions (TIGHT), among them three or four
# agents that must make way for each other: two-pockets-four (two pockets and a dead end below),
# dead-end-two (a dead end two agents must leave for the third), tee-rotate (three agents rotate
# their places at a T junction), parked-middle (a corridor with a pocket above and one below)


def root_search(adj, starts, goals, group_bounds=False, **kw):
    """``(search, root)``: the optimal CBS search with the default options, and its root."""
    solver = CBSSolver(adj, starts, goals, **kw)
    inst = solver.instance
    ctx = SearchContext(inst, time.perf_counter() + 30, solver)
    search = CBSSearch(ctx, list(range(inst.n_agents)), [EMPTY] * inst.n_agents, heuristic="wdg",
                       prioritize=True, bypass=True, target_reasoning=True, node_limit=None,
                       group_bounds=group_bounds, group_limit=20)
    root = search._root()
    assert root is not None
    return search, root


def root_bound(adj, starts, goals, group_bounds, **kw):
    """``(f of the root with its heuristic, stats)`` of the optimal CBS with the default options."""
    search, root = root_search(adj, starts, goals, group_bounds, **kw)
    return root.g + search._compute_h(root), search.ctx.stats


def test_cover_with_group_constraints_matches_enumeration():
    rng = random.Random(11)
    for _ in range(120):
        n = rng.randint(3, 6)
        edges = {}
        for i, j in itertools.combinations(range(n), 2):
            if rng.random() < 0.5:
                edges[(i, j)] = rng.randint(0, 3)
        for _ in range(rng.randint(1, 3)):
            edges[tuple(sorted(rng.sample(range(n), rng.randint(3, n))))] = rng.randint(0, 6)
        top = max(edges.values())
        best = min(sum(x) for x in itertools.product(range(top + 1), repeat=n)
                   if all(sum(x[v] for v in e) >= w for e, w in edges.items()))
        assert min_vertex_cover(edges) == best, edges


def test_group_constraints_on_shared_vertices_count_once():
    # pairs (0, 1) and (1, 2) of weight 2 are met by x_1 = 2, which also meets the group of 2
    assert min_vertex_cover({(0, 1): 2, (1, 2): 2, (0, 1, 2): 2}) == 2
    assert min_vertex_cover({(0, 1): 2, (1, 2): 2, (0, 1, 2): 3}) == 3
    assert min_vertex_cover({(0, 1, 2): 3, (2, 3, 4): 3}) == 3  # x_2 = 3 serves both


@pytest.mark.parametrize("name", TIGHT)
def test_root_bound_with_groups_is_admissible_and_solutions_stay_optimal(name):
    n, edges, starts, goals = build(name)
    expected = brute_force_soc(n, edges, starts, goals)
    assert expected is not None
    adj = adjacency(n, edges)
    plain, _ = root_bound(adj, starts, goals, False)
    grouped, _ = root_bound(adj, starts, goals, True)
    assert plain <= grouped <= expected, (name, plain, grouped, expected)
    for kw in ({}, {"group_bounds": True}, {"group_bounds": True, "merge_threshold": None, "node_limit": 3000},
               {"group_bounds": True, "group_max_agents": 4, "group_node_limit": 50}):
        res = solve_cbs(adj, starts, goals, time_limit=300, **kw)  # a safety net: seconds depend on load
        if res.status == "timeout" and kw.get("merge_threshold", 0) is None:
            assert res.lower_bound is None or res.lower_bound <= expected
            continue
        assert res.status == "optimal" and res.soc == expected, (name, kw, res.status, res.soc, expected)
        assert validate(adj, starts, goals, res.paths) == []


def test_group_bounds_fire_and_raise_the_root_bound():
    fired = raised = 0
    for name in TIGHT:
        n, edges, starts, goals = build(name)
        adj = adjacency(n, edges)
        plain, _ = root_bound(adj, starts, goals, False)
        grouped, stats = root_bound(adj, starts, goals, True)
        fired += stats.group_constraints
        raised += grouped > plain
        res = solve_cbs(adj, starts, goals, time_limit=10, group_bounds=True)
        assert res.stats.group_searches + res.stats.group_reuses > 0, name
    assert fired > 0 and raised > 0
    # off by default and under vanilla
    n, edges, starts, goals = build("pocket-rotate")
    adj = adjacency(n, edges)
    assert solve_cbs(adj, starts, goals, time_limit=10).stats.group_searches == 0
    res = solve_cbs(adj, starts, goals, time_limit=10, vanilla=True, group_bounds=True, node_limit=2000)
    assert res.stats.group_searches == 0


@pytest.mark.parametrize("seed", range(16))
def test_random_tiny_grids_root_bound_admissible_and_optimal(seed):
    rng = np.random.default_rng(9100 + seed)
    n, edges, cells = random_grid(rng, 2 + seed % 2, 4 + seed % 3 // 2, 0.2)
    k = 3 + seed % 2
    if n < k + 2:
        return
    starts = [int(x) for x in rng.choice(n, k, replace=False)]
    goals = starts[1:] + starts[:1] if seed % 3 else [int(x) for x in rng.choice(n, k, replace=False)]
    try:
        expected = brute_force_soc(n, edges, starts, goals)
    except Exception:  # the joint state space is too big for the brute force
        return
    adj = adjacency(n, edges)
    if expected is None:
        res = solve_cbs(adj, starts, goals, time_limit=10, group_bounds=True)
        assert res.status in ("infeasible", "timeout")
        return
    plain, _ = root_bound(adj, starts, goals, False)
    grouped, _ = root_bound(adj, starts, goals, True)
    assert plain <= grouped <= expected, (seed, plain, grouped, expected)
    for kw in ({"group_bounds": True}, {"group_bounds": True, "grid_coords": cells, "group_max_agents": 4}):
        res = solve_cbs(adj, starts, goals, time_limit=300, **kw)  # a safety net: seconds depend on load
        assert res.status == "optimal" and res.soc == expected, (seed, kw, res.status, res.soc, expected)
        assert validate(adj, starts, goals, res.paths) == []


def test_child_bounds_of_a_component_too_large_to_cover_exactly_stay_admissible():
    """A component of more than 12 vertices is covered by a packing bound; that bound minus d
    never exceeds the exact cover of the graph with i's edges lowered by d (checked by
    enumeration on 0/1 weights), and it is what the search takes for a child that raises agent
    i by d when the component is very large."""
    rng = random.Random(5)
    n = 13
    for _ in range(6):
        edges = {(i, i + 1): 1 for i in range(n - 1)}  # a path keeps it one component
        for i, j in itertools.combinations(range(n), 2):
            if j > i + 1 and rng.random() < 0.15:
                edges[(i, j)] = 1
        bound = min_vertex_cover(edges)
        for i in rng.sample(range(n), 3):
            reduced = {e: (w - 1 if i in e else w) for e, w in edges.items()}
            pairs = [e for e, w in reduced.items() if w > 0]
            exact = min(sum(x) for x in itertools.product((0, 1), repeat=n)
                        if all(x[a] + x[b] >= 1 for a, b in pairs))
            assert bound - 1 <= exact
    # the search takes that bound for a forced child of an agent in such a component
    m = 2 * (heuristics._CHILD_COVER_MAX + 2)
    starts, goals = list(range(0, m, 2)), list(range(1, m, 2))
    adj = [[v for v in (u - 1, u + 1) if 0 <= v < m] for u in range(m)]
    search, root = root_search(adj, starts, goals)
    root.hedges = {(i, i + 1): 2 for i in range(len(starts) - 1)}  # a path through every agent
    root.hmemo = None
    total = search._cover_memo(root)["total"]
    # agent 0 ends the path: the reduced graph's packing bound would be total - 2, below the
    # bound taken (total - 1); the node's own f is left at g so that no path-max hides it
    g, f = search._child_bound(root, 0, (), True)
    assert g == root.g + 1 and f == g + total - 1
