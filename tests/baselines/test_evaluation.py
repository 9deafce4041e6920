"""The evaluation harness: problems, execution in the PettingZoo env, aggregation, the table."""
import json
import math

import numpy as np
import pytest

import safe_mapf_envs
from agents.search.execution.stats import ACTIVITIES
from baselines.evaluation import (
    EvaluationSetup,
    c_max_grid,
    evaluate,
    make_problems,
    markdown_table,
    write_csv,
)
from baselines.methods import METHODS, execute, get_methods
from baselines.metrics import aggregate


@pytest.fixture(scope="module")
def setup(stand_in_models):
    import gymnasium as gym

    from agents.self_sampling import observations_at

    env = gym.make("SafeCentralObstacle-v0")
    states = env.unwrapped.sample_states(250, np.random.default_rng(0))
    obs = observations_at(env, states)
    env.close()
    D, C = stand_in_models["unconstrained"].pairwise(obs, obs)
    return EvaluationSetup("SafeCentralObstacle-v0", stand_in_models, states, obs, D, C)


def test_problems_follow_the_protocol(setup):
    target = setup.target("medium")
    assert target == pytest.approx(setup.max_finite_distance / 4)
    probs = make_problems(setup, "medium", 4, 3, seed=7)
    again = make_problems(setup, "medium", 4, 3, seed=7)
    for p, q in zip(probs, again):  # reproducible
        np.testing.assert_array_equal(p.start_nodes, q.start_nodes)
        np.testing.assert_array_equal(p.goal_nodes, q.goal_nodes)
    for p in probs:
        assert p.n_agents == 4
        assert ((p.graph_distance >= 0.8 * target) & (p.graph_distance <= 1.2 * target)).all()
        for pts in (p.starts, p.goals):
            d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
            assert d[np.triu_indices(4, 1)].min() >= 2.5
    other = make_problems(setup, "medium", 4, 3, seed=8)
    assert any((p.start_nodes != q.start_nodes).any() for p, q in zip(probs, other))
    with pytest.raises(ValueError, match="difficulty"):
        make_problems(setup, "extreme", 1, 1)


def test_search_beats_the_straight_line_past_the_obstacle(setup):
    """Across the central block, the straight-line policy gets stuck; SoRB+CBS gets through
    and the cost-pruned search pays less cost than the distance-only one."""
    env = safe_mapf_envs.parallel_env(setup.env_id, n_agents=2, max_cycles=150)
    starts = np.array([[4.0, 27.5], [27.5, 4.0]])
    goals = np.array([[51.0, 27.5], [27.5, 51.0]])
    direct = execute(env, METHODS["unconstrained_policy"], setup.models, setup.planner, starts, goals)
    sorb = execute(env, METHODS["sorb"], setup.models, setup.planner, starts, goals)
    ours = execute(env, METHODS["ours"], setup.models, setup.planner, starts, goals)
    assert not direct.success
    assert sorb.success and ours.success
    assert sorb.plan_status in ("optimal", "suboptimal")
    assert ours.cost.max() < sorb.cost.max()
    budget = execute(env, METHODS["ours_budget"], setup.models, setup.planner, starts, goals)
    assert budget.success and budget.cost.max() < sorb.cost.max()
    assert sorb.trajectories.shape == (sorb.steps + 1, 2, 2)
    env.close()


def test_evaluate_aggregate_and_table(setup, tmp_path):
    rows = evaluate(setup, get_methods(["sorb", "ours"]), agent_counts=[2], difficulties=["easy"],
                    n_problems=2, progress=False)
    assert len(rows) == 4
    assert {r["method"] for r in rows} == {"sorb", "ours"}
    agg = aggregate(rows)
    assert len(agg) == 2
    for a in agg:
        assert 0.0 <= a["success_rate"] <= 1.0 and a["runs"] == 2
    write_csv(rows, tmp_path / "runs.csv")
    assert (tmp_path / "runs.csv").read_text().splitlines()[0].startswith("method,agents,difficulty")


