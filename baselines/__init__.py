"""Compared methods, the evaluation harness, tables, figures and the ``safe-mapf`` command line."""
from typing import Any


def __getattr__(name: str) -> Any:
    # ``__version__`` lazily, so that ``safe-mapf --help`` does not import the environments
    if name == "__version__":
        from safe_mapf_envs import __version__

        return __version__
    raise AttributeError(f"module 'baselines' has no attribute {name!r}")
