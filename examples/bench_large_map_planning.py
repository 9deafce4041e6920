"""Planning for hundreds to a thousand agents on the buffer graph of a large map: scatter-64-64.

Builds the graph of ``--nodes`` observations (drawn with ``--seed``) on the 64 x 64 MovingAI map
``examples/data/maps/scatter-64-64.map`` (a 192 x 192 world, registered as
``SafeScatter-64-64-v0``) with the shipped unconstrained agent, reading the critics only for the
pairs the environment's distance bound (``min_steps``) puts below ``d_max``
(``BufferPlanner.from_agent(..., bound=env.min_steps)``, every other option the planner's
default). Then, per agent count of ``--agents``, it draws ``--repeats`` hard problems as the
evaluation draws them (:func:`baselines.evaluation.make_problems`: each agent's start and goal are
graph nodes whose shortest distance on the buffer graph is within 20% of half the graph's
largest; starts, and goals, 2.5 world units apart and not within the proximity radius of each
other; problem ``i`` of ``K`` agents is the same whatever else is run) and plans each with
``BufferPlanner.plan`` for every solver of ``--solvers`` (default ``auto``, the planner's
default: prioritised planning with safe intervals above 20 agents).

Per agent count and solver it prints the median planning time over the problems (the whole
``plan`` call: attaching the starts and goals with the critics, pruning, the solver), each time,
the solver's share, the statuses, how many plans pass :func:`agents.search.mapf.validate` (run on
every plan, on the graph, starts, goals and proximity the planner planned with; not timed), and
the median sum of costs and makespan, and the median CPU time of the ``plan`` calls (this
process's time, one thread: about what an idle core takes, on a loaded machine).

Every solver call is budgeted in work (the planner's defaults), so statuses and plans do not
depend on the machine's load; times do, and the load average is printed first. One thread: the
script sets ``OMP_NUM_THREADS=1`` (unless it is set) and one torch thread. Where numba is
installed the solvers' compiled loops are used (the same plans, faster; see
:mod:`agents.search.mapf.compiled`); the script says which, and compiles them before timing.

With ``--replans N`` it first times ``N`` one-agent plans from new places around ``--parked``
parked agents (default 50), as a stuck agent's replan asks them of the planner (the first, which
scores the buffer against every parked agent, is not in the median).

Run: ``OMP_NUM_THREADS=1 python examples/bench_large_map_planning.py [--agents 100 250 500 1000]
[--repeats 5] [--nodes 4000] [--solvers auto] [--seed 0] [--replans 10] [--parked 50]``
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import collections  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import List, Tuple  # noqa: E402

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

MAP = REPO / "examples" / "data" / "maps" / "scatter-64-64.map"
SOLVERS = ("auto", "prioritized", "pibt", "lacam", "lns", "cbs")
#: the evaluation's difficulty "hard": pairs within 20% of the graph's largest distance over 2
HARD, TOLERANCE = 2.0, 0.2


def build(nodes: int, seed: int):
    """The env id, the env, the sampled observations and the planner on them (timed)."""
    import gymnasium as gym
    import torch

    import safe_mapf_envs
    from agents import load_pretrained
    from agents.search.planner import BufferPlanner
    from safe_mapf_envs import GridMap

    torch.set_num_threads(1)
    env_id = safe_mapf_envs.register_map(GridMap.from_file(MAP))
    agent = load_pretrained(env_id, kind="unconstrained")
    env = gym.make(env_id).unwrapped
    states = env.sample_states(nodes, np.random.default_rng(seed))
    obs = np.asarray(env.observations_at(states))
    t = time.perf_counter()
    planner = BufferPlanner.from_agent(agent, obs, bound=env.min_steps)
    print(f"graph of {nodes} nodes on {env_id}: {time.perf_counter() - t:.2f} s "
          f"({planner.buffer_graph.n_edges} edges)", flush=True)
    return env_id, env, states, obs, planner


def draw_problems(states: np.ndarray, D: np.ndarray, shortest: np.ndarray, k: int, n_problems: int, seed: int,
                  min_separation: float, radius: float) -> List[Tuple[np.ndarray, np.ndarray]]:
    """``n_problems`` hard problems of ``k`` agents, node ids ``(starts, goals)``: the draw of
    :func:`baselines.evaluation.make_problems` (the same generator, the same choices, so the same
    problems), with the count of each start's open goals kept up to date instead of recomputed."""
    finite = shortest[np.isfinite(shortest)]
    target = float(finite.max()) / HARD
    ok_pair = (shortest >= (1 - TOLERANCE) * target) & (shortest <= (1 + TOLERANCE) * target)
    ok_int = ok_pair.astype(np.int32)
    near = (D < radius) | (D.T < radius)
    pos = states
    far = (np.linalg.norm(pos[:, None] - pos[None], axis=-1) >= min_separation) & ~near
    n = len(pos)
    rng = np.random.default_rng([seed, k, 2])  # 2: "hard" in the evaluation's list of difficulties
    out = []
    for _ in range(n_problems):
        for _attempt in range(200):
            free_s = np.ones(n, dtype=bool)
            free_g = np.ones(n, dtype=bool)
            open_goals = ok_int.sum(axis=1)  # per node, the free goals it pairs with
            s_ids, g_ids = [], []
            for _ in range(k):
                cand_s = np.flatnonzero(free_s & (open_goals > 0))
                if not len(cand_s):
                    break
                s = int(rng.choice(cand_s))
                g = int(rng.choice(np.flatnonzero(ok_pair[s] & free_g)))
                s_ids.append(s)
                g_ids.append(g)
                free_s &= far[s]
                gone = free_g & ~far[g]
                free_g &= far[g]
                open_goals -= ok_int[:, gone].sum(axis=1)
            if len(s_ids) == k:
                break
        else:
            raise ValueError(f"could not place {k} agents for a hard problem on {n} nodes")
        out.append((np.array(s_ids), np.array(g_ids)))
    return out


