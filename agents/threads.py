"""How many CPU threads the critics use when they answer queries (distances, costs, matrices).

The critics are small networks evaluated on large batches of pairs. With several threads,
torch splits every matrix product across them and waits for the slowest; on a machine where
other work holds some of the cores (a training run, other users), that wait dominates: on a
two-core machine busy with other work, the 1,000 x 1,000 matrices of a planner took 67-129 s
with torch's default two threads and 8 s with one. One thread never waits for another, so it
is the default.

The rule, first match wins (:func:`inference_threads`):

1. the ``threads=`` argument of ``SafeGoalTD3.distance``, ``cost``, ``pairwise_distance``,
   ``pairwise_cost`` and ``pairwise``;
2. the environment variable ``SAFE_MAPF_INFERENCE_THREADS`` (a positive integer);
3. torch's own setting, where the user chose it: after ``torch.set_num_threads(n)`` (seen as a
   count different from torch's start-up default), or with ``OMP_NUM_THREADS`` or
   ``MKL_NUM_THREADS`` set;
4. otherwise one thread.

The count applies for the duration of one call (:func:`torch_threads`); torch's setting is
restored afterwards, so training and user code are unaffected.
"""
from __future__ import annotations

import contextlib
import functools
import os
import sys
from typing import Iterator, Optional, Set, Tuple

import torch

#: environment variable that sets the inference thread count (rule 2)
ENV_VAR = "SAFE_MAPF_INFERENCE_THREADS"

#: the default when nobody chose a count (rule 4)
DEFAULT_THREADS = 1

# torch's start-up count, exact when torch was first imported by this package (nobody could
# have changed it yet); otherwise estimated as torch computes it, one thread per physical core
_agents = sys.modules.get("agents")
_STARTUP_THREADS: Optional[int] = (torch.get_num_threads()
                                   if _agents is not None and not getattr(_agents, "_TORCH_PRELOADED", True)
                                   else None)


@functools.lru_cache(maxsize=1)
def _physical_cores() -> int:
    """Physical cores this process may run on (torch's default thread count), else logical CPUs."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1
    cores: Set[Tuple[str, str]] = set()
    for c in cpus:
        base = f"/sys/devices/system/cpu/cpu{c}/topology/"
        try:
            with open(base + "physical_package_id") as f1, open(base + "core_id") as f2:
                cores.add((f1.read().strip(), f2.read().strip()))
        except OSError:
            return len(cpus) or 1
    return len(cores) or 1


def torch_default_threads() -> int:
    """torch's intra-op thread count before anybody changed it (measured or estimated)."""
    return _STARTUP_THREADS if _STARTUP_THREADS is not None else _physical_cores()


def _positive_int(value: object, what: str) -> int:
    try:
        n = int(value)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a positive integer, got {value!r}") from None
    if n < 1 or isinstance(value, bool) or (isinstance(value, float) and n != value):
        raise ValueError(f"{what} must be a positive integer, got {value!r}")
    return n


def inference_threads(threads: Optional[int] = None) -> Optional[int]:
    """The thread count of one critic query by the rule of this module's docstring.

    ``None`` means "leave torch's setting as it is" (the user chose it, rule 3).
    """
    if threads is not None:
        return _positive_int(threads, "threads")
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return _positive_int(env, ENV_VAR)
    if os.environ.get("OMP_NUM_THREADS") or os.environ.get("MKL_NUM_THREADS"):
        return None
    if torch.get_num_threads() != torch_default_threads():
        return None
    return DEFAULT_THREADS


@contextlib.contextmanager
def torch_threads(threads: Optional[int]) -> Iterator[None]:
    """Run the block with ``threads`` intra-op threads (``None``: unchanged); restore afterwards."""
    before = torch.get_num_threads()
    if threads is None or threads == before:
        yield
        return
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


__all__ = ["DEFAULT_THREADS", "ENV_VAR", "inference_threads", "torch_default_threads", "torch_threads"]
