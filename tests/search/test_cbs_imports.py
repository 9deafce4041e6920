"""The MAPF solver lives in ``agents.search.mapf``; the old module paths still give the same objects."""
import importlib

import pytest

import agents.search as search
import agents.search.mapf as mapf

# old module -> names it must still provide, and the new module that defines each
OLD_PATHS = {
    "agents.search.cbs": {
        "solve_cbs": "solver", "CBSSolver": "solver", "CBSResult": "result", "CBSStats": "result",
        "CTNode": "ctnode", "MapfInstance": "instance", "Proximity": "instance", "integer_durations": "instance",
        "STATUSES": "result", "DEFAULT_MEMORY_LIMIT_MB": "solver", "HEURISTICS": "solver",
    },
    "agents.search.cbs_lowlevel": {
        "AgentPath": "paths", "Reservation": "paths", "satisfies": "paths", "Counter": "lowlevel",
        "SearchTimeout": "lowlevel", "space_time_astar": "lowlevel", "focal_search": "lowlevel",
        "earliest_arrival": "lowlevel", "MDD": "mdd", "build_mdd": "mdd", "prune_mdd": "mdd",
        "mdds_dependent": "mdd", "pair_conflicts": "conflicts", "make_expander": "successors",
    },
    "agents.search.constraints": {
        "VertexConstraint": "constraints", "EdgeConstraint": "constraints", "RangeConstraint": "constraints",
        "LengthConstraint": "constraints", "ConstraintSet": "constraints", "EMPTY": "constraints",
        "FOREVER": "constraints", "compile_constraints": "constraints", "Conflict": "conflicts",
        "VERTEX": "conflicts", "EDGE": "conflicts", "TARGET": "conflicts", "PROXIMITY": "conflicts",
        "CARDINAL": "conflicts",
    },
    "agents.search.symmetry": {"Corridors": "symmetry", "GridGeometry": "symmetry"},
    "agents.search.validate": {"validate": "validate"},
    "agents.search.mapf_instance": {
        "MapfInstance": "instance", "Proximity": "instance", "UNREACHABLE": "instance", "TIME_MODELS": "instance",
        "integer_durations": "instance", "as_proximity": "instance",
    },
    "agents.search.mapf_grid": {
        "load_map": "movingai", "load_scen": "movingai", "load_instance": "movingai", "grid_graph": "movingai",
        "GridMap": "movingai", "GridInstance": "movingai", "ScenAgent": "movingai",
    },
}


@pytest.mark.parametrize("old", sorted(OLD_PATHS))
def test_old_module_paths_reexport_the_same_objects(old):
    module = importlib.import_module(old)
    for name, new in OLD_PATHS[old].items():
        defined = getattr(importlib.import_module(f"agents.search.mapf.{new}"), name)
        assert getattr(module, name) is defined, f"{old}.{name}"


def test_package_exports_the_public_api():
    for name in mapf.__all__:
        assert hasattr(mapf, name), name
    for name in ("solve_cbs", "CBSSolver", "CBSResult", "validate", "MapfInstance", "Proximity",
                 "integer_durations"):
        assert getattr(search, name) is getattr(mapf, name)


def test_the_solver_does_not_import_torch():
    import subprocess
    import sys

    code = "import sys, agents.search.mapf, agents.search; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
