"""``--protocol paper``: the conventions of the paper's published evaluation code, on stand-in critics."""
from __future__ import annotations

import math
import types
from dataclasses import replace

import numpy as np
import pytest
from conftest import StraightLineAgent

import safe_mapf_envs
from baselines.methods import METHODS
from baselines.metrics import aggregate
from baselines.paper_protocol import (
    PAPER_C_MAX_FACTORS,
    PaperSetup,
    choose_best_c_max,
    evaluate_paper,
    execute_paper,
    grid_diameter,
    make_paper_problems,
    paper_targets,
)
from safe_mapf_envs.maps import GridMap

ENV = "SafeCenterDot-v0"


@pytest.fixture(scope="module")
def setup():
    env = safe_mapf_envs.parallel_env(ENV, n_agents=1)
    agent = StraightLineAgent(env.field, env.world_size)
    agent.lagrangian = types.SimpleNamespace(cost_limit=4.0)
    rng = np.random.default_rng(0)
    states = env.sample_states(150, rng)
    obs = env.observations_at(states)
    env.close()
    D, C = agent.pairwise(obs, obs)
    return PaperSetup(ENV, {"unconstrained": agent, "constrained": agent}, states, obs, D, C, D.copy(),
                      targets=paper_targets("CenterDot"))


def test_grid_diameter_counts_8_connected_hops_on_the_resized_grid():
    assert grid_diameter("CenterDot") == 17  # 15 x 15 cells around a 3 x 3 block
    assert paper_targets("CenterDot") == {"easy": 2, "medium": 4, "hard": 8}
    # a 1 x 4 corridor resized by 2: 8 x 2 cells, the far corners 7 hops apart (diagonals count 1)
    assert grid_diameter(GridMap("corridor", ("....",), resize_factor=2, cost_radius=1.0)) == 7
    # a wall splits the map: the diameter is the largest finite distance
    assert grid_diameter(GridMap("split", ("..#..",), resize_factor=1, cost_radius=1.0)) == 1


def test_problems_keep_the_pairs_nearest_to_the_target(setup):
    probs = make_paper_problems(setup, "hard", 3, 4, seed=5, candidates=12)
    again = make_paper_problems(setup, "hard", 3, 4, seed=5, candidates=12)
    other = make_paper_problems(setup, "hard", 3, 4, seed=6, candidates=12)
    assert [p.starts.tolist() for p in probs] == [p.starts.tolist() for p in again]
    assert [p.starts.tolist() for p in probs] != [p.starts.tolist() for p in other]
    assert all(p.target == 8 and p.n_agents == 3 and (p.start_nodes == -1).all() for p in probs)
    # redo the first draw: its 5 kept pairs are the 5 of 144 whose predicted distance is nearest to 8
    env = safe_mapf_envs.parallel_env(ENV, n_agents=1)
    rng = np.random.default_rng([5, 3, 2, 7])
    s, g = env.sample_states(12, rng), env.sample_states(12, rng)
    D = setup.models["unconstrained"].pairwise_distance(env.observations_at(s), env.observations_at(g))
    env.close()
    gap = np.sort(np.abs(D - 8).ravel())
    kept = np.concatenate([p.graph_distance for p in probs])[:5]
    assert np.allclose(np.sort(np.abs(kept - 8)), gap[:5])
    pairs = np.concatenate([p.starts for p in probs])[:5]
    for (x, y) in pairs:
        assert np.isclose(s, (x, y)).all(axis=1).any()


def test_hop_routes_always_have_a_waypoint_and_are_fewest_hops(setup):
    sorb = METHODS["sorb"]
    a, b = setup.observations[0], setup.observations[1]
    # even start == goal gets one waypoint: the endpoints attach only to buffer nodes
    routes = setup.plan_hops(sorb, np.stack([a, a]), np.stack([b, a]))
    assert all(r is not None and len(r) >= 1 for r in routes)
    # fewest hops: check against a breadth-first search on the explicit graph
    from scipy.sparse.csgraph import shortest_path

    n = len(setup.observations)
    adj = (setup.D_unc < setup.d_max).astype(float)
    np.fill_diagonal(adj, 0)
    hops = shortest_path(adj, unweighted=True)
    ds, dg = setup.D_unc[0] < setup.d_max, setup.D_unc[:, 1] < setup.d_max
    best = min(hops[i, j] for i in np.flatnonzero(ds) for j in np.flatnonzero(dg))
    route = routes[0]
    assert len(route) == best + 1 and ds[route[0]] and dg[route[-1]]
    assert all(adj[u, v] for u, v in zip(route[:-1], route[1:]))
    # ours drops costly edges; with a tiny c_max nothing is left and the run falls back to the policy
    tight = METHODS["ours"].with_options(c_max=1e-9)
    assert setup.plan_hops(tight, np.stack([a]), np.stack([b])) == [None]
    assert n == 150


