"""A thousand agents in one world on a large map, and the shortcuts that make the envs fast while
keeping their results: the box index of the cost field, the single-agent fast paths, restarting
a one-agent world, nearest neighbours from a k-d tree, the limited goal search and the packing's
windowed grid test."""
import gc
import weakref

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial import cKDTree

import safe_mapf_envs
from safe_mapf_envs import cost as cost_module
from safe_mapf_envs.cost import ObstacleField
from safe_mapf_envs.maps import GridMap
from safe_mapf_envs.scenario import NavigationScenario
from safe_mapf_envs.world import World


def _scatter(size: int = 64, blocked: float = 0.1, seed: int = 0) -> GridMap:
    """A ``size`` x ``size`` map with about ``blocked`` of its cells blocked at random, 3 units per cell."""
    grid = np.random.default_rng(seed).random((size, size)) < blocked
    rows = tuple("".join("#" if b else "." for b in row) for row in grid)
    return GridMap(f"Scatter{size}", rows, resize_factor=3.0, cost_radius=3.0)


BIG = _scatter()


# --------------------------------------------------------------------- a thousand agents
def test_a_thousand_agents_make_reset_and_step_on_a_large_map():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1000, layout=BIG, max_cycles=3)
    assert env.capacity >= 1000 and env.world_size == (192.0, 192.0)
    obs, infos = env.reset(seed=0)
    assert len(obs) == len(infos) == 1000 == len(env.agents)
    starts = env.positions
    assert cKDTree(starts).query(starts, k=2)[0][:, 1].min() >= env.min_separation
    assert env.scenario.is_free(starts).all()
    rng = np.random.default_rng(0)
    for _ in range(3):
        live = env.agents
        obs, rewards, terms, truncs, infos = env.step(dict(zip(live, rng.uniform(-1, 1, (len(live), 2)))))
        assert set(obs) == set(rewards) == set(infos) == set(live)
        pos = np.array([infos[a]["position"] for a in live])
        assert np.all((pos >= 0) & (pos <= 192.0))
        assert np.allclose(pos, env.positions[[env.agent_name_mapping[a] for a in live]])
        costs = np.array([infos[a]["obstacle_cost"] for a in live])
        want = env.scenario.field.cost_of_distance(env.scenario.field.distance(pos))
        assert np.all(costs >= want)  # the largest over the step's sub-steps, the last one included
    assert all(truncs.values()) and not env.agents


def test_the_world_of_an_episode_is_freed_at_the_next_reset():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=50, layout=BIG, max_cycles=5)
    env.reset(seed=0)
    env.step({a: np.ones(2) for a in env.agents})
    old_world, old_space = weakref.ref(env._world), weakref.ref(env._world.space)
    env.reset(seed=1)
    gc.collect()
    assert old_world() is None and old_space() is None


def test_a_single_agent_restarts_in_its_space_unless_parked_agents_come_or_go():
    env = gym.make("SafeCentralObstacle-v0").unwrapped
    env.reset(seed=0)
    world = env._world
    first = [weakref.ref(world.bodies[0]), weakref.ref(world._discs[0])]
    for _ in range(3):
        env.reset()
        env.step(np.ones(2, np.float32))
    gc.collect()
    assert env._world is world and env._world.n_agents == 1
    assert all(ref() is None for ref in first)  # the agents of earlier episodes are freed
    assert len(world.space.bodies) == 1 and len(world.space.shapes) == 1 + len(world._walls)
    parked = gym.make("SafeCentralObstacle-v0", parked_agents=3).unwrapped
    parked.reset(seed=0)
    first = parked._world
    parked.reset()
    assert parked._world is not first  # worlds with parked agents are built anew


# --------------------------------------------------------------------- the box index
def _probes(field: ObstacleField, n: int, seed: int) -> np.ndarray:
    """Points anywhere (a little outside the world too), at box corners, exactly a cost radius
    from a box and just within or beyond it, and non-finite ones."""
    rng = np.random.default_rng(seed)
    boxes = field.boxes[rng.integers(len(field.boxes), size=n)]
    return np.concatenate([
        rng.uniform(-5.0, 197.0, size=(2 * n, 2)),
        boxes[:, :2], boxes[:, 2:],
        np.stack([boxes[:, 0] - 3.0, rng.uniform(boxes[:, 1], boxes[:, 3])], 1),
        boxes[:, 2:] + rng.choice([0.0, 0.5, 2.9999999, 3.0, 3.0000001], size=(n, 1)),
        [[np.nan, 3.0], [np.inf, 4.0], [-np.inf, np.nan]],
    ])


