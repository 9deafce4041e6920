"""Spreading routes: the low-level searches prefer paths that enter fewer places of other routes."""
import numpy as np
import pytest

from agents.search.config import GraphConfig, SolverConfig
from agents.search.mapf import EMPTY, CBSSolver, MapfInstance, Proximity, compile_constraints, solve_cbs, validate
from agents.search.mapf.paths import AgentPath, Reservation
from agents.search.mapf.successors import SPREAD_SHIFT, make_successors


def adjacency(n, edges):
    """Adjacency list of undirected edges ``(u, v, duration)``."""
    adj = [[] for _ in range(n)]
    for u, v, d in edges:
        adj[u].append((v, d))
        adj[v].append((u, d))
    return adj


def two_routes(x, y, detour):
    """Agent 0 goes 1 -> 2 and parks; agent 1 goes 3 -> 4 by way of ``x`` (which is node 1, left
    by agent 0 at time 1, so passing it later is no conflict) or of ``y`` (nowhere near agent 0),
    the way by ``y`` ``detour`` steps longer. Nodes 0 and 5 are the ways' middle nodes."""
    return adjacency(8, [(1, 2, 1), (3, 0, 2), (0, x, 1), (x, 4, 1), (3, 5, 2), (5, y, 1), (y, 4, 1 + detour)])


def nodes_of(path):
    return {v for v, _ in path}


@pytest.mark.parametrize("suboptimality", [1.0, 1.5])
def test_equal_routes_spread_only_when_asked(suboptimality):
    # node 1 is the lower id, so without spreading the tie goes its way
    adj = two_routes(1, 6, detour=0)
    plain = solve_cbs(adj, [1, 3], [2, 4], time_model="durative", suboptimality=suboptimality)
    assert 1 in nodes_of(plain.paths[1])
    for mode in ("routes", "near"):
        spread = solve_cbs(adj, [1, 3], [2, 4], time_model="durative", suboptimality=suboptimality, spread=mode)
        assert 1 not in nodes_of(spread.paths[1]) and 6 in nodes_of(spread.paths[1])
        assert spread.soc == plain.soc == 1 + 4
        assert validate(adj, [1, 3], [2, 4], spread.paths, time_model="durative") == []


@pytest.mark.parametrize("suboptimality", [1.0, 1.5])
def test_near_also_avoids_the_neighbours_of_other_routes(suboptimality):
    # node 6 lies near agent 0's start (left at time 1, so no conflict when agent 1 passes at time 3)
    adj = two_routes(6, 7, detour=0)
    dist = np.full((8, 8), 10.0)
    dist[1, 6] = dist[6, 1] = 1.0
    prox = Proximity(dist, 1.5)
    kw = dict(time_model="durative", proximity=prox, suboptimality=suboptimality)
    plain = solve_cbs(adj, [1, 3], [2, 4], **kw)
    routes = solve_cbs(adj, [1, 3], [2, 4], spread="routes", **kw)
    near = solve_cbs(adj, [1, 3], [2, 4], spread="near", **kw)
    assert 6 in nodes_of(plain.paths[1]) and 6 in nodes_of(routes.paths[1])
    assert 6 not in nodes_of(near.paths[1]) and 7 in nodes_of(near.paths[1])
    assert near.soc == routes.soc == plain.soc
    assert validate(adj, [1, 3], [2, 4], near.paths, time_model="durative", proximity=prox) == []


@pytest.mark.parametrize("bad", [True, 1, "nodes", None])
def test_a_spread_mode_that_does_not_exist_is_refused(bad):
    adj = two_routes(1, 6, detour=0)
    with pytest.raises(ValueError, match="spread must be one of 'off', 'routes', 'near'"):
        solve_cbs(adj, [1, 3], [2, 4], time_model="durative", spread=bad)


def test_spreading_never_takes_a_longer_route():
    # by node 6 one step longer: within ECBS's bound, but spreading only breaks ties
    adj = two_routes(1, 6, detour=1)
    for w in (1.0, 1.5):
        res = solve_cbs(adj, [1, 3], [2, 4], time_model="durative", suboptimality=w, spread="near")
        assert 1 in nodes_of(res.paths[1]) and res.soc == 5


