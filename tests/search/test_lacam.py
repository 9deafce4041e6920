"""The LaCAM* configuration search: optimal sums of costs and infeasibility proofs against the brute
force on small random graphs (unit and durative time, proximity), the tiny coupled MovingAI
instances against CBS, crowds on grids and buffer-like graphs (valid plans), a medium MovingAI
instance, determinism, budgets, bad input, the command line and the planner."""
import json
from pathlib import Path

import numpy as np
import pytest
from cbs_bruteforce import brute_force_soc
from test_cbs_bruteforce import adjacency, pick, random_graph
from test_pibt import buffer_like, open_grid
from test_planner import _crossing_problem, _validate_plan, euclid_pairwise, grid_points, make_planner
from test_prioritized import random_proximity

from agents.search.mapf import MapfInstance, load_instance, solve_cbs, solve_lacam, validate
from baselines.cli import main

DATA = Path(__file__).resolve().parents[2] / "examples" / "data" / "movingai"
TINY = DATA / "tiny"
TINY_NAMES = sorted(p.stem for p in TINY.glob("*.map"))


def tiny(name):
    grid = load_instance(TINY / f"{name}.map", TINY / f"{name}.scen")
    return grid, MapfInstance(grid.graph, grid.starts, grid.goals)


@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_the_optimum_or_infeasibility_of_small_random_instances_matches_the_brute_force(time_model):
    optimal = infeasible = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(5, 9))
        edges = random_graph(rng, n, 0.3, directed=seed % 3 == 0, max_dur=1 if time_model == "unit" else 3)
        prox, near = random_proximity(rng, n, 0.1) if seed % 2 else (None, None)
        k = int(rng.integers(2, 4))
        starts, goals = pick(rng, n, k, crossing=seed % 4 == 1)
        adj = adjacency(n, edges)
        expected = brute_force_soc(n, edges, starts, goals, unit=time_model == "unit", near=near)
        res = solve_lacam(MapfInstance(adj, starts, goals, time_model=time_model, proximity=prox),
                          expansion_limit=2_000_000)
        if expected is None:
            assert res.status == "infeasible" and res.paths is None, (seed, res.status, res.message)
            infeasible += 1
            continue
        assert res.status == "optimal" and res.soc == expected, (seed, res.status, res.soc, expected, res.message)
        assert validate(adj, starts, goals, res.paths, time_model=time_model, proximity=prox) == []
        assert res.soc == sum(p[-1][1] for p in res.paths) and res.lower_bound == res.soc
        optimal += 1
    assert optimal >= 25 and infeasible >= 5, (optimal, infeasible)


@pytest.mark.parametrize("name", TINY_NAMES)
def test_tiny_coupled_instances_reach_the_optimum_cbs_finds_or_are_proven_infeasible(name):
    grid, inst = tiny(name)
    res = solve_lacam(inst, expansion_limit=5_000_000)
    if name.startswith("infeasible-"):
        assert res.status == "infeasible" and "exhausted every configuration" in res.message, res.message
        return
    cbs = solve_cbs(grid.graph, grid.starts, grid.goals, time_limit=10)
    assert cbs.status == "optimal"
    assert res.status == "optimal" and res.soc == cbs.soc, (res.status, res.soc, cbs.soc, res.message)
    assert validate(inst, None, None, res.paths) == []
    first = solve_lacam(inst, anytime=False)
    assert first.solved and first.soc >= res.soc  # the first solution, before any refinement


def test_unit_time_allows_rotations_the_durative_model_forbids():
    ring = [[1, 3], [0, 2], [1, 3], [2, 0]]  # four agents on a ring of four, each one node on
    res = solve_lacam(MapfInstance(ring, [0, 1, 2, 3], [1, 2, 3, 0]))
    assert res.status == "optimal" and res.soc == 4 and res.makespan == 1
    assert validate(ring, [0, 1, 2, 3], [1, 2, 3, 0], res.paths) == []
    # occupying both ends of an edge while on it, nobody can move: no plan
    res = solve_lacam(MapfInstance(ring, [0, 1, 2, 3], [1, 2, 3, 0], time_model="durative"))
    assert res.status == "infeasible"


@pytest.mark.parametrize("time_model", ["unit", "durative"])
def test_a_grid_crowd_is_solved_with_a_valid_plan(time_model):
    adj = open_grid(8)
    rng = np.random.default_rng(0)
    starts, goals = (rng.permutation(64)[:40].tolist() for _ in range(2))
    inst = MapfInstance(adj, starts, goals, time_model=time_model)
    res = solve_lacam(inst, expansion_limit=300_000)
    assert res.status == "suboptimal", res.message
    assert validate(adj, starts, goals, res.paths, time_model=time_model) == []
    assert res.lower_bound <= res.soc == sum(p[-1][1] for p in res.paths)
    assert res.stats.configurations > 0 and res.stats.generations > 0 and res.work > 0 and res.solver == "lacam"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_buffer_like_crowds_with_durative_edges_and_proximity_are_solved(seed):
    inst = buffer_like(seed)
    res = solve_lacam(inst, expansion_limit=600_000)
    assert res.status == "suboptimal", res.message
    assert validate(inst, None, None, res.paths) == []
    # the goals have no way out: every agent arrives there once, at the end of its path
    for i, p in enumerate(res.paths):
        assert [v for v, _ in p].count(inst.goals[i]) == 1


