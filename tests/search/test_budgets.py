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
    pp_cut = solve_prioritized(pp_inst, expansion_limit=pp.stats.ll_expanded // 2)
    ecbs = CBSSolver(ecbs_inst, suboptimality=1.05, time_limit=60).solve()
    ecbs_cut = CBSSolver(ecbs_inst, suboptimality=1.05, time_limit=60,
                         expansion_limit=ecbs.stats.ll_expanded // 2).solve()
    return [(pp_inst, r) for r in (pp, pp_cut)] + [(ecbs_inst, r) for r in (ecbs, ecbs_cut)]


def _fingerprint(res):
    return res.status, res.paths, res.soc, res.stats.ll_expanded, res.stats.hl_expanded


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
