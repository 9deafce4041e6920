"""Running evaluation runs on Ray: a local Ray on this machine's cores, or a cluster.

Ray is an optional dependency (``pip install "safe-mapf[ray]"``). The driver builds the
evaluation setup once (graph nodes, the critics' matrices) and puts it into Ray's object store
once; each worker (one Ray actor per CPU) rebuilds the planner from it and loads the models
from their saved bytes, then runs single (method, problem) executions. The problems are drawn
by the driver, every run is seeded as in the serial evaluation, and the rows come back in the
serial order, so a Ray evaluation gives the serial rows (timing fields aside).

This module is the evaluation's back end and knows nothing of it: :mod:`baselines.evaluation`
hands it the setup (a dataclass rebuilt on each worker from its fields) and the function that
runs one (method, problem) pair, so imports go one way, from the evaluation down to here.
"""
from __future__ import annotations

import dataclasses
import io
import os
from typing import Any, Callable, Dict, Iterable, Optional, Sequence, Tuple

RAY_HINT = 'Ray is not installed: pip install "safe-mapf[ray]" (or pip install ray)'

#: ``run(setup, env, method, problem, seed, memory=...) -> (row, execution)``: one evaluation run
RunFn = Callable[..., Tuple[Dict[str, Any], Any]]


class MissingExtraError(ImportError):
    """An optional dependency a flag needs (e.g. Ray for ``--ray``) is not installed."""


def require_ray() -> Any:
    """The ``ray`` module, or an ``ImportError`` that says how to install it."""
    try:
        import ray
    except ImportError:
        raise MissingExtraError(RAY_HINT) from None
    return ray


def init_ray(address: Optional[str] = None, num_cpus: Optional[int] = None) -> Any:
    """Start (or join) Ray unless it is running: ``address`` ``None`` or ``"local"`` starts a local
    Ray with ``num_cpus`` (default: this machine's cores) whose workers run at the caller's
    niceness (Ray's own default is 15), ``"auto"`` joins the cluster this machine
    belongs to (``ray start --head`` / ``ray start --address=...``), anything else is a cluster
    address (``ray://host:10001`` or ``host:6379``)."""
    ray = require_ray()
    if not ray.is_initialized():
        kwargs: Dict[str, Any] = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        if address in (None, "local"):
            # Ray starts its workers at niceness 15, so on a machine running anything else they get
            # what is left (measured: a quarter of a core each beside two other jobs on 2 cores);
            # a local evaluation is the user's own foreground job: its workers run as the driver
            # does, unless RAY_worker_niceness says otherwise. Ray adds it to the niceness the
            # workers inherit from the driver, so 0 keeps the driver's (its own niceness would
            # count it twice: a driver at 10 had workers at 19)
            key = "RAY_worker_niceness"
            preset = key in os.environ
            if not preset:
                os.environ[key] = "0"
            try:
                ray.init(num_cpus=num_cpus or os.cpu_count() or 1, **kwargs)
            finally:
                if not preset:
                    os.environ.pop(key, None)
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
    """What a worker needs to rebuild ``setup`` (a dataclass such as
    :class:`~baselines.evaluation.EvaluationSetup` whose ``models`` field holds SB3 models): its
    class and its ``__init__`` fields, the models as the bytes of their zips."""
    fields = {f.name: getattr(setup, f.name) for f in dataclasses.fields(setup) if f.init}
    fields["models"] = {k: _pack_model(m) for k, m in fields["models"].items()}
    from safe_mapf_envs.registration import map_specs

    return dict(cls=type(setup), fields=fields, map_specs=map_specs())


class EvaluationWorker:
    """One worker: the setup rebuilt from its payload, the function that runs one task, and one
    env per agent count."""

    def __init__(self, payload: Dict[str, Any], run: RunFn, max_cycles: int, threads: int = 1,
                 env_kwargs: Optional[Dict[str, Any]] = None) -> None:
        import torch

        from safe_mapf_envs.registration import register_spec

        torch.set_num_threads(threads)
        for spec in payload.get("map_specs", ()):  # maps of one's own the driver registered
            register_spec(spec)
        fields = dict(payload["fields"])
        fields["models"] = {k: _unpack_model(v) for k, v in fields["models"].items()}
        self.setup = payload["cls"](**fields)
        self.run_fn = run
        self.max_cycles = max_cycles
        self.env_kwargs = dict(env_kwargs or {})
        self.envs: Dict[int, Any] = {}

    def run(self, task: Tuple[int, Any, Any, int, Any]) -> Tuple[int, Dict[str, Any], Any]:
        """Run one task ``(index, method, problem, base seed, edge memory or None)``; returns ``(index, row,
        execution)``."""
        import safe_mapf_envs

        index, method, problem, seed, memory = task
        k = problem.n_agents
        if k not in self.envs:
            self.envs[k] = safe_mapf_envs.parallel_env(self.setup.env_id, n_agents=k, max_cycles=self.max_cycles,
                                                       **self.env_kwargs)
        row, ex = self.run_fn(self.setup, self.envs[k], method, problem, seed, memory=memory)
        return index, row, ex


def run_on_ray(setup: Any, tasks: Sequence[Tuple[Any, Any]], seed: int, max_cycles: int, run: RunFn,
               address: Optional[str] = None, memories: Optional[Dict[str, Any]] = None,
               env_kwargs: Optional[Dict[str, Any]] = None) -> Iterable[Tuple[int, Dict[str, Any], Any]]:
    """Run ``tasks`` (``(method, problem)`` pairs) on Ray workers, each with ``run`` (e.g.
    :func:`baselines.evaluation.run_row`); yields ``(index, row, execution)`` as results arrive
    (``index``: the task's position). ``memories``: frozen edge memories by method name, each
    run's starting point; ``env_kwargs``: more arguments of the workers' parallel envs (e.g.
    ``agent_collisions=False``)."""
    ray = init_ray(address)
    payload = ray.put(setup_payload(setup))
    n_workers = max(1, min(len(tasks), int(ray.available_resources().get("CPU", 1))))
    Worker = ray.remote(num_cpus=1)(EvaluationWorker)
    workers = [Worker.remote(payload, run, max_cycles, env_kwargs=env_kwargs) for _ in range(n_workers)]
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


def in_task_order(results: Iterable[Tuple[int, Dict[str, Any], Any]],
                  on_arrival: Optional[Callable[[], None]] = None) -> Iterable[Tuple[int, Dict[str, Any], Any]]:
    """``(index, row, execution)`` results that arrive in any order (:func:`run_on_ray`), handed on in
    the order of their indices 0, 1, 2, ... as soon as each one's predecessors are in;
    ``on_arrival()`` is called as each arrives (e.g. a progress bar's update)."""
    pending: Dict[int, Tuple[Dict[str, Any], Any]] = {}
    nxt = 0
    for i, row, ex in results:
        if on_arrival is not None:
            on_arrival()
        pending[i] = (row, ex)
        while nxt in pending:
            row_n, ex_n = pending.pop(nxt)
            yield nxt, row_n, ex_n
            nxt += 1


__all__ = ["EvaluationWorker", "MissingExtraError", "RAY_HINT", "RunFn", "in_task_order", "init_ray", "require_ray",
           "run_on_ray", "setup_payload"]
