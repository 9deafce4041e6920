"""SearchPolicy: plan on the buffer graph and drive, through an SB3-style predict()."""
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import safe_mapf_envs
from agents.search import BufferPlanner, SearchPolicy, WaypointGraph, build_problem_graph
from agents.search.config import ControllerConfig, GraphConfig
from agents.search.graph.build import edge_mask

ENV_ID = "SafeCentralObstacle-v0"


@pytest.fixture(scope="module")
def nodes():
    env = gym.make(ENV_ID)
    u = env.unwrapped
    obs = u.normalize(u.sample_states(300, np.random.default_rng(0))).astype(np.float32)
    env.close()
    return obs


@pytest.fixture
def agent(stand_in_models):
    return stand_in_models["constrained"]


def run_episode(env, policy, seed, options=None, reset=True):
    obs, _ = env.reset(seed=seed, options=options)
    if reset:
        policy.reset()
    arrived, cost, steps = set(), 0.0, 0
    while env.agents:
        actions, state = policy.predict({a: obs[a] for a in env.agents})
        assert state is None and set(actions) == set(env.agents)
        obs, _, term, _, infos = env.step(actions)
        steps += 1
        arrived |= {a for a, t in term.items() if t}
        cost += sum(i["cost"] for i in infos.values())
    return arrived, cost, steps


def test_predict_plans_with_cbs_and_brings_every_agent_home(agent, nodes):
    policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, c_max=0.5, seed=3)
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=4)
    arrived, _, steps = run_episode(env, policy, seed=1)
    assert arrived == set(env.possible_agents)
    plan = policy.current_plan
    assert plan is not None and plan.solved and plan.status in ("optimal", "suboptimal")
    assert policy.agents == env.possible_agents
    # the plan carries its problem graph: 300 buffer nodes + 4 starts + 4 goals
    assert plan.problem.observations.shape == (308, 2) and plan.problem.n_agents == 4
    for i, a in enumerate(policy.agents):
        assert policy.routes[a][0] == plan.problem.start_ids[i]  # routes begin at the agent's start node
    assert policy.planning_time > 0 and policy.stats.steps == steps


def test_the_cost_cut_off_steers_clear_of_the_costly_ring(agent, nodes):
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=1)
    # start and goal on either side of the central obstacle
    options = {"starts": [[10.0, 27.5]], "goals": [[45.0, 27.5]]}
    costs = {}
    for c_max in (np.inf, 0.05):
        policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, c_max=c_max)
        arrived, costs[c_max], _ = run_episode(env, policy, seed=0, options=options)
        assert arrived == {"agent_0"}
    assert costs[0.05] < costs[np.inf]


def test_predict_on_a_single_gymnasium_observation(agent, nodes):
    env = gym.make(ENV_ID)
    policy = SearchPolicy.from_models(agent, None, nodes, d_max=12.0)
    obs, _ = env.reset(seed=4)
    for _ in range(200):
        action, _ = policy.predict(obs)
        assert action.shape == (2,)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert info["is_success"]
    assert len(policy.current_plan.nodes) == 1
    # a batch of one (a VecEnv with one environment) gives a batch of one action
    batch = {k: v[None] for k, v in env.reset(seed=5)[0].items()}
    action, _ = policy.predict(batch)
    assert action.shape == (1, 2)


def test_a_new_episode_is_planned_without_being_told(agent, nodes):
    policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0)
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=2)
    run_episode(env, policy, seed=0, reset=False)
    first = policy.current_plan
    run_episode(env, policy, seed=1, reset=False)  # other goals: a new plan
    assert policy.current_plan is not first
    second = policy.current_plan
    obs, _ = env.reset(seed=1)  # the same problem again, but agents came back: a new plan
    policy.predict(obs)
    assert policy.current_plan is not second
    assert policy.controller.t == 1


def test_replan_gives_the_agents_new_plans_from_where_they_stand(agent, nodes):
    policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0)
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=2)
    obs, _ = env.reset(seed=2)
    for _ in range(5):
        actions, _ = policy.predict({a: obs[a] for a in env.agents})
        obs, *_ = env.step(actions)
    policy.predict({a: obs[a] for a in env.agents})
    new = policy.replan()
    assert new.solved
    for a in env.agents:
        np.testing.assert_allclose(policy.waypoints(a)[0], obs[a]["observation"])  # starts where it stands
        assert policy.controller.index[a] == 0


