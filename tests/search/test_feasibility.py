"""The exhaustive feasibility check against the joint brute force, on generated corridors,
rings and trees, and the solvers reporting ``infeasible`` at once where it applies."""
import json
import time

import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc
from test_mapf_cli import write_instance

from agents.search.mapf import CBSSolver, MapfInstance, Proximity, solve_cbs
from agents.search.mapf.feasibility import configuration_count, joint_feasible
from baselines.cli import main


def undirected(pairs):
    edges = {}
    for u, v in pairs:
        edges[(u, v)] = 1
        edges[(v, u)] = 1
    return edges


def corridor_with_pocket(length, at):
    """A path ``0 .. length-1`` and a pocket node ``length`` hanging off node ``at``."""
    return length + 1, undirected([(i, i + 1) for i in range(length - 1)] + [(at, length)])


def ring(n):
    return n, undirected([(i, (i + 1) % n) for i in range(n)])


def random_tree(rng, n):
    return n, undirected([(i, int(rng.integers(0, i))) for i in range(1, n)])


def adjacency(n, edges):
    adj = [[] for _ in range(n)]
    for (u, v), d in sorted(edges.items()):
        adj[u].append((v, d))
    return adj


def generated(seed):
    """A small corridor-with-pocket, ring or tree, crowded with agents in random places."""
    rng = np.random.default_rng(seed)
    kind = seed % 3
    if kind == 0:
        length = int(rng.integers(4, 8))
        n, edges = corridor_with_pocket(length, int(rng.integers(0, length)))
    elif kind == 1:
        n, edges = ring(int(rng.integers(3, 8)))
    else:
        n, edges = random_tree(rng, int(rng.integers(4, 9)))
    k = int(rng.integers(2, min(n, 5)))
    starts = [int(x) for x in rng.choice(n, size=k, replace=False)]
    goals = [int(x) for x in rng.choice(n, size=k, replace=False)]
    return n, edges, starts, goals


@pytest.mark.parametrize("seed", range(60))
def test_joint_feasible_matches_brute_force_on_generated_instances(seed):
    n, edges, starts, goals = generated(seed)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="unit")
    expected = brute_force_soc(n, edges, starts, goals, unit=True) is not None
    assert joint_feasible(inst) is expected
    # no durative plan where no unit-time plan exists
    if not expected:
        assert brute_force_soc(n, edges, starts, goals, unit=False) is None


@pytest.mark.parametrize("seed", range(20))
def test_joint_feasible_with_proximity_matches_brute_force(seed):
    n, edges, starts, goals = generated(1000 + seed)
    rng = np.random.default_rng(seed)
    near = rng.random((n, n)) < 0.1
    near = near | near.T
    np.fill_diagonal(near, False)
    dist = np.where(near, 0.5, 5.0)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="unit", proximity=Proximity(dist, 1.0))
    expected = brute_force_soc(n, edges, starts, goals, unit=True, near=near.tolist()) is not None
    assert joint_feasible(inst) is expected


def test_classic_cases():
    # two agents cannot pass each other in a bare corridor, but can with a pocket off its middle
    n, edges = corridor_with_pocket(5, 2)
    bare = [[v for v in row if v != 5] for row in adjacency(n, edges)][:5]
    assert joint_feasible(MapfInstance(bare, [0, 4], [4, 0])) is False
    assert joint_feasible(MapfInstance(adjacency(n, edges), [0, 4], [4, 0])) is True
    # a pocket at the corridor's end: the agents cannot get past each other either way
    n, edges = corridor_with_pocket(5, 4)
    assert joint_feasible(MapfInstance(adjacency(n, edges), [0, 3], [3, 0])) is False
    # a full ring rotates, but two neighbours cannot trade places
    n, edges = ring(5)
    assert joint_feasible(MapfInstance(adjacency(n, edges), list(range(5)), [1, 2, 3, 4, 0])) is True
    assert joint_feasible(MapfInstance(adjacency(n, edges), list(range(5)), [1, 0, 2, 3, 4])) is False
    # undecided past the state limit
    n, edges = ring(8)
    assert joint_feasible(MapfInstance(adjacency(n, edges), [0, 4, 6], [4, 0, 2]), max_states=3) is None
    assert configuration_count(5, 2) == 20 and configuration_count(2, 3) == 0
    with pytest.raises(ValueError, match="max_states"):
        joint_feasible(MapfInstance(adjacency(n, edges), [0], [1]), max_states=0)


@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_solver_reports_infeasible_at_once(time_model):
    # three agents in a corridor of 9 must reverse their order; its one pocket, off the second
    # node, is too close to the end to let them: impossible (with the pocket off the middle
    # node any number of agents can reverse)
    n, edges = corridor_with_pocket(9, 1)
    t = time.perf_counter()
    res = solve_cbs(adjacency(n, edges), [0, 1, 2], [8, 7, 6], time_model=time_model,
                    time_limit=30)
    assert res.status == "infeasible" and "joint configurations" in res.message
    assert time.perf_counter() - t < 10  # far below the time limit it would otherwise reach
    # the same corridor where the order is kept: solved optimally as before, nothing changed
    ok = CBSSolver(adjacency(n, edges), [0, 1, 2], [6, 7, 8], time_model=time_model, time_limit=30).solve()
    assert ok.status == "optimal"
    assert ok.soc == brute_force_soc(n, edges, [0, 1, 2], [6, 7, 8], unit=time_model == "unit")
    off = CBSSolver(adjacency(n, edges), [0, 1, 2], [8, 7, 6], time_model=time_model, time_limit=0.3,
                    joint_check_states=0, merge_threshold=None).solve()
    assert off.status in ("timeout", "infeasible") and "joint configurations" not in off.message
    with pytest.raises(ValueError, match="joint_check_states"):
        CBSSolver(adjacency(n, edges), [0], [1], joint_check_states=-1)


def test_mapf_command_reports_infeasible_on_a_movingai_file(tmp_path, capsys):
    # a corridor of 9 cells with a pocket below its second cell; three agents must reverse order
    rows = ["@@@@@@@@@@@", "@.........@", "@@.@@@@@@@@", "@@@@@@@@@@@"]
    m, s = write_instance(tmp_path, rows, [((1, 1), (1, 9)), ((1, 2), (1, 8)), ((1, 3), (1, 7))])
    rc = main(["mapf", str(m), str(s), "--agents", "3", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert rc == 1 and report["status"] == "infeasible" and "joint configurations" in report["message"]


def test_an_impossible_enclosed_part_of_a_larger_graph_is_found():
    # the impossible corridor of nine with its pocket, beside a separate 6 x 6 open grid where
    # four more agents could move freely: the whole instance is far too large to enumerate
    n_c, edges = corridor_with_pocket(9, 1)
    adj = adjacency(n_c, edges)
    g = 6
    for r in range(g):
        for c in range(g):
            adj.append([n_c + (r + dr) * g + c + dc for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0))
                        if 0 <= r + dr < g and 0 <= c + dc < g])
    starts = [0, 1, 2] + [n_c + i for i in (0, 5, 30, 35)]
    goals = [8, 7, 6] + [n_c + i for i in (35, 30, 5, 0)]
    assert configuration_count(len(adj), len(starts)) > 10**9
    res = solve_cbs(adj, starts, goals, time_limit=30)
    assert res.status == "infeasible" and "agents [0, 1, 2]" in res.message
    # the same with the corridor's order kept is solved as usual
    ok = solve_cbs(adj, starts, [6, 7, 8] + goals[3:], time_limit=30)
    assert ok.status == "optimal"
