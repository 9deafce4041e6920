"""Solvers by name: the configuration, the registry, the ``"auto"`` cascade and the one result type."""
import dataclasses
import json

import numpy as np
import pytest

import agents.search.mapf.registry as registry
from agents.search.mapf import (
    AUTO_CASCADE,
    AUTO_SEARCH_AGENTS,
    SOLVERS,
    CascadeStage,
    CBSStats,
    ConfigurationStats,
    MapfInstance,
    MapfResult,
    PrioritizedStats,
    RepairStats,
    SolverConfig,
    StepperStats,
    register_solver,
    solve,
    validate,
)
from agents.search.mapf.registry import SolveCall, run_cascade


def grid(n):
    """Adjacency lists of an ``n x n`` 4-connected grid (node ``r * n + c``)."""
    adj = []
    for r in range(n):
        for c in range(n):
            adj.append([(r + dr) * n + c + dc for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1))
                        if 0 <= r + dr < n and 0 <= c + dc < n])
    return adj


def crossing(n=5, k=4):
    """``k`` agents crossing an ``n x n`` grid from the left column to the right one, rows reversed."""
    starts = [r * n for r in range(k)]
    goals = [(k - 1 - r) * n + n - 1 for r in range(k)]
    return MapfInstance(grid(n), starts, goals)


STATS = {"cbs": CBSStats, "prioritized": PrioritizedStats, "lns": RepairStats, "pibt": StepperStats,
         "lacam": ConfigurationStats}


def test_the_defaults_are_the_planners():
    import agents.search.planner as planner_module
    from agents.search.planner import BufferPlanner

    pts = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), axis=-1).reshape(-1, 2)
    D = np.maximum(np.linalg.norm(pts[:, None] - pts[None], axis=-1), 1.0)
    planner = BufferPlanner(pts, D, np.zeros_like(D), lambda a, b: (D, D))
    assert planner.solver_config == SolverConfig()
    assert set(planner_module.SOLVERS) == set(SOLVERS) and planner_module.AUTO_SEARCH_AGENTS == AUTO_SEARCH_AGENTS
    custom = planner.with_options(solver="lns", repair_seed=4, time_limit=2.5, spread_routes="near",
                                  lacam_expansions_per_agent=None)
    assert custom.solver_config == dataclasses.replace(SolverConfig(), name="lns", seed=4, time_limit=2.5,
                                                       spread="near", lacam_expansions_per_agent=None)


def test_the_command_offers_the_registry_names():
    from baselines.commands.mapf import OPTION_FIELDS, SOLVER_NAMES

    assert set(SOLVER_NAMES) == set(SOLVERS)
    fields = {f.name for f in dataclasses.fields(SolverConfig)}
    assert set(OPTION_FIELDS.values()) <= fields


@pytest.mark.parametrize("change, match", [
    (dict(name="nope"), "unknown solver 'nope'"),
    (dict(suboptimality=0.9), "suboptimality must be >= 1"),
    (dict(suboptimality=float("nan")), "suboptimality must be >= 1"),
    (dict(fallback_suboptimality=0.5), "fallback_suboptimality must be >= 1"),
    (dict(expansion_limit=0), "expansion_limit must be an integer >= 1"),
    (dict(repair_expansions_per_agent=-3), "repair_expansions_per_agent must be an integer >= 1"),
    (dict(prioritized_expansions_per_agent=2.5), "prioritized_expansions_per_agent must be an integer"),
    (dict(work_limit=True), "work_limit must be an integer"),
    (dict(node_limit=-1), "node_limit must be an integer >= 0"),
    (dict(time_limit=0), "time_limit must be > 0"),
    (dict(seed=1.5), "seed must be an integer"),
    (dict(spread="everywhere"), "spread must be one of"),
    (dict(heuristic="best"), "heuristic must be one of"),
    (dict(memory_limit_mb=-1), "memory_limit_mb must be > 0"),
    (dict(anytime=1), "anytime must be True or False"),
])
def test_a_bad_configuration_says_which_field(change, match):
    with pytest.raises(ValueError, match=match):
        SolverConfig(**change)
    with pytest.raises(ValueError, match=match):  # a variant is checked as well
        dataclasses.replace(SolverConfig(), **change)