def test_aggregate_hand_computed():
    rows = [
        {"method": "m", "agents": 5, "difficulty": "easy", "success": True, "cost_max": 1.0, "cost_mean": 0.5,
         "collisions": 0, "steps": 10, "planning_time": 0.1},
        {"method": "m", "agents": 5, "difficulty": "easy", "success": True, "cost_max": 3.0, "cost_mean": 1.5,
         "collisions": 2, "steps": 20, "planning_time": 0.3},
        {"method": "m", "agents": 5, "difficulty": "easy", "success": False, "cost_max": 99.0, "cost_mean": 9.0,
         "collisions": 7, "steps": 300, "planning_time": 0.2},
        {"method": "n", "agents": 5, "difficulty": "easy", "success": False, "cost_max": 5.0, "cost_mean": 5.0,
         "collisions": 0, "steps": 300, "planning_time": 0.0},
    ]
    agg = {a["method"]: a for a in aggregate(rows)}
    m = agg["m"]
    assert m["success_rate"] == pytest.approx(2 / 3)
    assert m["cost_mean"] == pytest.approx(2.0) and m["cost_std"] == pytest.approx(1.0)
    assert m["mean_cost_mean"] == pytest.approx(1.0)
    assert m["steps_mean"] == pytest.approx(15.0)
    assert m["cost_median"] == pytest.approx(2.0) and math.isnan(agg["n"]["cost_median"])
    assert agg["n"]["success_rate"] == 0 and math.isnan(agg["n"]["cost_mean"])
    table = markdown_table(list(agg.values()), ["m", "n"], bold_min_success=0.5)
    lines = table.splitlines()
    assert lines[0].startswith("| Problem | Agents | m | n |")
    assert lines[2] == "| Easy | 5 | **2.00 ± 1.00 (67%)** | - (0%) |"
    # by default a method needs 90% success to be marked best
    assert markdown_table(list(agg.values()), ["m", "n"]).splitlines()[2] == "| Easy | 5 | 2.00 ± 1.00 (67%) | - (0%) |"


def test_unknown_method_is_named():
    with pytest.raises(ValueError, match="unknown method 'magic'"):
        get_methods(["magic"])


def test_evaluate_command_with_shipped_checkpoints(tmp_path, capsys):
    """The CLI end to end on a tiny grid: JSON aggregate rows, CSV and Markdown files."""

    from baselines.cli import main

    code = main(["evaluate", "--agents", "2", "--problems", "1", "--difficulty", "easy", "--methods", "sorb",
                 "ours", "--nodes", "150", "--no-figure", "--json", "--out", str(tmp_path)])
    assert code == 0
    agg = json.loads(capsys.readouterr().out)
    assert {a["method"] for a in agg} == {"sorb", "ours"}
    for a in agg:
        assert a["agents"] == 2 and a["difficulty"] == "easy"
        assert {"success_rate", "cost_mean", "cost_std", "mean_cost_mean"} <= set(a)
    table = (tmp_path / "table.md").read_text()
    assert "Constrained Search (Ours, CBS)" in table and "| Easy | 2 |" in table
    assert (tmp_path / "runs.csv").exists() and (tmp_path / "table.csv").exists()


def test_policy_only_methods_run_only_where_asked(setup):
    rows = evaluate(setup, get_methods(["unconstrained_policy", "sorb"]), agent_counts=[1, 2], difficulties=["easy"],
                    n_problems=1, progress=False, policy_agents=[1])
    cells = {(r["method"], r["agents"]) for r in rows}
    assert cells == {("unconstrained_policy", 1), ("sorb", 1), ("sorb", 2)}
    assert all(math.isinf(r["c_max"]) for r in rows)


