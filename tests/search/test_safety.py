"""The safety layer: no two agents touch, agents still arrive, and contacts are reported honestly without it."""
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import safe_mapf_envs
from agents.search import SearchPolicy
from agents.search.execution.safety import SafetyLayer, SafetyState, team_positions
from baselines.methods import METHODS, execute

LAYER = SafetyLayer(agent_radius=0.5, step_length=1.0)


def closest_approach(p, u, step=1.0):
    """Smallest centre distance over one step of straight-line motion, per pair ``(N, N)``."""
    d = p[:, None] - p[None]
    v = step * (u[:, None] - u[None])
    vv = (v * v).sum(-1)
    t = np.clip(-(d * v).sum(-1) / np.maximum(vv, 1e-18), 0.0, 1.0)
    c = d + t[..., None] * v
    out = np.sqrt((c * c).sum(-1))
    np.fill_diagonal(out, np.inf)
    return out


def drive(starts, goals, layer=True, steps=150, layout="SafeCentralObstacle-v0"):
    """Each agent heads straight for its goal at full speed, through the layer or not; returns
    (all arrived, contacts, steps taken, layer stats)."""
    env = safe_mapf_envs.parallel_env(layout, n_agents=len(starts), max_cycles=steps)
    env.reset(seed=0, options={"starts": starts, "goals": goals})
    shield, stats = SafetyLayer.for_env(env), SafetyState()
    goals = np.asarray(goals, dtype=np.float64)
    contacts = 0
    t = 0
    while env.agents:
        pos = team_positions(env)
        actions = {}
        for a in env.agents:
            d = goals[env.possible_agents.index(a)] - pos[a]
            actions[a] = (d / max(np.abs(d).max(), 1.0)).astype(np.float32)
        if layer:
            actions = shield.filter_agents(actions, pos, stats)
        _, _, term, _, infos = env.step(actions)
        contacts += sum(i["collisions"] for i in infos.values())
        t += 1
    arrived = bool(env.parked.all())
    env.close()
    return arrived, contacts, t, stats


RING = 8
ANGLES = np.linspace(0.0, 2 * np.pi, RING, endpoint=False)
CASES = {
    "head-on": ([(10.0, 10.0), (20.0, 10.0)], [(20.0, 10.0), (10.0, 10.0)]),
    "crossing": ([(10.0, 15.0), (15.0, 10.0)], [(20.0, 15.0), (15.0, 20.0)]),
    "crowded": ([(15 + 6 * math.cos(a), 15 + 6 * math.sin(a)) for a in ANGLES],
                [(15 - 6 * math.cos(a), 15 - 6 * math.sin(a)) for a in ANGLES]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_agents_arrive_without_touching(case):
    starts, goals = CASES[case]
    arrived, contacts, steps, stats = drive(starts, goals)
    assert arrived and contacts == 0
    assert stats.steered > 0  # the layer had work to do
    assert steps < 60


@pytest.mark.parametrize("case", sorted(CASES))
def test_without_the_layer_the_same_runs_touch(case):
    starts, goals = CASES[case]
    _, contacts, _, _ = drive(starts, goals, layer=False, steps=40)
    assert contacts > 0


def test_an_agent_is_steered_around_a_parked_one():
    """The second agent parks first, on the first one's straight line; the first slides past it."""
    arrived, contacts, _, stats = drive([(5.0, 10.0), (11.0, 10.0)], [(20.0, 10.0), (12.0, 10.0)])
    assert arrived and contacts == 0 and stats.steered > 0


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 30))
def test_no_step_brings_two_agents_into_contact(seed, n):
    """Whatever the actions asked for, the filtered step keeps every pair that starts apart apart."""
    rng = np.random.default_rng(seed)
    pos = []
    while len(pos) < n:  # agents at least a contact apart, packed into a small square
        q = rng.uniform(0.0, 2.0 * math.sqrt(n), 2)
        if all(np.hypot(*(q - o)) >= 1.0 for o in pos):
            pos.append(q)
    p = np.array(pos)
    u = rng.uniform(-1.0, 1.0, (n, 2))
    movable = rng.random(n) < 0.8
    out, steered, stopped = LAYER.filter(p, u, movable)
    assert out.dtype == np.float32 and np.abs(out).max() <= 1.0
    assert not out[~movable].any()
    assert not (stopped & ~movable).any() and not (steered & ~movable).any()
    dmin = closest_approach(p, out.astype(np.float64))
    start = np.hypot(*(p[:, None] - p[None]).transpose(2, 0, 1))
    assert (dmin >= np.minimum(1.0 + 1e-9, start - 1e-9)).all()


