"""The one loop of every evaluation: tasks run serially or on Ray, with progress, in the order of the rows.

Both protocols (:func:`baselines.evaluation.evaluate`, the strict one, and
:func:`baselines.paper_protocol.evaluate_paper`, the paper's conventions) make a list of
``(method, problem)`` tasks and hand it here with the function that runs one task on an env
(``run(setup, env, method, problem, seed, memory=...) -> (row, execution)``). The harness skips
the tasks an interrupted evaluation already ran (their ``kept`` rows open the result), keeps one
parallel env per cell (agent count and difficulty) when it runs serially, sends the tasks to Ray
workers otherwise (:mod:`baselines.distributed`; the same rows in the same order), draws the
progress bar and hands every new row on as it comes (``on_run``).
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from .distributed import RunFn


def run_tasks(
    setup: Any,
    tasks: Sequence[Tuple[Any, Any]],
    run: RunFn,
    *,
    seed: int,
    max_cycles: int,
    kept: Sequence[Dict[str, Any]] = (),
    memories: Optional[Dict[str, Any]] = None,
    env_kwargs: Optional[Dict[str, Any]] = None,
    on_run: Optional[Callable[[Dict[str, Any], Any, Any], None]] = None,
    progress: bool = True,
    desc: str = "evaluate",
    ray: Optional[str] = None,
) -> List[Dict[str, Any]]:
    """Run ``tasks`` (``(method, problem)`` pairs, in the order of the rows) with ``run``.

    Args:
        setup: what every run shares (the graph, the models), handed to ``run``.
        tasks: every task of the evaluation, the ones ``kept`` rows already ran first.
        run: runs one task on a parallel env (seeded with ``seed + problem.index``, wherever it runs).
        seed, max_cycles: the evaluation's seed and the envs' step limit.
        kept: rows of an interrupted evaluation with the same tasks (checked by the caller); their
            tasks are not run again, and they open the returned rows (``on_run`` sees new runs only).
        memories: per method name, the frozen edge memory every run of that method starts from.
        env_kwargs: more arguments of the parallel envs (e.g. ``agent_collisions=False``).
        on_run: ``on_run(row, problem, execution)`` after each new run, in the order of the rows.
        progress: draw a progress bar (tqdm) over all tasks.
        desc: the progress bar's label.
        ray: run the tasks as Ray tasks: ``"local"``, ``"auto"`` or a cluster address (``None``: serially).
    """
    import safe_mapf_envs

    todo = list(tasks[len(kept):])
    memories = memories or {}
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(todo) + len(kept), initial=len(kept), desc=desc, unit="run", mininterval=2.0)
    rows: List[Dict[str, Any]] = list(kept)

    def done(row: Dict[str, Any], problem: Any, ex: Any) -> None:
        rows.append(row)
        if on_run is not None:
            on_run(row, problem, ex)

    env, cell = None, None
    try:
        if ray is not None:
            from .distributed import in_task_order, require_ray, run_on_ray

            require_ray()

            results = run_on_ray(setup, todo, seed, max_cycles, run, address=ray, memories=memories,
                                 env_kwargs=env_kwargs)
            for j, row, ex in in_task_order(results, on_arrival=bar.update if bar is not None else None):
                done(row, todo[j][1], ex)
            return rows
        for method, problem in todo:
            if env is None or cell != (problem.n_agents, problem.difficulty):  # one env per cell
                if env is not None:
                    env.close()
                env = safe_mapf_envs.parallel_env(setup.env_id, n_agents=problem.n_agents, max_cycles=max_cycles,
                                                  **(env_kwargs or {}))
                cell = (problem.n_agents, problem.difficulty)
            row, ex = run(setup, env, method, problem, seed, memory=memories.get(method.name))
            done(row, problem, ex)
            if bar is not None:
                bar.update(1)
                bar.set_postfix_str(f"{method.name} N={problem.n_agents} {problem.difficulty}")
    finally:
        if env is not None:
            env.close()
        if bar is not None:
            bar.close()
    return rows


__all__ = ["run_tasks"]
