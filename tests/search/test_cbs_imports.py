"""The MAPF solver lives in ``agents.search.mapf``; ``agents.search`` exports its public names."""
import agents.search as search
import agents.search.mapf as mapf


def test_package_exports_the_public_api():
    for name in mapf.__all__:
        assert hasattr(mapf, name), name
    for name in ("solve_cbs", "CBSSolver", "CBSResult", "MapfResult", "SolverConfig", "validate", "MapfInstance",
                 "Proximity", "integer_durations"):
        assert getattr(search, name) is getattr(mapf, name)


def test_the_solver_does_not_import_torch():
    import subprocess
    import sys

    code = "import sys, agents.search.mapf, agents.search; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
