"""Capacity of the multi-agent env: decided in the constructor by the placement ``reset`` uses, so
every count the constructor accepts is placed at every seed."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

import safe_mapf_envs
from safe_mapf_envs import GridMap, NavigationScenario
from safe_mapf_envs.maps.apartments import APARTMENT_ENV_KWARGS
from safe_mapf_envs.scenario import RANDOM_FILL


def placed(env, infos, key):
    return np.array([infos[a][key] for a in env.possible_agents])


def assert_separated(env, pts, least):
    assert env.scenario.is_free(pts).all()
    if len(pts) > 1:
        assert cKDTree(pts).query(pts, k=2)[0][:, 1].min() >= least


@pytest.mark.parametrize("env_id, seeds, least", [
    ("SafeCentralObstacle-v0", 25, 700),   # random sampling alone separates about 390 here
    ("SafeCenterDot-v0", 100, 50),         # and about 35 here
])
def test_every_reset_places_the_capacity_and_one_more_agent_is_refused(env_id, seeds, least):
    cap = safe_mapf_envs.parallel_env(env_id, n_agents=1).capacity
    assert cap >= least
    env = safe_mapf_envs.parallel_env(env_id, n_agents=cap)
    assert env.capacity == cap
    for seed in range(seeds):
        _, infos = env.reset(seed=seed)
        for key in ("position", "goal"):
            assert_separated(env, placed(env, infos, key), env.min_separation)
    with pytest.raises(ValueError, match=f"n_agents={cap + 1} cannot fit on .*: its capacity is {cap} agents"):
        safe_mapf_envs.parallel_env(env_id, n_agents=cap + 1)


def test_counts_that_random_sampling_cannot_separate_are_placed_from_the_packing():
    env = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=40)  # random sampling fails at most seeds
    for seed in range(20):
        _, infos = env.reset(seed=seed)
        for key in ("position", "goal"):
            assert_separated(env, placed(env, infos, key), env.min_separation)
    big = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=450)
    for seed in range(2):
        _, infos = big.reset(seed=seed)
        assert_separated(big, placed(big, infos, "position"), big.min_separation)


def test_placement_from_the_packing_is_random_and_depends_on_the_seed_alone():
    sc = NavigationScenario("CentralObstacle")
    n = sc.max_agents(2.0, RANDOM_FILL) + 1  # beyond random sampling: from the packing
    a = sc.sample_separated(n, 2.0, np.random.default_rng(7))
    b = sc.sample_separated(n, 2.0, np.random.default_rng(7))
    c = sc.sample_separated(n, 2.0, np.random.default_rng(8))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    # most positions were moved off the packing
    slots = sc.packing(2.0)
    assert (cKDTree(slots).query(a)[0] > 1e-6).mean() > 0.4
    env1 = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=59)
    env2 = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=59)
    assert np.array_equal(env1.reset(seed=3)[1]["agent_5"]["goal"], env2.reset(seed=3)[1]["agent_5"]["goal"])


@pytest.mark.parametrize("name", ["CentralObstacle", "CenterDot", "Maze", "Spiral", "Apartment0", "Apartment3"])
def test_the_packing_is_free_separated_deterministic_and_shared(name):
    kw = {"agent_radius": APARTMENT_ENV_KWARGS["agent_radius"]} if name.startswith("Apartment") else {}
    sc = NavigationScenario(name, **kw)
    sep = 2.0 * sc.agent_radius + (0.5 if kw else 1.0)
    slots = sc.packing(sep)
    assert len(slots) == sc.capacity(sep) > 0
    assert sc.is_free(slots).all()
    assert cKDTree(slots).query(slots, k=2)[0][:, 1].min() >= sep
    assert not slots.flags.writeable
    assert NavigationScenario(name, **kw).packing(sep) is slots  # one per map and arguments
    # a wider separation fits fewer
    assert sc.capacity(1.5 * sep) < len(slots)
    with pytest.raises(ValueError, match="at least 2 \\* agent_radius"):
        sc.packing(sc.agent_radius)


def test_low_cost_starts_have_their_own_capacity():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1, max_start_cost=0.0)
    plain = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1).capacity
    cap = env.capacity
    assert 0 < cap < plain and cap == env.scenario.capacity(env.min_separation, 0.0)
    full = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=cap, max_start_cost=0.0)
    for seed in range(5):
        _, infos = full.reset(seed=seed)
        starts = placed(full, infos, "position")
        assert_separated(full, starts, full.min_separation)
        assert (full.field.cost(starts) == 0.0).all()
    with pytest.raises(ValueError, match=f"n_agents={cap + 1} .* its capacity is {cap} agents .*starts with cost <= 0"):
        safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=cap + 1, max_start_cost=0.0)


def test_capacity_follows_min_separation_and_holds_without_agent_collisions():
    base = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=1)
    wide = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=1, min_separation=3.0)
    tight = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=1, min_separation=1.0)
    assert wide.capacity < base.capacity < tight.capacity
    ghost = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=base.capacity, agent_collisions=False)
    assert ghost.capacity == base.capacity
    ghost.reset(seed=0)
    with pytest.raises(ValueError, match="cannot fit on CenterDot: its capacity is"):
        safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=base.capacity + 1, agent_collisions=False)


def test_a_map_of_your_own_has_a_capacity_too():
    room = GridMap("Room", ("....", ".#..", "...."), resize_factor=2.0, cost_radius=2.0)
    cap = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=1, layout=room).capacity
    env = safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=cap, layout=room)
    assert env.metadata["name"] == "room_v0"
    for seed in range(20):
        _, infos = env.reset(seed=seed)
        assert_separated(env, placed(env, infos, "position"), env.min_separation)
    with pytest.raises(ValueError, match=f"cannot fit on Room: its capacity is {cap} agents"):
        safe_mapf_envs.parallel_env("SafeCenterDot-v0", n_agents=cap + 1, layout=room)