def test_a_configuration_is_frozen_and_normalised():
    config = SolverConfig(expansion_limit=np.int64(7), fallback_suboptimality=2, seed=np.int32(3))
    assert type(config.expansion_limit) is int and config.fallback_suboptimality == 2.0 and type(config.seed) is int
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.name = "cbs"
    assert dataclasses.replace(config, name="pibt").name == "pibt" and config.name == "auto"
    assert hash(config) == hash(SolverConfig(expansion_limit=7, seed=3))


@pytest.mark.parametrize("name", ["cbs", "prioritized", "lns", "pibt", "lacam"])
def test_every_solver_fills_the_common_fields(name):
    inst = crossing()
    res = solve(inst, SolverConfig(name=name, lacam_expansions_per_agent=2_000))
    assert isinstance(res, MapfResult) and res.solver == name and isinstance(res.stats, STATS[name])
    assert res.solved and validate(inst, None, None, res.paths) == []
    assert res.soc == sum(p[-1][1] for p in res.paths) and res.makespan == max(p[-1][1] for p in res.paths)
    assert res.work > 0 and res.runtime_s > 0 and res.time_model == "unit"
    alone = sum(int(inst.h[i][s]) for i, s in enumerate(inst.starts))
    assert res.lower_bound is not None and alone <= res.lower_bound <= res.soc
    if name in ("prioritized", "lns", "pibt"):  # no search bound: the agents' own distances, no more
        assert res.lower_bound == alone
    assert res.status == ("optimal" if res.soc == res.lower_bound else "suboptimal")
    d = res.to_dict()
    assert d["solver"] == name and d["work"] == res.work and d["stats"] == dataclasses.asdict(res.stats)
    json.dumps(d)


def test_a_timeout_reports_its_work_and_no_plan():
    inst = crossing(k=5)
    for name in ("cbs", "prioritized", "lns", "pibt", "lacam"):
        res = solve(inst, SolverConfig(name=name, work_limit=3, fallback_suboptimality=None))
        assert res.status == "timeout" and res.paths is None and res.soc is None, name
        assert res.solver == name and res.work >= 3 and "expansion limit" in res.message, name


def test_the_stepper_reports_its_steps():
    res = solve(crossing(), SolverConfig(name="pibt"))
    assert res.stats.steps >= res.makespan and res.stats.moves >= len(crossing().starts)
    starved = solve(crossing(), SolverConfig(name="pibt", work_limit=5))
    assert starved.status == "timeout" and starved.stats.steps >= 1  # also where it gave up


def test_auto_is_the_declared_cascade():
    assert AUTO_CASCADE == (CascadeStage("cbs", max_agents=AUTO_SEARCH_AGENTS, then="lns"),
                            CascadeStage("prioritized", then="pibt"))
    assert SOLVERS["auto"].reads == SOLVERS["cbs"].reads | SOLVERS["lns"].reads | SOLVERS["prioritized"].reads \
        | SOLVERS["pibt"].reads
    inst = crossing()
    untimed = [dataclasses.replace(solve(inst, SolverConfig(name=name)), runtime_s=0.0) for name in ("auto", "cbs")]
    assert untimed[0] == untimed[1]  # few agents: CBS alone
    # CBS / ECBS out of its budget: the repair, which says so
    res = solve(inst, SolverConfig(expansion_limit=1, fallback_suboptimality=None))
    cbs = solve(inst, SolverConfig(name="cbs", expansion_limit=1, fallback_suboptimality=None))
    lns = solve(inst, SolverConfig(name="lns"))
    assert res.solver == "lns" and res.paths == lns.paths and res.work == lns.work
    assert res.message == f"{lns.message} (after cbs: {cbs.message})"


