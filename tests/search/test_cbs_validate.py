"""The independent validator catches every kind of planted violation and never raises on them."""
import numpy as np
import pytest

from agents.search.mapf import Proximity, solve_cbs, validate

# a 3x3 grid, nodes numbered row by row
W = 3
PAIRS = [(r * W + c, r * W + c + 1) for r in range(W) for c in range(W - 1)]
PAIRS += [(r * W + c, (r + 1) * W + c) for r in range(W - 1) for c in range(W)]
ADJ = [[] for _ in range(W * W)]
for u, v in PAIRS:
    ADJ[u].append(v)
    ADJ[v].append(u)


def kinds(problems):
    return " | ".join(problems)


def test_a_valid_solution_has_no_violations():
    res = solve_cbs(ADJ, [0, 2, 6], [8, 6, 2])
    assert res.status == "optimal"
    assert validate(ADJ, [0, 2, 6], [8, 6, 2], res.paths) == []
    # plain node sequences are accepted too
    assert validate(ADJ, [0, 2, 6], [8, 6, 2], res.node_sequences()) == []


def test_vertex_conflict():
    probs = validate(ADJ, [0, 2], [4, 4 + 1], [[0, 1, 4], [2, 1, 4, 5]])
    assert any("vertex conflict" in p and "node 1" in p and "t=1" in p for p in probs), kinds(probs)


def test_swap_conflict():
    probs = validate(ADJ, [0, 1], [1, 0], [[0, 1], [1, 0]])
    assert any("swap conflict" in p for p in probs), kinds(probs)


def test_target_conflict():
    # agent 0 parks at 1 at t=1; agent 1 drives through node 1 at t=2
    probs = validate(ADJ, [1, 0], [1, 2], [[1], [0, 0, 1, 2]])
    assert any("target conflict" in p and "parked" in p for p in probs), kinds(probs)


def test_proximity_conflict():
    pos = np.array([[r, c] for r in range(W) for c in range(W)], float)
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    paths = [[0, 1, 2], [6, 7, 8]]  # two rows apart: fine with radius 1.5
    assert validate(ADJ, [0, 6], [2, 8], paths, proximity=Proximity(dist, 1.5)) == []
    paths = [[0, 1, 2], [3, 4, 5]]  # neighbouring rows: distance 1
    probs = validate(ADJ, [0, 3], [2, 5], paths, proximity=(dist, 1.5))
    assert any("proximity conflict" in p for p in probs), kinds(probs)
    assert validate(ADJ, [0, 3], [2, 5], paths) == []  # no proximity rule: valid


def test_bad_edge_bad_start_bad_goal():
    probs = validate(ADJ, [0], [8], [[0, 4, 8]])  # diagonal jumps
    assert any("no such edge" in p for p in probs), kinds(probs)
    probs = validate(ADJ, [0], [2], [[1, 2]])
    assert any("starts at" in p for p in probs), kinds(probs)
    probs = validate(ADJ, [0], [2], [[0, 1]])
    assert any("instead of its goal" in p for p in probs), kinds(probs)


def test_durative_model_checks_durations_and_occupancy():
    adj = [[(1, 3)], [(0, 3), (2, 1)], [(1, 1)]]
    good = [[(0, 0), (1, 3)]]
    assert validate(adj, [0], [1], good, time_model="durative") == []
    probs = validate(adj, [0], [1], [[(0, 0), (1, 1)]], time_model="durative")
    assert any("takes 1 steps, the edge takes 3" in p for p in probs), kinds(probs)
    # agent 1 waits at 1 while agent 0 is still traversing 0 -> 1: both occupy node 1
    probs = validate(adj, [0, 1], [1, 2], [[(0, 0), (1, 3)], [(1, 0), (1, 1), (2, 2)]], time_model="durative")
    assert any("vertex conflict" in p and "during step" in p for p in probs), kinds(probs)
    # leaving before the other agent starts in: fine
    assert validate(adj, [0, 1], [1, 2], [[(0, 0), (0, 1), (1, 4)], [(1, 0), (2, 1)]], time_model="durative") == []


@pytest.mark.parametrize("paths", [
    None,
    [[0, 1]],
    [[], [2]],
    [[0, "x"], [2]],
    [[(0, 0), (1, 0)], [2]],
    [[0, 1, 99], [2]],
    [[(0, 0), (1, 1, 1)], [2]],
])
def test_malformed_solutions_are_reported_not_raised(paths):
    probs = validate(ADJ, [0, 2], [1, 2], paths)
    assert probs and all(isinstance(p, str) for p in probs)