def test_execution_follows_waypoints_and_falls_back_without_a_route(setup):
    env = safe_mapf_envs.parallel_env(ENV, n_agents=2, agent_collisions=False, max_cycles=60)
    prob = make_paper_problems(setup, "medium", 2, 1, seed=0, candidates=30)[0]
    ex = execute_paper(env, setup, METHODS["sorb"], prob)
    assert ex.plan_status == "planned" and min(ex.waypoints) >= 1 and ex.success
    tight = execute_paper(env, setup, METHODS["ours"].with_options(c_max=1e-9), prob)
    plain = execute_paper(env, setup, METHODS["constrained_policy"], prob)
    assert tight.plan_status == "fallback" and tight.steps == plain.steps
    assert np.allclose(tight.cost, plain.cost)
    env.close()


def test_a_lone_agent_counts_its_start_cost(setup):
    """A lone agent's cost includes its start state's; in a multi-agent run it does not (an
    identical twin passes through it, so both trajectories are the same)."""
    start, goal = np.array([[6.0, 5.5]]), np.array([[6.0, 3.5]])  # starts inside the block's cost radius
    prob = make_paper_problems(setup, "easy", 1, 1, seed=0, candidates=5)[0]
    one = replace(prob, starts=start, goals=goal)
    two = replace(prob, starts=np.repeat(start, 2, 0), goals=np.repeat(goal, 2, 0))
    env1 = safe_mapf_envs.parallel_env(ENV, n_agents=1, agent_collisions=False)
    env2 = safe_mapf_envs.parallel_env(ENV, n_agents=2, agent_collisions=False)
    lone = execute_paper(env1, setup, METHODS["constrained_policy"], one)
    twins = execute_paper(env2, setup, METHODS["constrained_policy"], two)
    _, infos = env1.reset(options={"starts": start, "goals": goal})
    start_cost = infos["agent_0"]["cost"]
    assert start_cost > 0 and lone.success and twins.success and lone.steps == twins.steps
    assert np.isclose(twins.cost[0], twins.cost[1])
    assert np.isclose(lone.cost[0], twins.cost[0] + start_cost)
    env1.close()
    env2.close()


def test_agents_pass_through_each_other_only_when_asked():
    starts, goals = [(2.0, 2.0), (5.0, 2.0)], [(5.0, 2.0), (2.0, 2.0)]
    for collide in (True, False):
        env = safe_mapf_envs.parallel_env(ENV, n_agents=2, agent_collisions=collide)
        env.reset(seed=0, options={"starts": starts, "goals": goals})
        contacts = 0
        for _ in range(4):
            acts = {a: np.array([1.0, 0.0]) if a == "agent_0" else np.array([-1.0, 0.0]) for a in env.agents}
            _, _, _, _, infos = env.step(acts)
            contacts += sum(i["collisions"] for i in infos.values())
        assert (contacts > 0) == collide
        assert env.parked.all() != collide  # head-on, only agents that pass each other both arrive
        env.close()
    env = safe_mapf_envs.parallel_env(ENV, n_agents=2, agent_collisions=False)
    env.reset(options={"starts": [(2, 2), (2, 2)]})  # overlapping starts are fine without collisions
    with pytest.raises(ValueError, match="would overlap"):
        safe_mapf_envs.parallel_env(ENV, n_agents=2).reset(options={"starts": [(2, 2), (2, 2)]})
    with pytest.raises(ValueError, match="agent_collisions must be True or False"):
        safe_mapf_envs.parallel_env(ENV, n_agents=2, agent_collisions="no")


