"""Impossible is not hard: generated corridors with one pocket, rings and trees crowded beyond
what passing, rotations and exchanges allow are reported ``infeasible`` before any search, by
CBS and by prioritised planning alike; possible ones are not (joint brute force decides)."""
import pytest
from cbs_bruteforce import brute_force_soc
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from test_feasibility import adjacency, corridor_with_pocket, ring, undirected

from agents.search.mapf import CBSSolver, MapfInstance, validate
from agents.search.mapf.prioritized import solve_prioritized


@st.composite
def crowded_instances(draw):
    """A corridor with one pocket, a ring or a random tree, with 2-4 agents on distinct starts
    and distinct goals (often in another order than they can reach)."""
    kind = draw(st.sampled_from(["corridor", "ring", "tree"]))
    if kind == "corridor":
        length = draw(st.integers(3, 7))
        n, edges = corridor_with_pocket(length, draw(st.integers(0, length - 1)))
    elif kind == "ring":
        n, edges = ring(draw(st.integers(3, 7)))
    else:
        n = draw(st.integers(3, 8))
        edges = undirected([(i, draw(st.integers(0, i - 1))) for i in range(1, n)])
    k = draw(st.integers(2, min(4, n - 1)))
    starts = draw(st.permutations(range(n)))[:k]
    goals = draw(st.permutations(range(n)))[:k]
    return n, edges, list(starts), list(goals)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(crowded_instances())
@example((8, undirected([(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (3, 7)]), [0, 1, 2, 3], [2, 1, 0, 3]))
def test_generated_instances_are_told_impossible_or_solved(case):
    n, edges, starts, goals = case
    optimum = brute_force_soc(n, edges, starts, goals, unit=True)
    inst = MapfInstance(adjacency(n, edges), starts, goals, time_model="unit")
    cbs = CBSSolver(inst, expansion_limit=50_000, time_limit=30).solve()
    pp = solve_prioritized(inst)
    if optimum is None:
        # decided before any search: CBS by its pairwise or joint check, PP by the joint check
        assert cbs.status == "infeasible" and cbs.stats.hl_expanded == 0, cbs.message
        assert pp.status == "infeasible" and "joint configurations" in pp.message, pp.message
        assert pp.work == 0
    else:
        # possible: never called impossible. CBS may run out of its budget where the agents must
        # reshuffle through a pocket (e.g. a corridor 0-...-6 with a pocket 7 at node 3, starts
        # [0, 1, 2, 3], goals [2, 1, 0, 3]: 31 steps in all, tens of thousands of expansions)
        assert cbs.status in ("optimal", "timeout"), cbs.message
        if cbs.solved:
            assert cbs.status == "optimal" and cbs.soc == optimum
        assert pp.status != "infeasible"
        if pp.solved:
            assert validate(inst, None, None, pp.paths) == [] and pp.soc >= optimum


def test_prioritized_joint_check_can_be_switched_off_and_is_checked():
    # three agents that must reverse their order in a corridor whose pocket is off its second node
    n, edges = corridor_with_pocket(9, 1)
    inst = MapfInstance(adjacency(n, edges), [0, 1, 2], [8, 7, 6], time_model="unit")
    assert solve_prioritized(inst).status == "infeasible"
    off = solve_prioritized(inst, joint_check_states=0, expansion_limit=5_000)
    assert off.status == "timeout" and off.work > 0  # incomplete: it only fails
    with pytest.raises(ValueError, match="joint_check_states"):
        solve_prioritized(inst, joint_check_states=-1)