def test_c_max_grid_comes_from_the_graph(setup):
    grid = c_max_grid(setup)
    keep = (setup.D < setup.planner.graph.d_max) & (setup.C > 0)
    np.fill_diagonal(keep, False)
    costs = setup.C[keep]
    assert grid == sorted(grid) and 1 <= len(grid) <= 3
    assert costs.min() <= grid[0] and grid[-1] <= costs.max()
    assert grid[len(grid) // 2] == pytest.approx(np.median(costs), rel=1e-2)


def test_c_max_is_chosen_on_validation_problems_only(setup, monkeypatch):
    """select_c_max draws every problem with the validation seed, refuses the test seed, and the
    chosen cut-off per agent count is the cheapest among the most successful candidates."""
    import baselines.evaluation as ev

    seeds = []
    real = ev.make_problems

    def spy(s, difficulty, n_agents, n_problems, seed=0, **kw):
        seeds.append(seed)
        return real(s, difficulty, n_agents, n_problems, seed=seed, **kw)

    monkeypatch.setattr(ev, "make_problems", spy)
    grid = [0.05, 1.0, 50.0]
    sel = ev.select_c_max(setup, METHODS["ours"], [1, 2], ["hard"], grid=grid, n_problems=2, seed=123, test_seed=0,
                          progress=False)
    assert seeds and set(seeds) == {123}
    assert set(sel.chosen) == {1, 2} and all(c in grid for c in sel.chosen.values())
    assert sel.seed == 123 and {r["c_max"] for r in sel.rows} == set(grid)
    for k in (1, 2):
        cands = [t for t in sel.table if t["agents"] == k]
        best = max(t["success_rate"] for t in cands)
        ok = [t for t in cands if t["success_rate"] >= best - 0.05]
        assert sel.chosen[k] == min(ok, key=lambda t: (t["cost_mean"], -t["c_max"]))["c_max"]
    # test problems are drawn with another seed and so differ from the validation ones
    val = real(setup, "hard", 2, 2, seed=123)
    test = real(setup, "hard", 2, 2, seed=0)
    assert any((a.start_nodes != b.start_nodes).any() for a, b in zip(val, test))
    with pytest.raises(ValueError, match="validation seed must differ from the test seed"):
        ev.select_c_max(setup, METHODS["ours"], [1], grid=grid, seed=0, test_seed=0, progress=False)
    with pytest.raises(ValueError, match="no cost cut-off"):
        ev.select_c_max(setup, METHODS["sorb"], [1], grid=grid, seed=1, test_seed=0, progress=False)
    with pytest.raises(ValueError, match="positive"):
        ev.select_c_max(setup, METHODS["ours"], [1], grid=[0.0, 1.0], seed=1, test_seed=0, progress=False)


def test_evaluate_command_c_max_auto_writes_its_choice(tmp_path, capsys):
    from baselines.cli import main

    code = main(["evaluate", "--agents", "1", "2", "--problems", "1", "--difficulty", "hard", "--methods",
                 "unconstrained_policy", "ours", "--policies-at", "1", "--nodes", "150", "--no-figure", "--json",
                 "--c-max", "auto", "--c-max-grid", "0.1", "5", "--validation-problems", "1", "--seed", "3",
                 "--out", str(tmp_path)])
    assert code == 0
    agg = json.loads(capsys.readouterr().out)
    assert {(a["method"], a["agents"]) for a in agg} == {("unconstrained_policy", 1), ("ours", 1), ("ours", 2)}
    choice = json.loads((tmp_path / "c_max.json").read_text())
    assert choice["validation_seed"] == 10003 and choice["test_seed"] == 3
    assert set(choice["chosen"]) == {"1", "2"} and set(choice["chosen"].values()) <= {0.1, 5.0}
    runs = (tmp_path / "runs.csv").read_text().splitlines()
    assert "c_max" in runs[0].split(",")
    assert "c_max chosen on validation problems (seed 10003)" in (tmp_path / "table.md").read_text()


@pytest.mark.parametrize("argv, message", [
    (["--c-max", "lots"], "positive number or 'auto'"),
    (["--c-max", "-1"], "c_max must be > 0"),
    (["--nodes", "0"], "positive integer"),
    (["--seed", "-1"], "non-negative integer"),
    (["--policies-at", "0"], "positive integer"),
])
def test_evaluate_command_rejects_bad_arguments(argv, message, capsys):
    from baselines.cli import main

    with pytest.raises(SystemExit):
        main(["evaluate", *argv])
    assert message in capsys.readouterr().err


def test_evaluate_command_refuses_validation_on_the_test_seed(tmp_path, capsys):
    from baselines.cli import main

    assert main(["evaluate", "--c-max", "auto", "--validation-seed", "0", "--seed", "0", "--out", str(tmp_path)]) == 2
    assert "--validation-seed must differ from --seed" in capsys.readouterr().err
    assert not (tmp_path / "runs.csv").exists()


def test_an_execution_becomes_a_gif_with_a_caption(setup, tmp_path):
    from PIL import Image

    from baselines.figures import execution_frames, run_animation

    path = run_animation(setup, METHODS["ours"], tmp_path / "run.gif", n_agents=3, difficulty="easy", every=4)
    with Image.open(path) as gif:
        assert gif.n_frames >= 3
        w, h = gif.size
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1)
    traj = np.array([[[5.0, 5.0]], [[6.0, 5.0]], [[7.0, 5.0]]])
    frames = execution_frames(env.field, traj, np.array([[7.0, 5.0]]), env.goal_threshold, every=1, title="t")
    env.close()
    assert len(frames) == 3 and frames[0].shape[1:] == (w, 3) and h > frames[0].shape[0] > w  # a caption on top
    assert (frames[0][:10] == 255).all()  # the caption band on top
    assert not np.array_equal(frames[0], frames[2])  # the agent moves
    with pytest.raises(ValueError, match="every must be >= 1"):
        execution_frames(env.field, traj, np.array([[7.0, 5.0]]), 1.0, every=0)