def test_best_c_max_is_chosen_per_cell_by_success_then_cost():
    def row(c, ok, cost, k=5, d="hard"):
        return {"method": "ours", "agents": k, "difficulty": d, "c_max": c, "success": ok, "cost_max": cost,
                "cost_mean": cost, "collisions": 0, "steps": 1, "planning_time": 0.0}

    rows = [row(0.4, True, 1.0), row(0.4, False, 0.0),  # cheapest, but 50% success
            row(1.0, True, 3.0), row(1.0, True, 2.0),  # 100%, mean 2.5
            row(2.0, True, 2.0), row(2.0, True, 3.5),  # 100%, mean 2.75
            row(0.4, True, 9.0, k=1), row(1.0, True, 4.0, k=1),
            {**row(math.inf, True, 7.0), "method": "sorb"}]
    kept, chosen = choose_best_c_max(rows)
    assert chosen == {(5, "hard"): 1.0, (1, "hard"): 1.0}
    assert len(kept) == 4 and {r["c_max"] for r in kept if r["method"] == "ours"} == {1.0}
    agg = {(a["method"], a["agents"]): a for a in aggregate(kept)}
    assert agg[("ours", 5)]["cost_mean"] == 2.5 and agg[("sorb", 5)]["cost_mean"] == 7.0


def test_evaluate_paper_runs_ours_once_per_c_max(setup):
    methods = [METHODS[m] for m in ("unconstrained_policy", "sorb", "ours")]
    rows = evaluate_paper(setup, methods, [1, 2], ["easy"], 2, progress=False, policy_agents=[1], candidates=20)
    grid = setup.c_max_grid()
    assert grid == [4.0 * f for f in PAPER_C_MAX_FACTORS]
    ours = [r for r in rows if r["method"] == "ours"]
    assert sorted({r["c_max"] for r in ours}) == grid and len(ours) == 2 * 2 * len(grid)
    assert not any(r["method"] == "unconstrained_policy" and r["agents"] == 2 for r in rows)
    assert all(r["collisions"] == 0 for r in rows)
    with pytest.raises(ValueError, match="paper's protocol defines"):
        evaluate_paper(setup, [METHODS["ours_budget"]], [1], ["easy"], 1, progress=False)


def test_paper_protocol_on_ray_gives_the_serial_rows_in_order(setup):
    ray = pytest.importorskip("ray")
    import sys

    # the stand-in agent's class lives in the tests' conftest, which workers cannot import: ship it by value
    ray.cloudpickle.register_pickle_by_value(sys.modules[StraightLineAgent.__module__])
    methods = [METHODS[m] for m in ("unconstrained_policy", "sorb", "ours")]
    kwargs = dict(agent_counts=[1, 2], difficulties=["easy", "hard"], n_problems=1, seed=3, progress=False,
                  policy_agents=[1], candidates=20, max_cycles=80)
    serial, arrived = [], []
    rows = evaluate_paper(setup, methods, on_row=serial.append, **kwargs)
    try:
        on_ray = evaluate_paper(setup, methods, ray="local", on_row=arrived.append, **kwargs)
    finally:
        ray.shutdown()
    assert len(rows) == 2 * (1 + 1 + len(PAPER_C_MAX_FACTORS)) + 2 * (1 + len(PAPER_C_MAX_FACTORS))
    assert on_ray == rows and arrived == serial == rows  # the same rows, handed on in the serial order
    assert any(r["success"] for r in rows) and any(r["plan_status"] == "planned" for r in rows)


def test_paper_protocol_command_refuses_what_does_not_apply(tmp_path, capsys):
    from baselines.cli import main

    assert main(["evaluate", "--protocol", "paper", "--env", "SafeApartment0-v0", "--fallback",
                 "--out", str(tmp_path)]) == 2
    assert "--fallback does not apply" in capsys.readouterr().err
    assert main(["evaluate", "--protocol", "paper", "--env", ENV, "--c-max", "0.5", "--out", str(tmp_path)]) == 2
    assert "--c-max does not apply" in capsys.readouterr().err
    assert main(["evaluate", "--protocol", "paper", "--env", ENV, "--methods", "ours_budget",
                 "--out", str(tmp_path)]) == 2
    assert "ours_budget" in capsys.readouterr().err
    assert not (tmp_path / "c_max.json").exists()