def test_a_medium_movingai_instance_is_solved_and_refined():
    grid = load_instance(DATA / "maps" / "random-32-32-10.map", DATA / "scens" / "random-32-32-10-random-1.scen", 100)
    inst = MapfInstance(grid.graph, grid.starts, grid.goals)
    first = solve_lacam(inst, anytime=False)
    assert first.status == "suboptimal" and "first solution" in first.message
    assert validate(inst, None, None, first.paths) == []
    assert first.soc < 1.5 * first.lower_bound
    refined = solve_lacam(inst, expansion_limit=1_000_000)
    assert refined.status == "suboptimal" and "expansion limit of 1000000 reached" in refined.message
    assert refined.soc <= first.soc and validate(inst, None, None, refined.paths) == []


def test_same_seed_same_result():
    inst = buffer_like(4)
    a, b = (solve_lacam(inst, expansion_limit=200_000) for _ in range(2))
    assert a.paths == b.paths and a.work == b.work
    assert a.stats == b.stats
    crowd = MapfInstance(open_grid(8), *(np.random.default_rng(1).permutation(64)[:40].tolist() for _ in range(2)))
    c, d = (solve_lacam(crowd, seed=5, anytime=False) for _ in range(2))
    assert c.solved and c.paths == d.paths


def test_budgets_end_the_search():
    inst = buffer_like(2)
    res = solve_lacam(inst, expansion_limit=100)
    assert res.status == "timeout" and res.paths is None
    assert "expansion limit of 100 reached before a plan was found" in res.message
    assert res.work > 100
    res = solve_lacam(inst, time_limit=1e-9)
    assert res.status == "timeout" and "time limit" in res.message
    # a plan found, then the budget ends the refinement: the best plan so far
    res = solve_lacam(inst, expansion_limit=200_000)
    assert res.status == "suboptimal" and "expansion limit of 200000 reached" in res.message


def test_infeasible_and_bad_input():
    res = solve_lacam(MapfInstance([[1], [0], []], [0, 2], [1, 0]))
    assert res.status == "infeasible" and "agent 1" in res.message
    near = np.full((4, 4), 5.0)
    near[0, 1] = near[1, 0] = 0.5
    ring = [[1, 3], [0, 2], [1, 3], [2, 0]]
    res = solve_lacam(MapfInstance(ring, [0, 1], [2, 3], proximity=(near, 1.0)))
    assert res.status == "infeasible" and "starts of agents 0 and 1" in res.message
    empty = solve_lacam(MapfInstance(ring, [], []))
    assert empty.status == "optimal" and empty.paths == []
    alone = solve_lacam(MapfInstance(ring, [0], [2]))
    assert alone.status == "optimal" and alone.soc == 2
    inst = MapfInstance(ring, [0], [2])
    for kw, match in ((dict(seed=1.5), "seed"), (dict(expansion_limit=0), "expansion_limit"),
                      (dict(time_limit=0), "time_limit")):
        with pytest.raises(ValueError, match=match):
            solve_lacam(inst, **kw)


def test_the_command_line_runs_lacam(capsys):
    m, s = str(TINY / "pocket.map"), str(TINY / "pocket.scen")
    assert main(["mapf", m, s, "--agents", "3", "--solver", "lacam", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["solver"] == "lacam" and report["status"] == "optimal" and report["soc"] == 25
    assert report["valid"] is True and report["seed"] == 0 and report["suboptimality"] is None
    assert main(["mapf", m, s, "--agents", "3", "--solver", "lacam", "--first-solution", "--seed", "2"]) == 0
    assert "lacam" in capsys.readouterr().out
    assert main(["mapf", m, s, "--agents", "3", "--solver", "lacam", "--suboptimality", "1.5"]) == 2
    assert "--suboptimality does not apply to --solver lacam" in capsys.readouterr().err
    assert main(["mapf", m, s, "--agents", "3", "--seed", "3"]) == 2
    assert "--seed does not apply to --solver cbs" in capsys.readouterr().err


def test_the_planner_searches_configurations():
    pts = grid_points(12)
    starts, goals = _crossing_problem(24)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=0.9)
    plan = planner.with_options(solver="lacam", lacam_expansions_per_agent=5_000).plan(starts, goals)
    assert plan.solved and plan.solver == "lacam", plan.message
    assert _validate_plan(plan, 24, 0.9) == []
    assert plan.soc == sum(plan.arrival_times)
    assert planner.with_options(solver="lacam").solver_config.lacam_expansions_per_agent == 20_000
    with pytest.raises(ValueError, match="lacam_expansions_per_agent"):
        planner.with_options(lacam_expansions_per_agent=0)
