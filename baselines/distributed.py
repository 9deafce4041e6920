"""Running evaluation runs on Ray: a local Ray on this machine's cores, or a cluster.

Ray is an optional dependency (``pip install "safe-mapf[ray]"``). The driver builds the
evaluation setup once (graph nodes, the critics' matrices) and puts it into Ray's object store
once; each worker (one Ray actor per CPU) rebuilds the planner from it and loads the models
from their saved bytes, then runs single (method, problem) executions. The problems are drawn
by the driver, every run is seeded as in the serial evaluation, and the rows come back in the
serial order, so a Ray evaluation gives the serial rows (timing fields aside).
"""
from __future__ import annotations

import io
import os
from typing import Any, Dict, Iterable, Optional, Sequence, Tuple

RAY_HINT = 'Ray is not installed: pip install "safe-mapf[ray]" (or pip install ray)'


def require_ray() -> Any:
    """The ``ray`` module, or an ``ImportError`` that says how to install it."""
    from .cli import MissingExtraError

    try:
        import ray
    except ImportError:
        raise MissingExtraError(RAY_HINT) from None
    return ray


def init_ray(address: Optional[str] = None, num_cpus: Optional[int] = None) -> Any:
    """Start (or join) Ray unless it is running: ``address`` ``None`` or ``"local"`` starts a local
    Ray with ``num_cpus`` (default: this machine's cores), ``"auto"`` joins the cluster this machine
    belongs to (``ray start --head`` / ``ray start --address=...``), anything else is a cluster
    address (``ray://host:10001`` or ``host:6379``)."""
    ray = require_ray()
    if not ray.is_initialized():
        kwargs: Dict[str, Any] = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        if address in (None, "local"):
            ray.init(num_cpus=num_cpus or os.cpu_count() or 1, **kwargs)
        else:
            ray.init(address=address, **kwargs)
    return ray


def _pack_model(model: Any) -> Tuple[str, Any]:
    """An SB3 model as the bytes of its zip (loaded once per worker), anything else as itself."""
    if hasattr(model, "save") and hasattr(type(model), "load"):
        buf = io.BytesIO()
        model.save(buf)
        return "sb3", (type(model), buf.getvalue())
    return "object", model


def _unpack_model(packed: Tuple[str, Any]) -> Any:
    kind, value = packed
    if kind == "sb3":
        cls, data = value
        return cls.load(io.BytesIO(data), device="cpu")
    return value


def setup_payload(setup: Any) -> Dict[str, Any]:
    """What a worker needs to rebuild ``setup`` (an :class:`~baselines.evaluation.EvaluationSetup`)."""
    return dict(env_id=setup.env_id, models={k: _pack_model(m) for k, m in setup.models.items()},
                states=setup.states, observations=setup.observations, D=setup.D, C=setup.C,
                options=dict(d_max=setup.d_max, proximity_radius=setup.proximity_radius,
                             suboptimality=setup.suboptimality, cbs_time_limit=setup.cbs_time_limit,
                             min_separation=setup.min_separation, max_edges=setup.max_edges))


class EvaluationWorker:
    """One worker: the setup rebuilt from its payload, and one env per agent count."""

    def __init__(self, payload: Dict[str, Any], max_cycles: int, threads: int = 1) -> None:
        import torch

        from baselines.evaluation import EvaluationSetup

        torch.set_num_threads(threads)
        models = {k: _unpack_model(v) for k, v in payload["models"].items()}
        self.setup = EvaluationSetup(payload["env_id"], models, payload["states"], payload["observations"],
                                     payload["D"], payload["C"], **payload["options"])
        self.max_cycles = max_cycles
        self.envs: Dict[int, Any] = {}

    def run(self, task: Tuple[int, Any, Any, int, Any]) -> Tuple[int, Dict[str, Any], Any]:
        """Run one task ``(index, method, problem, base seed, edge memory or None)``; returns ``(index, row,
        execution)``."""
        import safe_mapf_envs
        from baselines.evaluation import run_row

        index, method, problem, seed, memory = task
        k = problem.n_agents
        if k not in self.envs:
            self.envs[k] = safe_mapf_envs.parallel_env(self.setup.env_id, n_agents=k, max_cycles=self.max_cycles)
        row, ex = run_row(self.setup, self.envs[k], method, problem, seed, memory=memory)
        return index, row, ex


def run_on_ray(setup: Any, tasks: Sequence[Tuple[Any, Any]], seed: int, max_cycles: int,
               address: Optional[str] = None,
               memories: Optional[Dict[str, Any]] = None) -> Iterable[Tuple[int, Dict[str, Any], Any]]:
    """Run ``tasks`` (``(method, problem)`` pairs) on Ray workers; yields ``(index, row, execution)``
    as results arrive (``index``: the task's position). ``memories``: frozen edge memories by method
    name, each run's starting point."""
    ray = init_ray(address)
    payload = ray.put(setup_payload(setup))
    n_workers = max(1, min(len(tasks), int(ray.available_resources().get("CPU", 1))))
    Worker = ray.remote(num_cpus=1)(EvaluationWorker)
    workers = [Worker.remote(payload, max_cycles) for _ in range(n_workers)]
    pool = ray.util.ActorPool(workers)
    items = [(i, m, p, seed, (memories or {}).get(m.name)) for i, (m, p) in enumerate(tasks)]
    # the longest runs first (many agents, far goals, a search to plan), so none is left to run alone at the end
    depth = {"hard": 0, "medium": 1, "easy": 2}
    items.sort(key=lambda t: (-t[2].n_agents, depth.get(t[2].difficulty, 3), not t[1].search, t[0]))
    try:
        yield from pool.map_unordered(lambda w, t: w.run.remote(t), items)
    finally:
        for w in workers:
            ray.kill(w)


__all__ = ["EvaluationWorker", "RAY_HINT", "init_ray", "require_ray", "run_on_ray", "setup_payload"]
