"""Plan waypoints for 5 agents with CBS on the replay-buffer graph, then execute them.

The pipeline of "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe Reinforcement
Learning" with the shipped checkpoints of ``SafeCentralObstacle-v0``: graph nodes -> the
critic's distance/cost matrices -> cost-pruned graph -> CBS -> controller -> safety layer, all
inside one :class:`agents.search.SearchPolicy`.

Run: ``python examples/plan_and_execute.py``
"""
from __future__ import annotations

import safe_mapf_envs
from agents import load_pretrained
from agents.search import SafetyLayer, SearchPolicy, team_positions

ENV_ID = "SafeCentralObstacle-v0"


def main(n_agents: int = 5, seed: int = 0) -> None:
    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=n_agents)
    critic = load_pretrained(ENV_ID, kind="unconstrained")  # annotates the graph
    safe = load_pretrained(ENV_ID, kind="constrained")  # drives the agents
    # graph nodes: observations of 1000 random free states (a replay buffer would do as well); the
    # safety layer keeps the agents from touching each other, reading the team's shared positions
    policy = SearchPolicy.from_models(critic, safe, n_nodes=1000, seed=seed, d_max=7.0, c_max=0.25,
                                      safety=SafetyLayer.for_env(env))

    obs, _ = env.reset(seed=seed)
    names = list(env.agents)
    cost = dict.fromkeys(names, 0.0)
    arrived, touched = set(), set()
    while env.agents:
        actions, _ = policy.predict({a: obs[a] for a in env.agents}, positions=team_positions(env))
        obs, _, terminations, _, infos = env.step(actions)
        for a, info in infos.items():
            cost[a] += info["cost"]
            touched.update([a, *info["collided_with"]] if info["collided_with"] else [])
            if terminations[a]:
                arrived.add(a)
    plan = policy.current_plan
    print(f"CBS: {plan.status}, sum of costs {plan.soc} steps, {policy.planning_time:.2f} s, "
          f"waypoints per agent {[len(n) for n in plan.nodes]}")
    print(f"{len(arrived)}/{n_agents} agents arrived in {policy.stats.steps} steps; "
          f"cumulative cost per agent: {[round(c, 2) for c in cost.values()]}")
    print(f"safety rate {1 - len(touched) / n_agents:.0%} (agents that never touched another); the layer "
          f"changed {policy.safety_state.steered} agent-steps")


if __name__ == "__main__":
    main()
