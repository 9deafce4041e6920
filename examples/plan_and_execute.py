"""Plan waypoints for 5 agents with CBS on the replay-buffer graph, then execute them.

The pipeline of "Safe Multi-Agent Navigation guided by Goal-Conditioned Safe Reinforcement
Learning", step by step, with the shipped checkpoints of ``SafeCentralObstacle-v0``:
graph nodes -> critics' distance/cost matrices -> cost-pruned graph -> CBS -> controller.

Run: ``python examples/plan_and_execute.py``
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

import safe_mapf_envs
from agents import load_pretrained
from agents.search import BufferPlanner, WaypointController
from agents.self_sampling import observations_at
from baselines.methods import distance_fn, policy_fn

ENV_ID = "SafeCentralObstacle-v0"


def main(n_agents: int = 5, seed: int = 0) -> None:
    critic = load_pretrained(ENV_ID, kind="unconstrained")  # annotates the graph
    safe = load_pretrained(ENV_ID, kind="constrained")  # drives the agents

    # graph nodes: observations of random free states (a replay buffer would do as well)
    single = gym.make(ENV_ID)
    states = single.unwrapped.sample_states(1000, np.random.default_rng(seed))
    nodes = observations_at(single, states)
    planner = BufferPlanner.from_agent(critic, nodes, d_max=7.0, c_max=0.25)

    env = safe_mapf_envs.parallel_env(ENV_ID, n_agents=n_agents)
    obs, _ = env.reset(seed=seed)
    names = list(env.agents)
    starts = np.stack([obs[a]["observation"] for a in names])
    goals = np.stack([obs[a]["desired_goal"] for a in names])
    plan = planner.plan(starts, goals)
    print(f"CBS: {plan.status}, sum of costs {plan.soc} steps, {plan.planning_time:.2f} s, "
          f"waypoints per agent {[len(n) for n in plan.nodes]}")

    plans = plan.agent_plans(planner.last_observations, goals, names, hold="waits")
    ctrl = WaypointController(policy_fn(safe), distance_fn(safe), plans, reach_threshold=2.0, safety_radius=2.0)
    cost = dict.fromkeys(names, 0.0)
    arrived = set()
    while env.agents:
        actions = ctrl.act({a: obs[a]["observation"] for a in env.agents})
        obs, _, terminations, _, infos = env.step(actions)
        for a, info in infos.items():
            cost[a] += info["cost"]
            if terminations[a]:
                arrived.add(a)
    print(f"{len(arrived)}/{n_agents} agents arrived in {ctrl.t} steps; "
          f"cumulative cost per agent: {[round(c, 2) for c in cost.values()]}")


if __name__ == "__main__":
    main()
