"""The search's settings: config objects that validate themselves, one option name per field, presets."""
import dataclasses
import json
import math

import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs  # noqa: F401  (registers the ids)
from agents.search import BufferPlanner, SearchPolicy, WaypointController
from agents.search.config import (
    OPTIONS,
    PARTS,
    PRESETS,
    ControllerConfig,
    GraphConfig,
    ReplanConfig,
    SearchConfig,
    SolverConfig,
    UnknownOptionError,
    preset,
)


@pytest.fixture(scope="module")
def nodes():
    u = gym.make("SafeCentralObstacle-v0").unwrapped
    return u.normalize(u.sample_states(40, np.random.default_rng(0))).astype(np.float32)


@pytest.fixture
def agent(stand_in_models):
    return stand_in_models["constrained"]


@pytest.mark.parametrize("cls, change, message", [
    (GraphConfig, dict(d_max=0), "d_max must be > 0"),
    (GraphConfig, dict(c_max=float("nan")), "c_max must be > 0"),
    (GraphConfig, dict(endpoint_edges=1.5), "endpoint_edges must be an integer >= 1"),
    (GraphConfig, dict(time_model="clock"), "time_model must be 'durative' or 'unit'"),
    (GraphConfig, dict(cost_guard=0.5), "cost_guard must be >= 1 or None"),
    (GraphConfig, dict(relax_cost=1), "relax_cost must be True or False"),
    (ControllerConfig, dict(hold="sometimes"), "hold must be 'order', 'waits' or 'all'"),
    (ControllerConfig, dict(reach_threshold=-1), "reach_threshold must be > 0"),
    (ControllerConfig, dict(stuck_window=0), "stuck_window must be an integer >= 1 or None"),
    (ControllerConfig, dict(escape_steps=True), "escape_steps must be an integer >= 1"),
    (ControllerConfig, dict(retreat="home"), "retreat must be None, 'goal' or 'any'"),
    (ControllerConfig, dict(safety_radius=float("nan")), "safety_radius must be >= 0 or None"),
    (ReplanConfig, dict(ban_detour=-1.0), "ban_detour must be >= 0"),
    (ReplanConfig, dict(replan_when_stuck="yes"), "replan_when_stuck must be True or False"),
    (SearchConfig, dict(budget=0.0), "budget must be > 0 or None"),
    (SearchConfig, dict(graph=ControllerConfig()), "graph must be a GraphConfig"),
])
def test_a_bad_value_is_refused_on_construction_naming_the_field(cls, change, message):
    with pytest.raises(ValueError, match=message):
        cls(**change)


def test_every_field_has_one_option_name_and_updated_changes_it_where_it_lives():
    names = {(part, f.name) for part, cls in PARTS.items() for f in dataclasses.fields(cls)}
    assert set(OPTIONS.values()) == names | {("", "budget")}  # every field, each named once
    config = SearchConfig().updated(c_max=0.25, solver="lns", repair_seed=3, spread_routes="near", hold="order",
                                    ban_radius=2, budget=4)
    assert config.graph.c_max == 0.25 and config.graph.d_max == GraphConfig().d_max
    assert (config.solver.name, config.solver.seed, config.solver.spread) == ("lns", 3, "near")
    assert config.controller.hold == "order" and config.replanning.ban_radius == 2.0 and config.budget == 4.0
    assert config.option("repair_seed") == 3 and config.option("budget") == 4.0
    assert SearchConfig().updated() == SearchConfig()
    with pytest.raises(UnknownOptionError, match=r"unknown options \['cmax'\]; the options are \[.*'c_max'"):
        SearchConfig().updated(cmax=0.3)
    with pytest.raises(ValueError, match=r"seed must be an integer.*\['repair_seed'\] set the solver's \['seed'\]"):
        SearchConfig().updated(repair_seed=1.5)


def test_configs_go_to_json_and_back_and_bad_json_is_named():
    config = preset("panorama").updated(c_max=0.5, max_leg=math.inf, solver="lacam")
    text = json.dumps(config.to_dict())
    assert SearchConfig.from_dict(json.loads(text)) == config
    assert SearchConfig.from_dict({"graph": {"d_max": 3.0}}) == SearchConfig(graph=GraphConfig(d_max=3.0))
    with pytest.raises(ValueError, match=r"g.json: unknown parts \['grph'\]"):
        SearchConfig.from_dict({"grph": {}}, where="g.json")
    with pytest.raises(ValueError, match=r"g.json: controller has unknown fields \['colour'\]"):
        SearchConfig.from_dict({"controller": {"colour": 1}}, where="g.json")
    with pytest.raises(ValueError, match=r"g.json: solver: unknown solver 'fast'"):
        SearchConfig.from_dict({"solver": {"name": "fast"}}, where="g.json")
    with pytest.raises(ValueError, match="must be a JSON object"):
        SearchConfig.from_dict([1, 2], where="g.json")


def test_the_presets_hold_the_panorama_rules_and_the_vector_defaults():
    assert PRESETS["vector"] == SearchConfig() and preset("vector") is PRESETS["vector"]
    pano = preset("panorama")
    assert pano.graph == GraphConfig(detour=1.5) and pano.solver == SolverConfig() and pano.replanning == ReplanConfig()
    c = pano.controller
    assert (c.hold, c.reach_threshold, c.self_margin, c.settle_patience, c.progress_patience, c.skip_after,
            c.sidestep_after, c.advance_slack, c.retreat, c.fallback_beyond) == (
        "order", 3.0, 0.5, 6, 20, 1, 4, 3.0, "goal", 14.0)
    with pytest.raises(ValueError, match="unknown preset 'lidar'"):
        preset("lidar")


def test_the_constructors_take_their_part_and_refuse_anything_else(agent, nodes):
    D = np.abs(nodes[:, None, 0] - nodes[None, :, 0]) * 10
    with pytest.raises(TypeError, match="graph and solver must be a GraphConfig and a SolverConfig"):
        BufferPlanner(nodes, D, D, None, ControllerConfig())
    with pytest.raises(TypeError, match="config must be a ControllerConfig"):
        WaypointController(None, None, {}, GraphConfig())
    with pytest.raises(TypeError, match="controller must be a ControllerConfig"):
        SearchPolicy(None, agent, controller=ReplanConfig())
    with pytest.raises(ValueError, match="max_leg needs a second_opinion"):
        BufferPlanner(nodes, D, D, None, GraphConfig(max_leg=5.0))
    planner = BufferPlanner(nodes, D, D, None, GraphConfig(d_max=3.0))
    with pytest.raises(ValueError, match=r"\['hold'\] are not options of the planner's graph or solver"):
        planner.with_options(hold="order")
    varied = planner.with_options(c_max=0.5, solver="prioritized")
    assert varied.graph == GraphConfig(d_max=3.0, c_max=0.5) and varied.solver_config.name == "prioritized"
    assert planner.graph.c_max == math.inf  # configs are frozen: the first planner is as it was


def test_a_policy_reports_the_config_in_use(agent, nodes):
    policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, c_max=0.5, hold="order", ban_radius=2.0,
                                      budget=3.0, solver="prioritized")
    config = policy.config
    assert config.graph == policy.planner.graph and config.graph.c_max == 0.5 and config.graph.d_max == 12.0
    assert config.solver.name == "prioritized" and config.controller.hold == "order"
    assert config.replanning.ban_radius == 2.0 and config.budget == 3.0
    again = SearchPolicy.from_models(agent, agent, nodes, config=config)
    assert again.config == config
