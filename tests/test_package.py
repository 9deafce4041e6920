"""Package metadata: one version everywhere, PEP 561 markers shipped."""
from importlib import metadata
from pathlib import Path

import pytest

import agents
import baselines
import safe_mapf_envs

tomllib = pytest.importorskip("tomllib")  # Python 3.11+
ROOT = Path(__file__).resolve().parents[1]


def test_one_version_everywhere():
    v = metadata.version("safe-mapf")
    assert safe_mapf_envs.__version__ == agents.__version__ == baselines.__version__ == v
    assert v == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_the_packages_are_marked_typed_and_ship_the_marker():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    for pkg in (safe_mapf_envs, agents, baselines):
        name = pkg.__name__
        assert (Path(pkg.__file__).parent / "py.typed").is_file()
        assert "py.typed" in data[name]
