"""Panorama raycaster, furnished apartments and the visual environments."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from scipy.sparse.csgraph import connected_components
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import safe_mapf_envs
from safe_mapf_envs import ENV_SPECS
from safe_mapf_envs.maps import APARTMENTS, get_map
from safe_mapf_envs.maps.apartments import APARTMENT_ENV_KWARGS
from safe_mapf_envs.scenario import NavigationScenario
from safe_mapf_envs.sensors import Material, PanoramaSensor, Scene, SceneBox, render_panoramas, scene_for_layout

VISUAL_IDS = [s.id for s in ENV_SPECS if s.obs_type == "panorama"]
PLAIN = Material((200, 200, 200))


def room_scene(boxes=(), size=(10.0, 10.0)):
    """An empty 10 x 10 m room (boundary walls only) plus ``boxes``; camera 1.2 m, range 10 m."""
    return Scene(size, list(boxes), ceiling_height=2.5, camera_height=1.2, max_range=10.0, agent_height=0.9)


def depth_m(pano, sensor):
    """Depth channel back to metres (quantised)."""
    return pano[..., 3].astype(np.float64) / 255.0 * sensor.max_range


# --------------------------------------------------------------------------- renderer
def test_shapes_and_dtype():
    scene = scene_for_layout(get_map("Apartment0"))
    out = render_panoramas(scene, np.array([[2.0, 4.0], [9.0, 3.5], [6.0, 6.0]]))
    assert out.shape == (3, 4, 32, 32, 4) and out.dtype == np.uint8
    single = render_panoramas(scene, [2.0, 4.0])
    assert single.shape == (4, 32, 32, 4)
    assert np.array_equal(single, out[0])
    small = PanoramaSensor(scene, image_size=16).render(np.array([[2.0, 4.0]]))
    assert small.shape == (1, 4, 16, 16, 4)


def test_identical_positions_identical_images_and_batch_equals_single():
    scene = scene_for_layout(get_map("Apartment1"))
    sensor = PanoramaSensor(scene)
    pts = NavigationScenario(get_map("Apartment1"), agent_radius=0.2).sample_states(6, np.random.default_rng(0))
    batch = sensor.render(np.concatenate([pts, pts[:2]]))
    assert np.array_equal(batch[:2], batch[6:])
    for i, p in enumerate(pts):
        assert np.array_equal(sensor.render(p), batch[i])
    # distinct places look distinct
    assert all(not np.array_equal(batch[i], batch[j]) for i in range(6) for j in range(i + 1, 6))


@pytest.mark.parametrize("name", sorted(APARTMENTS))
def test_moving_half_a_metre_changes_the_image(name):
    layout = get_map(name)
    sensor = PanoramaSensor(scene_for_layout(layout))
    sc = NavigationScenario(layout, agent_radius=0.2)
    rng = np.random.default_rng(1)
    starts = sc.sample_states(40, rng)
    angle = rng.uniform(0, 2 * np.pi, 40)
    ends = starts + 0.5 * np.stack([np.cos(angle), np.sin(angle)], 1)
    ok = sc.is_free(ends)
    a, b = sensor.render(starts[ok]), sensor.render(ends[ok])
    diff = np.abs(a.astype(int) - b.astype(int)).mean(axis=(1, 2, 3, 4))
    assert ok.sum() >= 10
    assert diff.min() > 3.0  # every 0.5 m move changes the panorama markedly


def test_wall_ahead_is_near_in_the_facing_view_and_far_behind():
    sensor = PanoramaSensor(room_scene())
    pano = sensor.render(np.array([5.0, 1.0]))  # 1 m from the north wall, 9 m from the south wall
    d = depth_m(pano, sensor)
    mid = slice(14, 18)  # rows and columns around the view centre
    north, east, south, west = (d[v, mid, mid] for v in range(4))
    assert np.allclose(north, 1.0, atol=0.05)
    assert np.allclose(south, 9.0, atol=0.05)
    assert np.allclose(east, 5.0, atol=0.05) and np.allclose(west, 5.0, atol=0.05)
    # the floor: the bottom row of the south view sees the floor at 1.2 / tan(45 deg) (1 - 1/32)
    assert d[2, -1, 16] == pytest.approx(1.2 / (1 - 1 / 32), abs=0.05)


def test_low_furniture_shows_its_top_and_the_wall_behind():
    bench = SceneBox((4.0, 1.5, 6.0, 4.0), 0.3, Material((200, 40, 40)), Material((40, 40, 200)))
    sensor = PanoramaSensor(room_scene([bench]))
    pano = sensor.render(np.array([5.0, 6.0]))  # the bench from 2 to 4.5 m north, the wall at 6 m
    col = pano[0, :, 16]
    d = depth_m(pano[0], sensor)[:, 16]
    below = np.arange(32) >= 16  # rows below the horizon (above it: ceiling)
    front = np.flatnonzero(below & (np.abs(d - 2.0) < 0.05))
    top = np.flatnonzero(below & (d > 2.05) & (d < 4.45))
    wall = np.flatnonzero(np.abs(d - 6.0) < 0.05)
    assert len(front) >= 2 and len(top) >= 2 and len(wall) >= 2
    assert wall.max() < top.min() and top.max() < front.min()  # wall above the top above the front
    assert (col[front, 0] > col[front, 2]).all()  # the red side
    assert (col[top, 2] > col[top, 0]).all()  # the blue top
    assert (np.diff(d[top]) < 0).all()  # the top recedes towards the horizon


def brute_force_depth(scene, sensor, p, agents=(), radius=0.0):
    """Planar depth of every pixel by intersecting its 3D ray with every box, cylinder, floor, ceiling."""
    S = sensor.image_size
    tan = np.tan(np.radians(sensor.fov) / 2)
    u = ((np.arange(S) + 0.5) * 2 / S - 1) * tan
    fwd = np.array([(0, -1), (1, 0), (0, 1), (-1, 0)], float)
    right = np.array([(1, 0), (0, 1), (-1, 0), (0, -1)], float)
    dxy = fwd[:, None, None, :] + u[None, None, :, None] * right[:, None, None, :]  # (4, 1, S, 2)
    dxy = np.broadcast_to(dxy, (4, S, S, 2)).reshape(-1, 2)
    v = np.broadcast_to(-u[None, :, None], (4, S, S)).reshape(-1)
    hc, ceil = sensor.camera_height, scene.ceiling_height
    best = np.full(len(v), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        best = np.where(v < 0, hc / -v, (ceil - hc) / v)
        for lo, hi, h in zip(scene.lo.astype(float), scene.hi.astype(float), scene.heights.astype(float)):
            t1 = (lo - p) / dxy
            t2 = (hi - p) / dxy
            tin = np.maximum(np.minimum(t1, t2).max(1), 0)
            tout = np.maximum(t1, t2).min(1)
            for t in (tin, np.where(v < 0, (h - hc) / v, np.inf)):  # side face, then the top
                z = hc + v * t
                ok = (t >= tin - 1e-9) & (t <= tout + 1e-9) & (tout > tin) & (z >= -1e-9) & (z <= h + 1e-9)
                best = np.where(ok & (t < best), t, best)
        for c in np.asarray(agents, float).reshape(-1, 2):
            oc = c - p
            a = (dxy ** 2).sum(1)
            b = dxy @ oc
            disc = b * b - a * (oc @ oc - radius ** 2)
            root = np.sqrt(np.maximum(disc, 0))
            tin, tout = (b - root) / a, (b + root) / a
            for t in (tin, np.where(v < 0, (scene.agent_height - hc) / v, np.inf)):
                z = hc + v * t
                ok = (disc > 0) & (t >= tin - 1e-9) & (t <= tout + 1e-9)
                ok &= (z >= -1e-9) & (z <= scene.agent_height + 1e-9)
                best = np.where(ok & (t > 0) & (t < best), t, best)
    return best.reshape(4, S, S)


@pytest.mark.parametrize("name", ["Apartment0", "Apartment3", "Maze"])
def test_depth_matches_brute_force_ray_casting(name):
    layout = get_map(name)
    scene = scene_for_layout(layout)
    sensor = PanoramaSensor(scene)
    radius = 0.2 * getattr(layout, "resize_factor", 1.0) if name == "Maze" else 0.2
    pts = NavigationScenario(layout, agent_radius=radius).sample_states(8, np.random.default_rng(3))
    others = pts[4:]
    for p in pts[:4]:
        for agents in ((), others):
            got = sensor.render(p, agents=np.asarray(agents).reshape(-1, 2), agent_radius=radius)[..., 3].astype(int)
            ref = brute_force_depth(scene, sensor, p, agents, radius)
            ref = np.round(np.minimum(ref / sensor.max_range, 1) * 255).astype(int)
            close = np.abs(got - ref) <= 1
            assert close.mean() > 0.995, f"{name} at {p}: {np.count_nonzero(~close)} pixels differ"


def test_other_agents_are_drawn_and_an_agent_never_sees_itself():
    scene = room_scene()
    sensor = PanoramaSensor(scene)
    cams = np.array([[5.0, 5.0], [5.0, 3.0]])
    plain = sensor.render(cams)
    both = sensor.render(cams, agents=cams, agent_radius=0.2, self_index=[0, 1])
    # camera 0 sees agent 1 two metres to its north, in agent 1's palette colour
    assert not np.array_equal(both[0], plain[0])
    d = depth_m(both[0, 0], sensor)
    assert d[22:26, 15:17].min() == pytest.approx(1.8, abs=0.05)  # the near side of its cylinder
    r, _, b = both[0, 0, 24, 16, :3].astype(int)
    assert b < 0.3 * r  # orange, the top-down colour of agent 1 (walls and floor are greyish)
    # alone in the room, an agent's own body is invisible
    alone = sensor.render(cams[:1], agents=cams[:1], agent_radius=0.2, self_index=[0])
    assert np.array_equal(alone[0], plain[0])


def test_sensor_rejects_bad_arguments():
    scene = room_scene()
    with pytest.raises(ValueError, match="image_size"):
        PanoramaSensor(scene, image_size=1)
    with pytest.raises(ValueError, match="fov"):
        PanoramaSensor(scene, fov=180.0)
    with pytest.raises(ValueError, match="camera_height"):
        PanoramaSensor(scene, camera_height=3.0)
    with pytest.raises(ValueError, match="max_range"):
        PanoramaSensor(scene, max_range=-1.0)
    sensor = PanoramaSensor(scene)
    with pytest.raises(ValueError, match="finite"):
        sensor.render(np.array([np.nan, 1.0]))
    with pytest.raises(ValueError, match="shape"):
        sensor.render(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="agent_radius"):
        sensor.render(np.array([5.0, 5.0]), agents=np.array([[4.0, 4.0]]))
    with pytest.raises(ValueError, match="self_index"):
        sensor.render(np.zeros((2, 2)) + 5, agents=np.zeros((1, 2)), agent_radius=0.2, self_index=[0])
    with pytest.raises(ValueError, match="camera_height"):
        Scene((5, 5), [], ceiling_height=2.0, camera_height=2.0, max_range=5, agent_height=1)


# --------------------------------------------------------------------------- apartments
@pytest.mark.parametrize("name", sorted(APARTMENTS))
def test_apartments_are_furnished_connected_layouts(name):
    apt = get_map(name)
    w, h = apt.size
    assert 10.0 <= max(w, h) <= 15.0 and min(w, h) >= 8.0
    assert len(apt.furniture) >= 10 and len(apt.rooms) >= 3
    assert apt.cost_radius == 1.0
    assert {"couch", "table", "counter", "bed", "bookshelf"} & {f.kind for f in apt.furniture}
    boxes = np.array(apt.boxes())
    assert len(boxes) == len(apt.walls) + len(apt.furniture)
    assert (boxes[:, :2] >= 0).all() and (boxes[:, 2] <= w).all() and (boxes[:, 3] <= h).all()
    # every free place can reach every other one: no pocket a sampled start could be stuck in
    oracle = NavigationScenario(apt, agent_radius=APARTMENT_ENV_KWARGS["agent_radius"]).oracle
    assert oracle.resolution == pytest.approx(0.1)
    _, labels = connected_components(oracle._graph, directed=False)
    assert len(np.unique(labels[oracle.free.reshape(-1)])) == 1


# --------------------------------------------------------------------------- environments
def test_visual_ids_are_registered():
    assert {"SafeApartment0-v0", "SafeApartment1-v0", "SafeApartment2-v0", "SafeApartment3-v0"} <= set(VISUAL_IDS)
    assert "SafeCentralObstacleVisual-v0" in VISUAL_IDS
    for env_id in VISUAL_IDS:
        assert gym.spec(env_id).max_episode_steps == 20


#: What SB3's checker says about the (4, 32, 32, 4) images: one warning per key, because its
#: image checks only know 3D (H, W, C) images. Agents use their own CNN feature extractor.
SB3_IMAGE_WARNING = "has an unconventional shape (neither an image, nor a 1D vector)"


@pytest.mark.parametrize("env_id", VISUAL_IDS)
def test_gymnasium_and_sb3_checkers_pass(env_id):
    env = gym.make(env_id)
    gym_check_env(env.unwrapped, skip_render_check=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(gym.make(env_id).unwrapped, warn=True)
    messages = {str(w.message) for w in caught}
    assert messages and all(SB3_IMAGE_WARNING in m for m in messages), messages
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert obs["observation"].shape == (4, 32, 32, 4) and obs["observation"].dtype == np.uint8


def test_goal_is_the_panorama_seen_at_the_goal_and_positions_stay_in_info():
    env = gym.make("SafeApartment0-v0").unwrapped
    obs, info = env.reset(seed=0, options={"start": (2.0, 4.0), "goal": (9.0, 3.6)})
    assert np.array_equal(obs["desired_goal"], env.sensor.render(np.array([9.0, 3.6])))
    assert np.array_equal(obs["observation"], env.sensor.render(np.array([2.0, 4.0])))
    assert np.array_equal(obs["achieved_goal"], obs["observation"])
    assert np.allclose(info["position"], (2.0, 4.0)) and np.allclose(info["goal"], (9.0, 3.6))
    obs2, _, _, _, info2 = env.step(np.array([1.0, 0.0], np.float32))
    assert np.array_equal(obs2["desired_goal"], obs["desired_goal"])
    assert info2["position"] == pytest.approx([2.25, 4.0], abs=1e-6)  # action_scale: 0.25 m
    assert np.array_equal(obs2["observation"], env.sensor.render(info2["position"]))


def test_observation_does_not_depend_on_render_mode():
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(6, 2)).astype(np.float32)
    runs = []
    for mode in (None, "rgb_array"):
        env = gym.make("SafeApartment2-v0", render_mode=mode)
        obs, _ = env.reset(seed=4)
        seq = [obs["observation"]]
        for a in actions:
            obs, *_ = env.step(a)
            seq.append(obs["observation"])
        if mode == "rgb_array":
            assert env.render().ndim == 3
        runs.append(np.array(seq))
    assert np.array_equal(runs[0], runs[1])


def test_compute_reward_and_terminated_on_images():
    env = gym.make("SafeApartment1-v0").unwrapped
    obs, _ = env.reset(options={"start": (7.0, 5.0), "goal": (7.3, 5.0)})
    obs, reward, terminated, _, info = env.step(np.array([1.0, 0.0], np.float32))
    assert terminated and info["is_success"]  # ground truth: 0.05 m away
    a, d = obs["achieved_goal"], obs["desired_goal"]
    assert reward == 0.0  # the step's reward follows its (ground-truth) termination
    # from images alone only identical panoramas count as reaching the goal
    assert env.compute_reward(a, d, info) == (0.0 if np.array_equal(a, d) else -1.0)
    assert env.compute_reward(a, a, info) == 0.0
    assert env.compute_terminated(a, a, info) is True
    assert env.compute_terminated(a, d, info) is (bool(np.array_equal(a, d)))
    batch_a, batch_d = np.stack([a, a, d]), np.stack([a, d, d])
    assert env.compute_reward(batch_a, batch_d, [info] * 3).tolist() == [0.0, -float(not np.array_equal(a, d)), 0.0]
    assert env.compute_terminated(batch_a, batch_d, [info] * 3).tolist() == [True, bool(np.array_equal(a, d)), True]
    assert env.compute_truncated(batch_a, batch_d, [info] * 3).tolist() == [False] * 3


def test_panoramas_on_2d_maps_and_bad_arguments():
    env = gym.make("SafeMaze-v0", obs_type="panorama", sensor_kwargs={"image_size": 16})
    obs, _ = env.reset(seed=0)
    assert obs["observation"].shape == (4, 16, 16, 4) and env.observation_space.contains(obs)
    obs, *_ = env.step(np.array([1.0, 0.0], np.float32))
    assert env.observation_space.contains(obs)
    with pytest.raises(ValueError, match="obs_type"):
        gym.make("SafeMaze-v0", obs_type="rgb")
    with pytest.raises(ValueError, match="action_scale"):
        gym.make("SafeMaze-v0", action_scale=0.0)
    # the vector ids keep their observations
    vec, _ = gym.make("SafeMaze-v0").reset(seed=0)
    assert vec["observation"].shape == (2,)
    assert isinstance(safe_mapf_envs.get_map("Apartment0"), safe_mapf_envs.Apartment)


# --------------------------------------------------------------------------- multi-agent
VISUAL_MULTI_IDS = ["SafeApartment0-v0", "SafeApartment3-v0", "SafeCentralObstacleVisual-v0"]


@pytest.mark.parametrize("env_id", VISUAL_MULTI_IDS)
def test_pettingzoo_api_on_visual_multi_agent_envs(env_id):
    from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

    parallel_api_test(safe_mapf_envs.parallel_env(env_id, n_agents=3, max_cycles=15), num_cycles=30)
    parallel_seed_test(lambda: safe_mapf_envs.parallel_env(env_id, n_agents=3, max_cycles=15), num_cycles=10)
    api_test(safe_mapf_envs.env(env_id, n_agents=3, max_cycles=15), num_cycles=20)
    par = safe_mapf_envs.parallel_env(env_id, n_agents=3)
    obs, _ = par.reset(seed=0)
    for agent in par.agents:
        assert par.observation_space(agent).contains(obs[agent])
        assert obs[agent]["observation"].shape == (4, 32, 32, 4)


def test_multi_agent_panoramas_show_the_other_agents():
    par = safe_mapf_envs.parallel_env("SafeApartment0-v0", n_agents=3)
    starts = [(5.0, 4.0), (5.0, 3.0), (2.0, 4.0)]  # agent_1 one metre north of agent_0
    goals = [(9.0, 3.6), (5.0, 7.5), (6.0, 8.0)]
    obs, _ = par.reset(seed=0, options={"starts": starts, "goals": goals})
    sensor = par.sensor
    a0 = obs["agent_0"]["observation"]
    assert np.array_equal(a0, sensor.render(np.array(starts[0]), agents=np.array(starts), agent_radius=0.2,
                                            self_index=[0]))
    alone = sensor.render(np.array(starts[0]))
    d = depth_m(a0[0], sensor)
    assert not np.array_equal(a0[0], alone[0])  # agent_1 in the north view
    assert d[22:26, 15:17].min() == pytest.approx(0.8, abs=0.05)
    assert np.array_equal(a0[2], alone[2])  # nobody to the south
    # goals are the static views from the goals; the agents see images only
    for i, g in enumerate(goals):
        assert np.array_equal(obs[f"agent_{i}"]["desired_goal"], sensor.render(np.array(g)))
    acts = {a: np.array([0.0, 1.0], np.float32) for a in par.agents}
    obs2, _, _, _, infos = par.step(acts)
    assert infos["agent_2"]["position"] == pytest.approx([2.0, 4.25], abs=1e-6)  # action_scale 0.25 m
    assert par.observation_space("agent_2").contains(obs2["agent_2"])