def test_free_agents_keep_their_actions():
    p = np.array([[0.0, 0.0], [10.0, 0.0]])
    u = np.array([[1.0, 0.5], [-0.3, 1.0]])
    out, steered, stopped = LAYER.filter(p, u, np.ones(2, bool))
    np.testing.assert_allclose(out, u, atol=1e-6)
    assert not steered.any() and not stopped.any()


def test_head_on_agents_turn_the_same_way():
    """Two agents nose to nose both turn to their right instead of stopping."""
    p = np.array([[0.0, 0.0], [1.6, 0.0]])
    out, steered, stopped = LAYER.filter(p, np.array([[1.0, 0.0], [-1.0, 0.0]]), np.ones(2, bool))
    assert steered.all() and not stopped.any()
    assert out[0, 1] * out[1, 1] < 0  # opposite sides in the world: each to its own right
    assert np.hypot(*out[0]) > 0.1 and np.hypot(*out[1]) > 0.1


def test_bad_settings_and_inputs_are_refused():
    for bad in ({"agent_radius": 0.0}, {"step_length": math.nan}, {"gamma": 0.0}, {"gamma": 1.5},
                {"clearance": -0.1}, {"bias": -1.0}, {"iterations": 0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            SafetyLayer(**bad)
    with pytest.raises(ValueError, match="finite"):
        LAYER.filter(np.array([[0.0, math.nan]]), np.zeros((1, 2)), np.ones(1, bool))
    with pytest.raises(ValueError, match="agent_1"):
        LAYER.filter_agents({"agent_1": np.zeros(2)}, {"agent_0": np.zeros(2)})
    with pytest.raises(TypeError, match="scenario"):
        SafetyLayer.for_env(object())


def test_the_layer_reads_the_env_geometry():
    env = safe_mapf_envs.parallel_env("SafeApartment0-v0", n_agents=2)
    layer = SafetyLayer.for_env(env)
    assert (layer.agent_radius, layer.step_length) == (0.2, 0.25)
    env.reset(seed=0)
    pos = team_positions(env)
    assert list(pos) == env.possible_agents
    np.testing.assert_array_equal(np.stack(list(pos.values())), env.positions)
    env.close()


def test_a_search_policy_with_a_layer_needs_the_team_positions(stand_in_models):
    policy = SearchPolicy(None, stand_in_models["unconstrained"], safety=LAYER)
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2)
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="positions"):
        policy.predict(obs)
    actions, _ = policy.predict(obs, positions=team_positions(env))
    assert set(actions) == set(env.agents)
    with pytest.raises(TypeError, match="SafetyLayer"):
        SearchPolicy(None, stand_in_models["unconstrained"], safety="on")
    env.close()


@pytest.mark.parametrize("safety", [True, False])
def test_the_harness_reports_contacts_and_the_safety_rate(stand_in_models, safety):
    """Head on in the env through the evaluation harness: with the layer no agent touches another and
    both arrive; without it the contacts and the safety rate say that they touched."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2, max_cycles=80)
    starts, goals = np.array([[10.0, 10.0], [20.0, 10.0]]), np.array([[20.0, 10.0], [10.0, 10.0]])
    method = METHODS["unconstrained_policy"].with_options(safety=safety)
    ex = execute(env, method, stand_in_models, None, starts, goals)
    env.close()
    if safety:
        assert ex.success and ex.collisions == 0 and ex.safety_rate == 1.0
        assert ex.extra["shield_steered"] > 0
    else:
        assert ex.collisions > 0 and ex.safety_rate == 0.0 and ex.touched.all()
        assert ex.extra["shield_steered"] == 0
    assert sum(ex.contact_reasons.values()) == ex.collisions  # every contact has its reason
    if not safety:  # the controller's yield did not keep them apart; then one drove into the other, parked
        assert ex.contact_reasons == {"into_holding": 1, "parked": 1}


def test_an_agent_the_layer_holds_for_long_counts_as_stuck(stand_in_models):
    """A blocked agent (a parked agent on its straight line, a wall beside it) is reported stuck after
    ``patience`` steps, so the controller's escapes take over."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=2, max_cycles=40)
    policy = SearchPolicy(None, stand_in_models["unconstrained"], safety=SafetyLayer.for_env(env, patience=3))
    obs, _ = env.reset(seed=0, options={"starts": [(0.5, 10.0), (0.9, 11.2)], "goals": [(0.5, 30.0), (0.9, 11.2)]})
    escapes = []
    while env.agents:
        actions, _ = policy.predict({a: obs[a] for a in env.agents}, positions=team_positions(env))
        obs, _, _, _, infos = env.step(actions)
        escapes.append(policy.stats.escapes)
        assert all(i["collisions"] == 0 for i in infos.values())
    env.close()
    assert policy.safety_state.deadlocks >= 1 and escapes[-1] >= 1
    assert escapes[0] == 0  # found stuck only once the layer had held it