def test_places_hold_the_other_routes_and_their_neighbours():
    adj = two_routes(1, 6, detour=0)
    dist = np.full((8, 8), 10.0)
    dist[2, 7] = dist[7, 2] = 1.0  # node 7 lies near agent 0's goal
    inst = MapfInstance(adj, [1, 3], [2, 4], time_model="durative", proximity=Proximity(dist, 1.5))
    other = AgentPath([(1, 0), (2, 1)], inst)
    assert Reservation([other, None], 1, inst, spread="near").places == {1, 2, 7}
    assert Reservation([other, None], 1, inst, spread="routes").places == {1, 2}
    assert Reservation([other, None], 1, inst).places == set()
    assert Reservation([other, None], 0, inst, spread="near").places == set()  # its own path is no other's
    unit = MapfInstance(adj, [1, 3], [2, 4], time_model="unit")
    assert Reservation([AgentPath([(1, 0), (2, 1)], unit), None], 1, unit, spread="near").places == set()
    assert CBSSolver(inst, spread="routes").spread == "routes" and CBSSolver(inst).spread == "off"


def moves(inst, cc, res):
    """``(v, t) -> [(w, arrival, conflicts), ...]``: the successors of a search with no state
    closed and no heuristic."""
    N = inst.n_nodes
    successors = make_successors(inst, cc, res, [0] * N, set(), 1 << 20)
    return lambda v, t: [(code % N, f, conflicts) for code, f, conflicts, _ in successors(t * N + v, v, t, 0)]


def test_a_successor_counts_conflicts_first_and_places_second():
    adj = two_routes(1, 6, detour=0)
    inst = MapfInstance(adj, [1, 3], [2, 4], time_model="durative")
    other = AgentPath([(1, 0), (2, 1)], inst)  # at 1 during step 0, parked at 2 from time 1
    cc = compile_constraints(EMPTY, inst.n_nodes, 4)
    spread = moves(inst, cc, Reservation([other, None], 1, inst, spread="routes"))
    plain = moves(inst, cc, Reservation([other, None], 1, inst))
    # 0 -> 1 during step 0 meets agent 0 at node 1 and enters one of its places
    assert (1, 1, (1 << SPREAD_SHIFT) + 1) in spread(0, 0) and (1, 1, 1) in plain(0, 0)
    # later node 1 is free: a place, no conflict
    assert (1, 3, 1) in spread(0, 2) and (1, 3, 0) in plain(0, 2)
    # away from agent 0's route: nothing
    assert (0, 2, 0) in spread(3, 0) and (0, 2, 0) in plain(3, 0)
    # waiting at a place is no new entry
    assert (1, 3, 0) in spread(1, 2)


def test_planner_passes_spread_routes_to_the_solver(monkeypatch):
    from agents.search.mapf import registry as registry_module
    from agents.search.planner import BufferPlanner

    seen = []
    real = registry_module.CBSSolver

    def recording(*args, **kwargs):
        seen.append(kwargs.get("spread"))
        return real(*args, **kwargs)

    monkeypatch.setattr(registry_module, "CBSSolver", recording)
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 2.0], [1.0, 2.0], [2.0, 2.0]])

    def pairwise(a, b):
        d = np.linalg.norm(np.asarray(a, float)[:, None] - np.asarray(b, float)[None], axis=-1)
        return np.maximum(d, 1.0), np.zeros_like(d)

    D, C = pairwise(pts, pts)
    planner = BufferPlanner(pts, D, C, pairwise, graph=GraphConfig(d_max=1.5), solver=SolverConfig(spread="near"))
    assert planner.solver_config.spread == planner.with_options(c_max=2.0).solver_config.spread == "near"
    assert BufferPlanner(pts, D, C, pairwise, graph=GraphConfig(d_max=1.5)).solver_config.spread == "off"
    plan = planner.plan(pts[[0, 3]], pts[[2, 5]])
    assert plan.solved and seen == ["near"]
    with pytest.raises(ValueError, match="spread must be one of"):
        BufferPlanner(pts, D, C, pairwise, graph=GraphConfig(d_max=1.5), solver=SolverConfig(spread=True))
