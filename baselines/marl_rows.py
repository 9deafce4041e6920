"""The multi-agent RL baselines as rows of the evaluation (``--methods ippo mappo_lag``).

The paper's Table I leaves multi-agent RL without search as "N/A". Here the shipped IPPO and
MAPPO-Lagrangian policies (:mod:`agents.marl`) run the very problems the other methods run, in
both protocols: every agent acts on its own observation and goal at every step, with no plan,
no waypoints and no yield rule (the policy is all there is). Rows and failure reasons are
those of :func:`~baselines.methods.execute`.
"""
from __future__ import annotations

from typing import Any, Dict, Iterable, Mapping, Optional

import numpy as np

#: method name -> trainer (``safe-mapf train-marl --algo``)
MARL_ALGOS = {"ippo": "ippo", "mappo_lag": "mappo-lag"}


def load_marl_models(env_id: str, names: Iterable[str], paths: Optional[Mapping[str, Optional[str]]] = None
                     ) -> Dict[str, Any]:
    """The policies of the MARL methods among ``names``, keyed by method name: the shipped ones of
    ``env_id`` unless ``paths[name]`` gives a checkpoint."""
    from agents.marl import load_marl_pretrained

    paths = paths or {}
    return {n: load_marl_pretrained(env_id, MARL_ALGOS[n], path=paths.get(n)) for n in names if n in MARL_ALGOS}


def execute_marl(env, agent, starts: np.ndarray, goals: np.ndarray, seed: int = 0,
                 count_start_cost: bool = False):
    """Run the MARL policy ``agent`` (a :class:`~agents.marl.MarlAgent`) from ``starts`` to ``goals``
    in the parallel env ``env`` until every agent arrived or ``env.max_cycles``; returns an
    :class:`~baselines.methods.Execution` (``plan_status = "direct"``).

    ``count_start_cost``: add the start state's cost of a lone agent (the paper protocol's convention).
    """
    from .anatomy import FailureTracker
    from .execution import Contacts, Execution, geodesic_of, tally_step

    obs, infos = env.reset(seed=seed, options={"starts": starts, "goals": goals})
    names = list(env.agents)
    k = len(names)
    index = {a: i for i, a in enumerate(names)}
    cost = np.zeros(k)
    if count_start_cost and k == 1:
        cost[0] += float(infos[names[0]].get("obstacle_cost", infos[names[0]]["cost"]))
    reached = np.zeros(k, dtype=bool)
    parked_at = np.full(k, -1)
    contacts = Contacts(index)
    traj = [env.positions]
    step_length = float(getattr(env, "action_scale", 1.0))
    tracker = FailureTracker(names, step_length, touch=2.0 * env.scenario.agent_radius + 0.5 * step_length)
    steps = 0
    while env.agents:
        obs, _, term, _, infos = env.step(agent.act_dict({a: obs[a] for a in env.agents}))
        steps += 1
        traj.append(env.positions)
        tracker.step({}, infos, env.agents)
        contacts.update(tally_step(infos, term, index, cost, reached, parked_at, steps))
    trajectories = np.stack(traj)
    failures = []
    if not reached.all():
        failures = tracker.diagnose(trajectories, np.asarray(goals, dtype=np.float64), reached, parked_at,
                                    geodesic_of(env), planned=False)
    return Execution(bool(reached.all()), reached, cost, steps, contacts.count, 0.0, "direct", trajectories,
                     {"algo": agent.algo}, failures, parked_at, touched=contacts.touched)


__all__ = ["MARL_ALGOS", "execute_marl", "load_marl_models"]