def test_without_a_planner_agents_head_straight_for_their_goals(agent):
    policy = SearchPolicy(None, agent)
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=2)
    obs, _ = env.reset(seed=0, options={"starts": [[5.0, 5.0], [5.0, 50.0]], "goals": [[15.0, 5.0], [15.0, 50.0]]})
    policy.predict(obs)
    assert policy.current_plan is None
    assert all(len(policy.waypoints(a)) == 0 for a in env.agents)
    with pytest.raises(ValueError, match="no planner"):
        policy.replan()


def test_bad_input_is_named(agent, nodes):
    policy = SearchPolicy.from_models(agent, agent, nodes[:50], d_max=12.0)
    good = {"observation": nodes[0], "achieved_goal": nodes[0], "desired_goal": nodes[1]}
    with pytest.raises(ValueError, match=r"shape \(3,\), the graph's observations have shape \(2,\)"):
        policy.predict({**good, "observation": np.zeros(3, np.float32)})
    with pytest.raises(ValueError, match="not a batch"):
        policy.predict({**good, "observation": np.zeros((4, 2), np.float32)})
    with pytest.raises(ValueError, match="NaN"):
        policy.predict({**good, "desired_goal": np.array([np.nan, 0.5], np.float32)})
    with pytest.raises(TypeError, match="dict"):
        policy.predict(nodes[:2])
    with pytest.raises(TypeError, match="'observation' and 'desired_goal'"):
        policy.predict({"agent_0": nodes[0]})
    with pytest.raises(TypeError, match="unknown options.*'cmax'"):
        SearchPolicy.from_models(agent, agent, nodes, cmax=0.3)
    with pytest.raises(ValueError, match="hold must be"):
        SearchPolicy(None, agent, controller=ControllerConfig(hold="never"))
    with pytest.raises(TypeError, match="predict"):
        SearchPolicy(None, object())


class FakeReplayBuffer:
    """The fields of an SB3 dict replay buffer that SearchPolicy reads."""

    def __init__(self, observations, buffer_size=1000):
        self.buffer_size = buffer_size
        self.observations = {"observation": np.zeros((buffer_size, 1, 2), np.float32)}
        self.observations["observation"][:len(observations), 0] = observations
        self.pos = len(observations)
        self.full = False


def test_nodes_can_come_from_a_replay_buffer(agent, nodes):
    buffer = FakeReplayBuffer(nodes)
    policy = SearchPolicy.from_models(agent, agent, buffer, n_nodes=100, seed=0, d_max=12.0)
    graph_obs = policy.planner.observations
    assert graph_obs.shape == (100, 2)
    # only stored transitions are drawn (never the empty slots), each at most once
    assert len(np.unique(graph_obs, axis=0)) == 100
    assert all((nodes == o).all(axis=1).any() for o in graph_obs)
    with pytest.raises(ValueError, match="holds 300 observations, fewer than the 500"):
        SearchPolicy.from_models(agent, agent, buffer, n_nodes=500)


def test_one_pruning_rule_for_the_buffer_graph_and_the_problem_graph(agent, nodes):
    D, C = agent.pairwise(nodes, nodes)
    planner = BufferPlanner(nodes, D, C, agent.pairwise, graph=GraphConfig(d_max=9.0, c_max=0.3, relax_cost=False))
    problem = planner.problem_graph(nodes[:2] + 0.001, nodes[2:4] + 0.001)
    n = len(nodes)
    buffer_block = problem.graph.distance.toarray()[:n, :n] > 0
    np.testing.assert_array_equal(buffer_block, edge_mask(D, C, 9.0, 0.3))
    np.testing.assert_array_equal(WaypointGraph.from_matrices(D, C, 9.0, 0.3).distance.toarray() > 0, buffer_block)
    # the planner's distance-only graph is the same rule without the cost cut-off
    np.testing.assert_array_equal(planner.buffer_graph.distance.toarray() > 0, edge_mask(D, C, 9.0, np.inf))
    # build_problem_graph is the pipeline the planner uses
    again = build_problem_graph(nodes, D, C, agent.pairwise, nodes[:2] + 0.001, nodes[2:4] + 0.001, d_max=9.0,
                                c_max=0.3, relax_cost=False)
    assert (again.graph.distance != problem.graph.distance).nnz == 0


def _panorama_model():
    from types import SimpleNamespace

    from gymnasium import spaces

    image = spaces.Box(0, 255, shape=(4, 32, 32, 4), dtype=np.uint8)
    return SimpleNamespace(observation_space=spaces.Dict({"observation": image, "desired_goal": image}))