def test_centerdot_table_sets_three_numbers_per_cell(setup, tmp_path, capsys, monkeypatch):
    """examples/centerdot_table.py reads a paper-protocol folder (keeping the chosen c_max only)
    and strict folders, and prints the paper's number beside both of ours in every cell."""
    import importlib.util
    import json
    import sys
    from pathlib import Path

    from baselines.evaluation import write_csv

    methods = [METHODS[m] for m in ("unconstrained_policy", "sorb", "constrained_policy", "ours")]
    rows = evaluate_paper(setup, methods, [1, 5], ["easy"], 2, progress=False, policy_agents=[1], candidates=20)
    kept, chosen = choose_best_c_max(rows)
    paper, strict = tmp_path / "paper", tmp_path / "strict"
    write_csv(rows, paper / "runs.csv")
    (paper / "c_max.json").write_text(json.dumps(
        {"chosen_on": "the test problems", "chosen": [{"agents": k, "difficulty": d, "c_max": c}
                                                      for (k, d), c in chosen.items()]}))
    write_csv(kept, strict / "runs.csv")
    path = Path(__file__).resolve().parents[2] / "examples" / "centerdot_table.py"
    spec = importlib.util.spec_from_file_location("centerdot_table", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(sys, "argv", ["centerdot_table.py", str(paper), str(strict)])
    module.main()
    out = capsys.readouterr().out
    easy5 = next(line for line in out.splitlines() if line.startswith("| Easy | 5 |"))
    assert easy5.count("<br>") == 8 and "1.68 ± 1.21 (100%)" in easy5  # the paper's ours, easy, 5 agents
    medium5 = next(line for line in out.splitlines() if line.startswith("| Medium | 5 |"))
    assert "5.12 ± 3.65 (100%)<br>n/a<br>n/a" in medium5  # the paper's SoRB; nothing of ours was run
    assert "SoRB + CBS and ours cells" in out and "Strict protocol" in out
    agg = {(a["method"], a["agents"]): a for a in aggregate(kept)}
    assert f"{agg[('ours', 5)]['cost_mean']:.2f}" in easy5


def test_apartments_take_their_targets_from_the_geodesic_diameter_in_steps():
    import gymnasium as gym

    from baselines.paper_protocol import step_diameter

    env = gym.make("SafeCenterDot-v0")  # a grid map: both measures exist and roughly agree
    d = step_diameter(env)
    assert grid_diameter("CenterDot") <= d <= np.hypot(*env.unwrapped.scenario.size)
    apt = gym.make("SafeApartment0-v0")
    u = apt.unwrapped
    steps = step_diameter(apt)
    assert steps == int(u.scenario.oracle.max_distance / u.action_scale) and steps > 40  # a 14 m walk, 0.25 m steps
    assert paper_targets("Apartment0", steps) == {"easy": steps // 8, "medium": steps // 4, "hard": steps // 2}


def test_paper_cells_run_apart_give_the_rows_of_one_run(tmp_path, capsys):
    """examples/paper_cells.py: each cell in its own process, merged in the order of one run, gives
    the rows one command over all cells writes; finished cells are not run again."""
    import importlib.util
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("paper_cells", root / "examples" / "paper_cells.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    common = ["--env", ENV, "--agents", "2", "1", "--difficulty", "easy", "--problems", "2", "--nodes", "60",
              "--paper-candidates", "20", "--methods", "sorb", "ours"]
    assert module.main([*common, "--workers", "2", "--keep-cells", "--out", str(tmp_path / "cells")]) == 0
    assert "| Easy | 2 |" in capsys.readouterr().out
    subprocess.run([sys.executable, "-m", "baselines.cli", "evaluate", "--protocol", "paper", *common,
                    "--no-figure", "--no-progress", "--out", str(tmp_path / "one")], check=True, cwd=root,
                   capture_output=True)
    for name in ("runs.csv", "c_max.json"):
        assert (tmp_path / "cells" / name).read_text() == (tmp_path / "one" / name).read_text()
    assert (tmp_path / "cells" / "cells" / "1_easy.log").exists()
    assert module.main([*common, "--workers", "1", "--out", str(tmp_path / "cells")]) == 0
    assert "2 already run" in capsys.readouterr().err
    assert not (tmp_path / "cells" / "cells").exists()  # merged again, then the cells removed
    assert (tmp_path / "cells" / "runs.csv").read_text() == (tmp_path / "one" / "runs.csv").read_text()