def check(planner, plan) -> bool:
    """Whether ``plan`` passes :func:`~agents.search.mapf.validate` on the graph, starts, goals and
    proximity the planner planned it with."""
    from agents.search.mapf import validate

    problem = plan.problem
    durations = problem.graph.distance.copy()
    durations.data = np.maximum(np.ceil(durations.data - 1e-9), 1.0)
    # the proximity the planner plans with (starts among themselves, goals among themselves exempt)
    prox = planner.problem_proximity(problem.D, problem.n_agents)
    return not validate(durations, list(problem.start_ids), list(problem.goal_ids), plan.cbs.paths,
                        time_model=planner.graph.time_model, proximity=prox)


def warm_up() -> None:
    """Compile the solvers' compiled loops (where numba is installed) before anything is timed."""
    from agents.search.mapf import MapfInstance, solve_prioritized

    line = [[1], [0, 2], [1]]
    solve_prioritized(MapfInstance(line, [0], [2], time_model="durative"))


def time_replans(planner, obs: np.ndarray, n: int, seed: int, n_parked: int = 50) -> None:
    """Time ``n`` one-agent plans from new places to one goal around ``n_parked`` parked agents and 3 banned
    nodes (what a stuck agent's replan asks the planner), after one untimed plan that scores the buffer against
    the parked agents (the planner keeps those distances, as over an episode)."""
    rng = np.random.default_rng([seed, 1])
    idx = rng.choice(len(obs), n_parked + 6 + n, replace=False)
    goal, parked = obs[idx[0]], obs[idx[1:n_parked + 1]]
    banned = [int(i) for i in idx[n_parked + 1:n_parked + 4]]
    starts = idx[n_parked + 5:]
    planner.plan(obs[idx[n_parked + 4]][None], goal[None], exclude=banned, avoid=parked)
    wall, cpu = [], []
    for k in range(n):
        t, c = time.perf_counter(), time.process_time()
        planner.plan(obs[starts[k]][None], goal[None], exclude=banned, avoid=parked)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    print(f"one-agent replans around {n_parked} parked agents: median {np.median(wall):.3f} s "
          f"(CPU {np.median(cpu):.3f} s) over {n}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[100, 250, 500, 1000])
    ap.add_argument("--repeats", type=int, default=5, help="problems per agent count (median over them)")
    ap.add_argument("--nodes", type=int, default=4000)
    ap.add_argument("--solvers", nargs="+", default=["auto"], choices=SOLVERS)
    ap.add_argument("--seed", type=int, default=0, help="seeds the graph's nodes and the problems")
    ap.add_argument("--replans", type=int, default=0, metavar="N",
                    help="also time N one-agent plans from new places to one goal with 50 agents parked, as a stuck "
                         "agent's replan makes them (median; default 0: none)")
    ap.add_argument("--parked", type=int, default=50, help="parked agents the --replans plans keep clear of")
    ap.add_argument("--time-limit", type=float, default=600.0,
                    help="seconds per solver call: a safety net behind the planner's budgets in work")
    args = ap.parse_args()

    from scipy.sparse.csgraph import dijkstra

    from agents.search.mapf import compiled
    from baselines.evaluation import default_min_separation

    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; OMP_NUM_THREADS="
          f"{os.environ.get('OMP_NUM_THREADS')}; compiled loops: {'on' if compiled.active() else 'off'}", flush=True)
    warm_up()
    env_id, env, states, obs, planner = build(args.nodes, args.seed)
    shortest = dijkstra(planner.buffer_graph.distance, directed=True)
    min_sep = default_min_separation(env_id)
    if args.replans:
        time_replans(planner, obs, args.replans, args.seed, args.parked)
    for k in args.agents:
        problems = draw_problems(states, planner.D, shortest, k, args.repeats, args.seed, min_sep,
                                 planner.graph.proximity_radius or 0.0)
        for name in args.solvers:
            pl = planner.with_options(solver=name, time_limit=args.time_limit)
            times, cpu, solver_times, socs, spans, valid = [], [], [], [], [], 0
            status: collections.Counter = collections.Counter()
            for s_ids, g_ids in problems:
                c0 = time.process_time()
                plan = pl.plan(obs[s_ids], obs[g_ids])
                cpu.append(time.process_time() - c0)
                times.append(plan.planning_time)
                solver_times.append(plan.cbs.runtime_s if plan.cbs is not None else np.nan)
                status[f"{plan.status} ({plan.solver})"] += 1
                if plan.solved:
                    socs.append(plan.soc)
                    spans.append(plan.makespan)
                    valid += check(pl, plan)
            each = ", ".join(f"{t:.2f}" for t in times)
            cost = (f"SoC median {np.median(socs):.0f}, makespan median {np.median(spans):.0f}" if socs else "no plan")
            print(f"{k} agents, {name}: median {np.median(times):.2f} s ({each}; solver median "
                  f"{np.nanmedian(solver_times):.2f} s; CPU median {np.median(cpu):.2f} s), {dict(status)}, "
                  f"valid {valid} of {len(socs)} plans, {cost}; load {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