def test_the_preset_follows_the_observation_type(agent):
    """Panorama critics predict more than 2 steps to a goal already within the goal radius often
    enough that waypoints would go unnoticed: their preset's threshold is larger, and its other
    controller rules are on; a vector agent gets the plain defaults."""
    from agents.search.config import PANORAMA_REACH_THRESHOLD, PRESETS, SearchConfig, preset_for

    pano = preset_for(_panorama_model())
    assert pano is PRESETS["panorama"] and preset_for(agent) is PRESETS["vector"] == SearchConfig()
    assert pano.controller.reach_threshold == PANORAMA_REACH_THRESHOLD > SearchConfig().controller.reach_threshold
    assert pano.controller.hold == "order" and pano.controller.settle_patience > 0 and pano.controller.self_margin > 0
    # a leg the panorama driver's critic puts beyond two graph edges goes to the fallback at once
    assert pano.controller.fallback_beyond == 14.0
    assert SearchPolicy(None, agent).config.controller == ControllerConfig()
    custom = SearchPolicy(None, agent, controller=ControllerConfig(reach_threshold=1.5, settle_patience=3))
    assert custom.config.controller.reach_threshold == 1.5 and custom.config.controller.settle_patience == 3
    policy = SearchPolicy(None, agent, distance_model=SimpleNamespace(distance=None, **vars(_panorama_model())))
    assert policy.config.controller == pano.controller  # the model that judges waypoints decides


def test_the_planner_admits_longer_and_costlier_detours_back_for_panorama_agents_only(agent, nodes):
    from agents.search.config import PANORAMA_DETOUR, preset_for

    assert preset_for(_panorama_model()).graph.detour == PANORAMA_DETOUR == 1.5
    # a vector agent's graph keeps the detours (its tables were made so), unless asked
    assert BufferPlanner.from_agent(agent, nodes[:20]).graph.detour is None
    assert BufferPlanner.from_agent(agent, nodes[:20], detour=2.0).graph.detour == 2.0


def test_the_driver_is_the_graphs_second_opinion_where_it_is_another_critic(stand_in_models, nodes, tmp_path):
    import copy

    from agents.search.models import SecondOpinion, default_second_opinion

    con = stand_in_models["constrained"]
    unc = copy.copy(con)  # another critic
    assert default_second_opinion(con, con) is None and default_second_opinion(con, None) is None
    assert default_second_opinion(con, lambda obs: obs) is None  # a policy that only drives
    second = default_second_opinion(unc, con)
    assert isinstance(second, SecondOpinion) and second.model is con
    np.testing.assert_allclose(second(nodes[:4], nodes[4:8]), con.distance(nodes[:4], nodes[4:8]))
    policy = SearchPolicy.from_models(unc, con, nodes[:30], seed=0)
    assert policy.planner.second_opinion.model is con
    assert SearchPolicy.from_models(con, None, nodes[:30], seed=0).planner.second_opinion is None
    assert SearchPolicy.from_models(unc, con, nodes[:30], seed=0, second_opinion=None).planner.second_opinion is None
    path = policy.save(tmp_path / "graph")
    assert SearchPolicy.load(path, unc, con).planner.second_opinion.model is con
    assert SearchPolicy.load(path, unc).planner.second_opinion is None


def test_a_stuck_agent_whose_ban_cuts_every_route_retries_banning_only_the_failed_waypoint(agent, nodes):
    """Banning every node near a failed waypoint can disconnect the graph (the only doorway);
    the replan then bans the failed waypoints alone instead of giving the waypoint up."""
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=1)
    policy = SearchPolicy.from_models(agent, agent, nodes, d_max=12.0, seed=0, ban_radius=1e9)
    obs, _ = env.reset(seed=0, options={"starts": [[10.0, 27.5]], "goals": [[45.0, 27.5]]})
    policy.predict({a: obs[a] for a in env.agents})
    route = list(policy.routes["agent_0"])
    assert len(route) >= 3
    policy.controller.index["agent_0"] = 1  # pretend it failed to reach its first waypoint
    new = policy.replanner.stuck(policy.controller, "agent_0", obs["agent_0"]["observation"],
                                 policy.controller.plans["agent_0"])
    assert policy.episode.states["agent_0"].banned == [route[1]]  # the neighbourhood ban (every node) was dropped
    new_route = policy.routes["agent_0"]
    # a new plan (giving the waypoint up would keep the old route's tail, without the start flag)
    assert new.starts_at_first and route[1] not in new_route and len(new.waypoints) == len(new_route)
