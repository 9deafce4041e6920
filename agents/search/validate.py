"""Old import path of the solution checker, kept for one release: use
:func:`agents.search.mapf.validate`, which this module re-exports.
"""
from .mapf.validate import validate  # noqa: F401

__all__ = ["validate"]
