"""Old import path of the CBS constraints and conflicts, kept for one release.

Use :mod:`agents.search.mapf.constraints` and :mod:`agents.search.mapf.conflicts`; this module
re-exports the names it used to define.
"""
from .mapf.conflicts import (  # noqa: F401
    CARDINAL,
    EDGE,
    KIND_NAMES,
    NON_CARDINAL,
    PROXIMITY,
    SEMI_CARDINAL,
    TARGET,
    VERTEX,
    Conflict,
)
from .mapf.constraints import (  # noqa: F401
    EMPTY,
    FOREVER,
    CompiledConstraints,
    Constraint,
    ConstraintSet,
    EdgeConstraint,
    LengthConstraint,
    RangeConstraint,
    VertexConstraint,
    compile_constraints,
)