def test_walls_stop_what_the_layer_plans_with():
    """An agent pressed against the world's border moves, for the layer, only along it: the other
    agent's approach from the side is judged with that motion."""
    env = safe_mapf_envs.parallel_env("SafeCentralObstacle-v0", n_agents=1)
    layer = SafetyLayer.for_env(env)
    env.close()
    assert layer.walls is not None and len(layer.walls) >= 4
    slid = layer._slide(np.array([[0.5, 10.0], [10.0, 10.0]]), np.array([[-1.0, 0.5], [-1.0, 0.5]]))
    np.testing.assert_allclose(slid, [[0.0, 0.5], [-1.0, 0.5]])


def _followed(env_id, start, actions, warm_up=()):
    """Per step, where the world moved one agent and where the layer said the walls would let it go."""
    env = safe_mapf_envs.parallel_env(env_id, n_agents=1)
    layer = SafetyLayer.for_env(env)
    env.reset(seed=0, options={"starts": [start]})
    for u in warm_up:
        env.step({"agent_0": np.asarray(u, np.float32)})
    out = []
    for u in actions:
        p = team_positions(env)["agent_0"].copy()
        said = p + layer.step_length * layer._slide(p[None], np.asarray([u], np.float64))[0]
        env.step({"agent_0": np.asarray(u, np.float32)})
        out.append((p, team_positions(env)["agent_0"].copy(), said))
    env.close()
    return out


def test_a_disc_meeting_a_box_corner_slides_round_it_as_the_world_moves_it():
    """Driven at a corner of CentralObstacle's box, the disc slides round it: the layer follows the
    world, where a straight line would miss by half the step."""
    steps = _followed("SafeCentralObstacle-v0", [19.4, 19.5], [[1.0, 0.6]] * 3)
    p, moved, said = steps[0]
    assert np.linalg.norm(moved - (p + [1.0, 0.6])) > 0.5  # the corner turned it
    for _, moved, said in steps:
        assert np.linalg.norm(moved - said) < 0.01


def test_a_disc_wedged_between_a_wall_and_a_corner_is_known_to_stay():
    """Apartment3 has a wall under a box whose corner leaves less than a disc's width: driven into the
    wedge, the disc stays, and the layer knows it stays."""
    steps = _followed("SafeApartment3-v0", [8.1, 7.9], [[1.0, 0.0], [0.83, -0.24]] * 2, warm_up=[[1.0, -0.3]] * 6)
    for p, moved, said in steps:
        assert np.linalg.norm(moved - p) < 0.01 and np.linalg.norm(said - p) < 0.01


def test_the_safety_table_reads_the_shipped_runs(run_example):
    on = sorted(str(p) for p in Path("examples/safety").glob("*_on"))
    off = sorted(str(p) for p in Path("examples/safety").glob("*_off"))
    code, out = run_example("safety_table.py", "--on", *on, "--off", *off)
    assert code in (None, 0)
    table, why_table = out.out.split("Why agents touched")
    rows = [r.split("|") for r in table.splitlines() if r.startswith("| 100 | ")]
    (layer,), (bare,) = [[r for r in rows if r[2].strip() == name] for name in ("on", "off")]
    assert layer[7].strip() == "100.0%" and float(bare[6]) > 0  # safety rate with it, contacts without
    why = [r.split("|") for r in why_table.splitlines() if r.startswith("| 100 | off |")]
    assert len(why) == 1 and sum(int(x) for x in why[0][5:10]) > 0  # the seed-101 runs recorded the reasons
    code, out = run_example("safety_table.py", "--on", "no/such/folder", "--off", *off)
    assert "no/such/folder/runs.csv" in str(code)