@pytest.mark.parametrize("cost_fn", ["linear", "cosine", "constant"])
def test_the_box_index_gives_the_costs_of_every_box(cost_fn):
    for boundary_cost in (False, True):
        field = ObstacleField(BIG.boxes(), BIG.size, 3.0, cost_fn=cost_fn, boundary_cost=boundary_cost)
        pts = _probes(field, 400, seed=1)
        assert field._index(3.0, len(pts)) is not None  # the indexed path is the one tested
        assert np.array_equal(field.cost(pts), field.cost_of_distance(field.distance(pts)), equal_nan=True)


def test_the_box_index_gives_the_overlaps_of_every_box(monkeypatch):
    field = ObstacleField(BIG.boxes(), BIG.size, 3.0)
    pts = _probes(field, 400, seed=2)
    with np.errstate(invalid="ignore"):
        indexed = {m: field.inside(pts, margin=m) for m in (0.0, 0.4995, 0.5, 3.0)}
        assert all(field._index(m, len(pts)) is not None for m in indexed)
        monkeypatch.setattr(cost_module, "INDEX_MIN_BOXES", 10 ** 9)  # every box, densely
        for m, inside in indexed.items():
            assert np.array_equal(inside, field.inside(pts, margin=m)), m


@pytest.mark.parametrize("layout", ["CentralObstacle", "FourRooms", "Maze"])
@pytest.mark.parametrize("cost_fn", ["linear", "cosine", "constant"])
def test_peak_cost_is_the_largest_cost_of_the_points(layout, cost_fn):
    sc = NavigationScenario(layout, cost_fn=cost_fn)
    rng = np.random.default_rng(2)
    for boundary in (False, True):
        field = ObstacleField(sc.boxes, sc.size, sc.field.cost_radius, cost_fn=cost_fn, boundary_cost=boundary)
        for k in (1, 2, 4, 5):
            for _ in range(50):
                pts = rng.uniform(-1.0, sc.size[0] + 1.0, size=(k, 2))
                assert field.peak_cost(pts) == float(field.cost(pts).max())
        with np.errstate(invalid="ignore"):
            nan = np.array([[np.nan, 1.0], [2.0, 2.0]])
            assert np.isnan(field.peak_cost(nan)) == np.isnan(float(field.cost(nan).max()))


# --------------------------------------------------------------------- one agent's world
def _drive(world: World, actions: np.ndarray) -> np.ndarray:
    return np.stack([world.step(a[None])[0] for a in actions])


def test_a_restarted_world_steps_exactly_like_a_new_one():
    sc = NavigationScenario("FourRooms")
    rng = np.random.default_rng(3)
    start = np.array([1.0, 1.0])
    world = World(sc.size, sc.boxes, start[None], sc.agent_radius, 4)
    for _ in range(6):
        # every episode ends pressed into a wall, where the last step leaves the body a push to apply
        _drive(world, np.concatenate([rng.uniform(-1.5, 1.5, size=(10, 2)), np.tile(rng.choice([-1.0, 1.0], 2),
                                                                                     (40, 1))]))
        start = sc.sample_states(1, rng)[0]
        actions = np.concatenate([np.tile(rng.uniform(-1.0, 1.0, 2), (15, 1)), rng.uniform(-1.5, 1.5, size=(15, 2))])
        assert world.restart(start[None])
        fresh = World(sc.size, sc.boxes, start[None], sc.agent_radius, 4)
        assert np.array_equal(_drive(world, actions), _drive(fresh, actions))
    world.park(0)
    assert not world.restart(start[None])


@pytest.mark.parametrize("env_id", ["SafeSpiral-v0", "SafeMaze-v0", "SafeApartment2-v0"])
def test_a_seeded_reset_replays_the_episode_after_any_other(env_id):
    env = gym.make(env_id).unwrapped
    rng = np.random.default_rng(8)
    for seed in range(60):
        actions = rng.uniform(-1.0, 1.0, size=(3, 2)).astype(np.float32)
        runs = []
        for _ in range(2):
            env.reset(seed=seed)
            runs.append([env.step(a)[4]["position"] for a in actions])
        assert np.array_equal(runs[0], runs[1]), seed


