"""Old import path of corridor and rectangle reasoning, kept for one release: use
:mod:`agents.search.mapf.symmetry`, which this module re-exports.
"""
from .mapf.conflicts import Branches  # noqa: F401
from .mapf.symmetry import Corridors, GridGeometry  # noqa: F401