def test_evaluate_names_an_unknown_env_id_before_any_work(tmp_path, capsys):
    from baselines.cli import main

    assert main(["evaluate", "--env", "Nope-v0", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown env id 'Nope-v0'" in err and "SafeCentralObstacle-v0" in err


def test_c_max_from_an_earlier_validation_is_checked_before_any_work(tmp_path, capsys):
    from baselines.cli import main

    f = tmp_path / "c_max.json"
    f.write_text(json.dumps({"chosen": {"1": 0.5, "5": 1.0}, "validation_seed": 10000, "test_seed": 0}))
    out = str(tmp_path / "out")
    assert main(["evaluate", "--c-max-from", str(f), "--agents", "1", "10", "--out", out]) == 2
    assert "no c_max for agent counts [10]" in capsys.readouterr().err
    assert main(["evaluate", "--c-max-from", str(f), "--seed", "10000", "--agents", "1", "--out", out]) == 2
    assert "test seed of this run" in capsys.readouterr().err
    assert main(["evaluate", "--c-max-from", str(f), "--c-max", "0.3", "--agents", "1", "--out", out]) == 2
    assert "not both" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_evaluate_command_fallback_reaches_only_the_constrained_searches(tmp_path, capsys, monkeypatch):
    """``--fallback`` reaches the constrained searches, ``--repair-routes``, ``--spread-routes`` and
    ``--max-leg`` every search method (the latter two its planner)."""
    import baselines.evaluation as ev
    import baselines.methods as bm
    from baselines.cli import main

    seen = {}
    real = ev.execute
    real_policy = bm.SearchPolicy

    def spy(env, method, models, *args, **kwargs):
        seen[method.name] = (method.fallback, method.option("repair_routes"), method.option("spread_routes"))
        return real(env, method, models, *args, **kwargs)

    planners = []

    def policy_spy(planner, *args, **kwargs):
        planners.append(None if planner is None else (planner.solver_config.spread, planner.graph.max_leg))
        return real_policy(planner, *args, **kwargs)

    monkeypatch.setattr(ev, "execute", spy)
    monkeypatch.setattr(bm, "SearchPolicy", policy_spy)
    code = main(["evaluate", "--agents", "1", "--problems", "1", "--difficulty", "easy", "--methods", "sorb",
                 "constrained_policy", "ours", "--nodes", "150", "--no-figure", "--json", "--fallback",
                 "--repair-routes", "--spread-routes", "routes", "--max-leg", "14", "--out", str(tmp_path)])
    assert code == 0
    assert seen == {"sorb": (None, True, "routes"), "constrained_policy": (None, None, None),
                    "ours": ("unconstrained", True, "routes")}
    # the plain policy has no planner
    assert sorted(planners, key=str) == [("routes", 14.0), ("routes", 14.0), None]
    table = (tmp_path / "table.md").read_text()
    assert "--fallback: the constrained searches" in table and "--repair-routes: an agent" in table
    assert "--spread-routes routes:" in table and "--max-leg 14: the search methods' plans" in table
    capsys.readouterr()
    assert main(["evaluate", "--max-leg", "0", "--out", str(tmp_path / "z")]) == 2
    assert "--max-leg must be > 0" in capsys.readouterr().err and not (tmp_path / "z").exists()
    import agents
    one = agents.load_pretrained("SafeCentralObstacle-v0", kind="constrained")
    monkeypatch.setattr(agents, "load_pretrained", lambda *a, **k: one)  # no second critic to read legs with
    assert main(["evaluate", "--max-leg", "14", "--out", str(tmp_path / "y")]) == 2
    assert "--max-leg needs a constrained agent" in capsys.readouterr().err
    for argv in (["--fallback"], ["--repair-routes"], ["--spread-routes", "near"], ["--max-leg", "14"]):
        assert main(["evaluate", "--protocol", "paper", "--env", "SafeCenterDot-v0", *argv,
                     "--out", str(tmp_path / "p")]) == 2
        assert f"{argv[0]} does not apply" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["evaluate", "--spread-routes", "yes", "--out", str(tmp_path / "q")])
    assert "invalid choice" in capsys.readouterr().err


def test_the_graph_learns_repairs_on_other_problems_and_keeps_them_frozen(setup, monkeypatch):
    """learn_edge_memory runs the search methods on problems of another seed, adds up what each run's
    memory learned and freezes it; evaluate hands every test run a frozen copy, so no test run learns."""
    import baselines.evaluation as ev
    from agents.search.execution.repair import EdgeMemory
    from baselines.evaluation import learn_edge_memory

    with pytest.raises(ValueError, match="repair seed must differ from the test seed"):
        learn_edge_memory(setup, get_methods(["ours"]), [1], seed=3, test_seed=3)
    seen = []
    real = ev.execute

    def spy(env, method, models, planner, starts, goals, **kwargs):
        ex = real(env, method, models, planner, starts, goals, **kwargs)
        memory = kwargs.get("memory")
        seen.append((method.name, None if memory is None else memory.frozen))
        if method.search and memory is None:  # a learning run: pretend it failed on one edge
            ex.extra["memory"].record_failure(0, 1)
        return ex

    monkeypatch.setattr(ev, "execute", spy)
    memories = learn_edge_memory(setup, get_methods(["sorb", "constrained_policy"]), [1], ["easy"], n_problems=2,
                                 progress=False)
    assert set(memories) == {"sorb"} and memories["sorb"].frozen  # only search methods learn
    assert memories["sorb"].failures == {(0, 1): 2} and memories["sorb"].is_removed(0, 1)
    assert seen == [("sorb", None), ("sorb", None)]
    seen.clear()
    rows = evaluate(setup, get_methods(["sorb", "constrained_policy"]), [1], ["easy"], n_problems=1,
                    progress=False, memories=memories)
    assert len(rows) == 2 and seen == [("sorb", True), ("constrained_policy", None)]
    assert memories["sorb"].failures == {(0, 1): 2}  # unchanged by the test runs
    assert isinstance(memories["sorb"], EdgeMemory)


def test_evaluate_command_writes_the_failure_anatomy_and_takes_hold_and_repairs(tmp_path, capsys, monkeypatch):
    import csv

    import baselines.evaluation as ev
    from baselines.cli import main

    holds = []
    real = ev.execute

    def spy(env, method, models, *args, **kwargs):
        holds.append((method.name, method.option("hold")))
        return real(env, method, models, *args, **kwargs)

    monkeypatch.setattr(ev, "execute", spy)
    code = main(["evaluate", "--agents", "2", "--problems", "1", "--difficulty", "hard", "--methods",
                 "constrained_policy", "ours", "--nodes", "150", "--no-figure", "--hold", "waits",
                 "--repair-problems", "1", "--max-cycles", "40", "--out", str(tmp_path)])
    assert code == 0
    assert ("ours", "waits") in holds and ("constrained_policy", None) in holds
    out = capsys.readouterr().out
    assert "Why agents did not arrive" in out
    with open(tmp_path / "runs.csv") as f:
        runs = list(csv.DictReader(f))
    with open(tmp_path / "failures.csv") as f:
        failures = list(csv.DictReader(f))
    assert len(failures) == sum(2 - int(r["reached"]) for r in runs)  # one row per agent that did not arrive
    for r in failures:
        assert r["reason"] in ("never_planned", "deadlock", "out_of_time", "blocked_by_parked", "stuck_on_leg")
    anatomy = (tmp_path / "anatomy.md").read_text()
    failed, touched = anatomy.split("why agents touched")
    assert failed.count("| ours |") == 1 and touched.count("| ours |") == 1  # one cell in each table
    contacts = sum(int(r["collisions"]) for r in runs if r["method"] == "ours")
    assert f"| ours | Hard | 2 | 1 | {contacts:.2f} |" in touched
    assert (tmp_path / "anatomy.png").exists() and (tmp_path / "edge_memory_ours.npz").exists()
    assert "--repair-problems 1 (seed 20000)" in (tmp_path / "table.md").read_text()
    assert main(["evaluate", "--repair-problems", "1", "--repair-seed", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--repair-seed must differ from --seed" in capsys.readouterr().err
    assert main(["evaluate", "--protocol", "paper", "--env", "SafeCenterDot-v0", "--hold", "waits",
                 "--out", str(tmp_path / "p")]) == 2
    assert "--hold does not apply" in capsys.readouterr().err


def test_mapf_metrics_hand_computed():
    from baselines.metrics import mapf_metrics

    # three agents arrive at steps 4, 9, 7: all arrived, makespan the last arrival
    assert mapf_metrics(np.array([4, 9, 7]), 9) == {"isr": 1.0, "soc": 20, "makespan": 9}
    # one agent never arrives in a run of 300 steps: it counts the run's length
    m = mapf_metrics(np.array([4, -1, 7, 5]), 300)
    assert m == {"isr": 0.75, "soc": 316, "makespan": 300}
    with pytest.raises(ValueError, match="arrival"):
        mapf_metrics(np.array([], dtype=int), 3)
    rows = [{"method": "m", "agents": 4, "difficulty": "hard", "success": s, "cost_max": 1.0, "cost_mean": 1.0,
             "collisions": 0, "steps": st, "planning_time": 0.0, **mapf_metrics(np.array(a), st)}
            for s, a, st in ((True, [3, 4, 5, 6], 6), (False, [4, -1, 7, 5], 300))]
    agg = aggregate(rows)[0]
    assert agg["csr"] == 0.5 and agg["isr"] == pytest.approx(0.875)
    assert agg["soc_mean"] == pytest.approx((18 + 316) / 2) and agg["makespan_mean"] == pytest.approx(153)
    # rows without the metrics (e.g. the paper protocol's) aggregate to nan, not to a wrong mean
    assert math.isnan(aggregate([{k: v for k, v in rows[0].items() if k != "soc"}])[0]["soc_mean"])


def test_many_agents_curve_reads_evaluate_rows(tmp_path, monkeypatch, capsys):
    """examples/many_agents_curve.py on hand-made rows: the table's CSR, ISR and per-agent sum of
    costs, and the figure; folders without the metrics are refused with a message."""
    import csv
    import runpy
    import sys

    from baselines.metrics import mapf_metrics

    folder = tmp_path / "grid"
    folder.mkdir()
    rows = []
    for i, (arrival, steps) in enumerate((([5, 9], 9), ([6, -1], 300))):
        rows.append({"method": "ours", "agents": 2, "difficulty": "hard", "problem": i, "success": -1 not in arrival,
                     "cost_max": 2.0 * (i + 1), "cost_mean": 1.0, "collisions": i, "safety_rate": 1.0 - i,
                     "steps": steps, "planning_time": 0.1, **mapf_metrics(np.array(arrival), steps)})
    with open(folder / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    monkeypatch.setattr(sys, "argv", ["many_agents_curve.py", str(folder), "--out", str(tmp_path / "c.png")])
    runpy.run_path("examples/many_agents_curve.py", run_name="__main__")
    out = capsys.readouterr().out
    # CSR 1 of 2 runs; ISR (1 + 0.5) / 2; sum of costs (14 + 306) / 2 over 2 agents; makespan (9 + 300) / 2;
    # safety rate (1 + 0) / 2
    assert "| 2 | 2 | 50% | 75.0% | 80.0 | 154 | 3.0 | 0.5 | 50.0% | 0.10 s |" in out
    assert (tmp_path / "c.png").stat().st_size > 0
    with open(folder / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["method", "agents"])
        w.writeheader()
        w.writerow({"method": "ours", "agents": 2})
    with pytest.raises(SystemExit, match="no isr"):
        runpy.run_path("examples/many_agents_curve.py", run_name="__main__")


def test_execute_splits_each_agents_cost_by_what_it_did(setup):
    """Execution.cost_split: per agent and activity, summing to the agent's cost; the row keeps the
    costliest agent's split; a method without search never holds; holds are paid where they happen."""
    from baselines.cost_anatomy import parse_cost_split
    from baselines.evaluation import run_row

    prob = make_problems(setup, "hard", 6, 1, seed=2)[0]
    env = safe_mapf_envs.parallel_env(setup.env_id, n_agents=6, max_cycles=150)
    col = {a: i for i, a in enumerate(ACTIVITIES)}
    for method in (METHODS["unconstrained_policy"], METHODS["ours"], METHODS["ours"].with_options(hold="order")):
        row, ex = run_row(setup, env, method, prob, seed=0)
        assert ex.cost_split.shape == (6, len(ACTIVITIES)) and (ex.cost_split >= 0).all()
        np.testing.assert_allclose(ex.cost_split.sum(1), ex.cost, atol=1e-9)
        split = parse_cost_split(row["cost_split"])
        assert sum(split.values()) == pytest.approx(row["cost_max"], abs=0.01 * len(ACTIVITIES))
        paid = {a for a in ACTIVITIES if ex.cost_split[:, col[a]].sum() > 0}
        if not method.search:  # no plan: nothing to wait for (it still yields, and escapes when stuck)
            assert paid <= {"drive", "escape", "yield"}
        elif method.option("hold") == "order":  # standing for the plan's order and for parking
            assert {"order", "park"} <= paid and "wait" not in paid
        else:  # vector agents keep to the plan's times
            assert "wait" in paid and not {"order", "park"} & paid
    env.close()


def test_the_setup_of_a_vector_env_hands_the_planner_its_distance_bound(stand_in_models):
    """Starts and goals are attached with the env's straight-line bound: the critics read only the
    pairs it puts within ``d_max``."""
    import gymnasium as gym

    built = EvaluationSetup.build("SafeCentralObstacle-v0", n_nodes=60, models=stand_in_models)
    assert built.bound == gym.make("SafeCentralObstacle-v0").unwrapped.step_bound()
    assert built.planner.pairwise.bound is built.bound