def test_the_single_agent_step_matches_pymunks_public_api():
    sc = NavigationScenario("Maze")
    actions = np.random.default_rng(4).uniform(-1.5, 1.5, size=(80, 2))
    a, b = (World(sc.size, sc.boxes, np.array([[1.5, 1.5]]), sc.agent_radius, 4) for _ in range(2))
    for x, y in actions.tolist():
        assert np.array_equal(a.step_single(x, y), b._step_single_api(x, y))


# --------------------------------------------------------------------- neighbours and overlaps
def test_nearest_neighbours_from_the_tree_are_those_of_every_agent():
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=300, layout=BIG, observe_neighbors=6)
    env.reset(seed=0)
    idx = np.arange(env.n_agents)
    tree = env._neighbors(idx, env.positions)
    assert np.array_equal(tree, env._nearest_dense(idx, env.positions, 6).astype(np.float32))
    # agents that pass through each other share places: ties at every distance, ordered by index
    ghosts = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=300, layout=BIG, observe_neighbors=6,
                                         agent_collisions=False)
    places = ghosts.scenario.sample_separated(190, 2.0, np.random.default_rng(5))
    crowded = np.repeat(places[:10], 12, axis=0)  # more at one place than the tree proposes
    ghosts.reset(seed=0, options={"starts": np.concatenate([crowded, places[10:]])})
    tree = ghosts._neighbors(idx, ghosts.positions)
    assert np.array_equal(tree, ghosts._nearest_dense(idx, ghosts.positions, 6).astype(np.float32))
    assert np.all(tree[:120] == 0.0) and np.all(tree[120:] != 0.0)


def test_overlapping_starts_among_many_are_named_as_among_few():
    sc = NavigationScenario(BIG)
    starts = sc.sample_separated(800, 2.0, np.random.default_rng(6))
    assert sc._first_overlap(starts) is None
    starts[500] = starts[120] + [0.3, 0.4]
    starts[700] = starts[640] + [0.0, 0.2]
    assert sc._first_overlap(starts) == (120, 500, pytest.approx(0.5))
    with pytest.raises(ValueError, match="starts of agent_120 and agent_500 are 0.5 apart"):
        sc.check_agent_positions(starts, 800, "start")


# --------------------------------------------------------------------- placement
@pytest.mark.parametrize("layout", ["CentralObstacle", "FourRooms", "Tunnel"])
def test_goals_in_a_band_are_those_of_the_full_geodesic_search(layout):
    sc = NavigationScenario(layout)
    oracle = sc.oracle

    def full_search(start, band, rng):  # every distance from the start, then the same draws
        lo, hi = band
        cells, _ = oracle.band_cells(start, lo, hi)
        centres = oracle.centres.reshape(-1, 2)
        for _ in range(100):
            goal = centres[cells[rng.integers(len(cells))]] + rng.uniform(-0.5, 0.5, size=2) * oracle.resolution
            if sc.is_free(goal) and lo <= float(oracle.distance(start, goal)) <= hi:
                return goal
        return centres[cells[rng.integers(len(cells))]].copy()

    starts = sc.sample_states(40, np.random.default_rng(7))
    for i, start in enumerate(starts):
        band = (0.0, 20.0) if i % 2 else (5.0, 12.0)
        want = full_search(start, band, np.random.default_rng(i))
        assert np.array_equal(sc.sample_goal_in_band(start, band, np.random.default_rng(i)), want)


def test_the_packing_grid_test_is_that_of_every_box():
    sc = NavigationScenario(BIG)
    xs, ys = np.arange(0.5, 70.0, 0.25), np.arange(0.5, 45.0, 0.25)
    r = sc.agent_radius
    w, h = sc.size
    free = ~(((ys < r) | (ys > h - r))[:, None] | ((xs < r) | (xs > w - r))[None, :])
    for x0, y0, x1, y1 in sc.field.boxes.tolist():
        gx = np.maximum(np.maximum(x0 - xs, xs - x1), 0.0)
        gy = np.maximum(np.maximum(y0 - ys, ys - y1), 0.0)
        free &= np.sqrt(gy[:, None] * gy[:, None] + gx[None, :] * gx[None, :]) >= r
    assert np.array_equal(sc._allowed_grid(xs, ys), free)