def test_a_cascade_picks_its_stage_by_the_number_of_agents():
    inst = crossing(k=3)
    stages = (CascadeStage("cbs", max_agents=2, then="lns"), CascadeStage("prioritized", then="pibt"))
    starved = SolverConfig(prioritized_expansions_per_agent=1)
    res = run_cascade(stages, inst, starved, SolveCall())
    first = solve(inst, dataclasses.replace(starved, name="prioritized"))
    pibt = solve(inst, dataclasses.replace(starved, name="pibt"))
    assert first.status == "timeout" and res.solver == "pibt" and res.paths == pibt.paths
    assert res.message == f"{pibt.message} (after prioritized: {first.message})"
    assert run_cascade(stages, inst, SolverConfig(), SolveCall()).solver == "prioritized"  # solved: no second
    with pytest.raises(ValueError, match="no stage"):
        run_cascade((CascadeStage("cbs", max_agents=2),), inst, SolverConfig(), SolveCall())


def test_a_call_scales_the_budgets():
    inst = crossing(k=5)
    config = SolverConfig(name="prioritized", work_limit=100)
    seen = {}

    def spy(instance, expansion_limit=None, **kwargs):
        seen["limit"] = expansion_limit
        return MapfResult("timeout", solver="prioritized")

    mp = pytest.MonkeyPatch()
    with mp.context() as m:
        m.setattr(registry, "solve_prioritized", spy)
        solve(inst, config, scale=0.25, size_scale=3.0)
        assert seen["limit"] == 75  # 100 x 3, then a quarter of it
        solve(inst, dataclasses.replace(config, work_limit=None, prioritized_expansions_per_agent=10), scale=2.0)
        assert seen["limit"] == 50  # 10 per agent; a scale above 1 leaves it
        solve(inst, dataclasses.replace(config, work_limit=1), scale=0.01)
        assert seen["limit"] == 1  # at least one expansion
    with pytest.raises(ValueError, match="scale"):
        SolveCall(scale=0)


def test_register_a_solver():
    calls = []

    @register_solver("test-direct", reads=("time_limit", "seed"))
    def direct(instance, config, call):
        calls.append(config.seed)
        paths = [[(s, 0), (g, int(instance.h[i][s]))] for i, (s, g) in enumerate(zip(instance.starts, instance.goals))]
        return MapfResult("suboptimal", paths, solver="test-direct")

    try:
        assert SOLVERS["test-direct"].reads == frozenset({"time_limit", "seed"})
        res = solve(crossing(k=1), SolverConfig(name="test-direct", seed=5))
        assert res.solver == "test-direct" and calls == [5]
        with pytest.raises(ValueError, match="registered already"):
            register_solver("test-direct")(direct)
    finally:
        registry._SOLVERS.pop("test-direct", None)
    with pytest.raises(ValueError, match="does not have"):
        register_solver("test-other", reads=("colour",))
    with pytest.raises(ValueError, match="unknown solver"):
        SolverConfig(name="test-direct")


def test_the_command_runs_every_solver(tmp_path, capsys):
    from test_mapf_cli import write_instance

    from baselines.cli import main

    agents = [((r, 0), (3 - r, 4)) for r in range(4)]
    m, s = write_instance(tmp_path, ["....."] * 4, agents)
    for name in ("auto", "cbs", "prioritized", "lns", "pibt", "lacam"):
        assert main(["mapf", str(m), str(s), "--agents", "4", "--solver", name, "--expansion-limit", "50000",
                     "--json"]) == 0, name
        report = json.loads(capsys.readouterr().out)
        assert report["valid"] is True and report["solver"] == name, report
        assert report["solver_used"] == ("cbs" if name == "auto" else name) and report["work"] > 0
    assert main(["mapf", str(m), str(s), "--agents", "4", "--solver", "lns", "--seed", "3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["seed"] == 3
    assert main(["mapf", str(m), str(s), "--agents", "4", "--solver", "pibt", "--first-solution"]) == 2
    assert "--first-solution does not apply to --solver pibt" in capsys.readouterr().err
    assert main(["mapf", str(m), str(s), "--agents", "4", "--solver", "prioritized", "--expansion-limit", "2"]) == 1
    assert "expansion limit of 2" in capsys.readouterr().out
