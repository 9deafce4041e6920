"""Work budgets: the same plan, and the same verdict at the budget, on an idle and a loaded machine."""
import multiprocessing as mp
import time

import numpy as np
import pytest
from cbs_bruteforce import random_grid
from test_cbs_bruteforce import adjacency, pick

from agents.search.mapf import CBSSolver, MapfInstance, validate
from agents.search.mapf.prioritized import solve_prioritized


def _burn(seconds):
    end = time.perf_counter() + seconds
    x = 0
    while time.perf_counter() < end:
        x += 1


@pytest.fixture
def cpu_load():
    """Two busy processes for the duration of the test (the machine's cores kept busy)."""
    ctx = mp.get_context("spawn")
    burners = [ctx.Process(target=_burn, args=(30.0,)) for _ in range(2)]
    for b in burners:
        b.start()
    time.sleep(0.5)
    yield
    for b in burners:
        b.terminate()
        b.join()


def _grid_instance(seed, k, size=16):
    rng = np.random.default_rng(seed)
    n, edges, _ = random_grid(rng, size, size, 0.0)
    starts, goals = pick(rng, n, k)
    return MapfInstance(adjacency(n, edges), starts, goals, time_model="unit")


def _runs():
    """Prioritised planning and ECBS, each solved and each stopped by its expansion budget."""
    pp_inst = _grid_instance(11, 60)
    ecbs_inst = _grid_instance(1, 20, size=10)
    pp = solve_prioritized(pp_inst)
    pp_cut = solve_prioritized(pp_inst, expansion_limit=pp.work // 2)
    ecbs = CBSSolver(ecbs_inst, suboptimality=1.05, time_limit=60).solve()
    ecbs_cut = CBSSolver(ecbs_inst, suboptimality=1.05, time_limit=60,
                         expansion_limit=ecbs.work // 2).solve()
    return [(pp_inst, r) for r in (pp, pp_cut)] + [(ecbs_inst, r) for r in (ecbs, ecbs_cut)]


def _fingerprint(res):
    return res.status, res.paths, res.soc, res.work, res.stats


def test_plans_are_the_same_under_cpu_load(request):
    idle = _runs()
    request.getfixturevalue("cpu_load")
    loaded = _runs()
    for (inst, a), (_, b) in zip(idle, loaded):
        assert _fingerprint(a) == _fingerprint(b)
        if a.solved:
            assert validate(inst, None, None, a.paths) == []
    statuses = [r.status for _, r in idle]
    assert statuses[0] == "suboptimal" or statuses[0] == "optimal"
    assert statuses[1] == statuses[3] == "timeout"
    assert "expansion limit" in idle[1][1].message and "expansion limit" in idle[3][1].message
    assert idle[2][1].solved


def test_expansion_limit_is_checked():
    inst = _grid_instance(1, 3, size=5)
    with pytest.raises(ValueError, match="expansion_limit"):
        CBSSolver(inst, expansion_limit=-1)
    res = CBSSolver(inst, expansion_limit=None).solve()
    assert res.status == "optimal"


def test_no_clock_decides_a_plan_of_the_planner(monkeypatch):
    """With the planner's defaults nothing reads the clock to decide: a clock that jumps an hour at every
    read (a machine as loaded as can be) gives the same plans, also where a budget stops a solver."""
    from scipy import sparse
    from test_planner import _crossing_problem, euclid_pairwise, make_planner

    pts = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0)), axis=-1).reshape(-1, 2)
    planner = make_planner(pts, euclid_pairwise(), d_max=1.6, proximity_radius=0.9)
    assert planner.solver_config.time_limit is None
    starts, goals = _crossing_problem(12)
    tight = planner.with_options(expansion_limit=300, solver="cbs", fallback_suboptimality=None)

    def plans():
        return [(p.status, p.soc, p.cbs.paths if p.cbs is not None else None, p.message)
                for p in (planner.plan(starts, goals), tight.plan(starts, goals))]

    calm = plans()
    assert calm[1][0] == "timeout" and "expansion limit" in calm[1][3]
    clock = [0.0]

    def hasty() -> float:
        clock[0] += 3600.0
        return clock[0]

    monkeypatch.setattr(time, "perf_counter", hasty)
    assert plans() == calm
    # the expansion budget shrinks on graphs denser than REFERENCE_EDGE_STEPS edge-steps per node
    from agents.search.planner import REFERENCE_EDGE_STEPS

    sparse_graph = sparse.csr_matrix(np.ones((10, 10)) * 3.0)  # 30 edge-steps per node
    dense = sparse.csr_matrix(np.ones((10, 10)) * (6.0 * REFERENCE_EDGE_STEPS / 10))  # 6 x the reference
    assert planner.work_scale(sparse_graph) == 1.0 and planner.work_scale(dense) == 1 / 6
    monkeypatch.undo()
    import agents.search.planner as planner_module

    monkeypatch.setattr(planner_module, "REFERENCE_EDGE_STEPS", 1e-9)  # every graph is "dense": budgets shrink
    scaled = tight.plan(starts, goals)
    assert scaled.status == "timeout" and "expansion limit of 1 low-level" in scaled.message
