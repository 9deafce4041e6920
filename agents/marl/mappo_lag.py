"""MAPPO-Lagrangian: parameter-shared PPO with centralised reward and cost critics and a multiplier.

Anchored on MAPPO-L (the Lagrangian baseline of MACPO, Gu et al., as in SafePO): the actor
acts from an agent's own flat observation ``[position, goal]`` (decentralised execution);
the reward critic and the cost critic see the global state (every agent's position and goal,
the env's :meth:`state`) with the agent's own observation appended (training only). The policy
loss is PPO's clipped surrogate on ``(A_r - lambda A_c) / (1 + lambda)``; after every rollout
``lambda <- max(0, lambda + lr (J_c - d))`` with ``J_c`` an agent's mean episode cost over
the episodes that ended in the rollout and ``d`` the cost limit (once ``lagrange_start`` agent
steps are done: a multiplier that grows before the agents can arrive teaches them to stand still).

Agents that reach their goal leave the env (parked there); their later slots are masked out
of every loss (the exact form of black death). Truncated agents bootstrap from the critics.
"""
from __future__ import annotations

from typing import Any, Dict, List, Sequence

import numpy as np
import torch
from torch import nn

from .common import Act, RunFolder, make_env
from .config import MarlConfig


def _mlp(n_in: int, n_out: int, arch: Sequence[int], out_gain: float) -> nn.Sequential:
    """Tanh MLP, orthogonally initialised as SB3's PPO does (hidden gain sqrt(2), output ``out_gain``)."""
    layers: List[nn.Module] = []
    for width in arch:
        layers += [nn.Linear(n_in, width), nn.Tanh()]
        n_in = width
    layers.append(nn.Linear(n_in, n_out))
    linear = [m for m in layers if isinstance(m, nn.Linear)]
    for i, m in enumerate(linear):
        nn.init.orthogonal_(m.weight, gain=out_gain if i == len(linear) - 1 else 2 ** 0.5)
        nn.init.zeros_(m.bias)
    return nn.Sequential(*layers)


class MappoNets(nn.Module):
    """The shared Gaussian actor (own observation) and the centralised reward and cost critics."""

    def __init__(self, obs_dim: int, state_dim: int, net_arch: Sequence[int], act_dim: int = 2) -> None:
        super().__init__()
        self.actor = _mlp(obs_dim, act_dim, net_arch, 0.01)
        self.log_std = nn.Parameter(torch.zeros(act_dim))
        self.critic = _mlp(state_dim + obs_dim, 1, net_arch, 1.0)
        self.cost_critic = _mlp(state_dim + obs_dim, 1, net_arch, 1.0)

    def dist(self, obs: torch.Tensor) -> torch.distributions.Normal:
        return torch.distributions.Normal(self.actor(obs), self.log_std.exp().expand(obs.shape[0], -1))

    def values(self, critic_in: torch.Tensor) -> torch.Tensor:
        """``(n, 2)``: the reward value and the cost value."""
        return torch.cat([self.critic(critic_in), self.cost_critic(critic_in)], dim=-1)


class _Envs:
    """``n_envs`` env copies stepped together; arrays are ``(n_envs, n_agents, ...)``."""

    def __init__(self, cfg: MarlConfig, rng: np.random.Generator) -> None:
        self.envs = [make_env(cfg.env_id, cfg.n_agents, cfg.max_cycles, **cfg.env_kwargs()) for _ in range(cfg.n_envs)]
        self.n, self.rng = cfg.n_agents, rng
        env0 = self.envs[0]
        self.obs_dim = int(env0.observation_space(env0.possible_agents[0]).shape[0])
        self.state_dim = int(env0.state_space.shape[0])
        self.obs = [env.reset(seed=self._seed())[0] for env in self.envs]
        self.ep_cost = np.zeros((len(self.envs), self.n))
        self.ep_reached = np.zeros((len(self.envs), self.n), dtype=bool)
        self.finished: List[Dict[str, float]] = []  # episodes that ended since the last call of take()

    def _seed(self) -> int:
        return int(self.rng.integers(2**31 - 1))

    def gather(self, observations=None):
        """Observations ``(E, N, d)``, critic inputs ``(E, N, s + d)`` and the live mask ``(E, N)``."""
        observations = self.obs if observations is None else observations
        E, N = len(self.envs), self.n
        obs = np.zeros((E, N, self.obs_dim), np.float32)
        alive = np.zeros((E, N), dtype=bool)
        state = np.zeros((E, self.state_dim), np.float32)
        for e, (env, ob) in enumerate(zip(self.envs, observations)):
            for a, o in ob.items():
                i = env.agent_name_mapping[a]
                obs[e, i], alive[e, i] = o, True
            state[e] = env.state()
        crit = np.concatenate([np.repeat(state[:, None], N, axis=1), obs], axis=-1)
        return obs, crit, alive

    def step(self, actions: np.ndarray, alive: np.ndarray):
        """Step every copy; returns rewards, costs, done ``(E, N)``, and the truncated agents' final
        critic inputs (``(E, N, s + d)``, zero elsewhere) with their mask."""
        E, N = alive.shape
        rew, cost = np.zeros((E, N), np.float32), np.zeros((E, N), np.float32)
        done = ~alive
        trunc_mask = np.zeros((E, N), dtype=bool)
        final_obs: List[Dict[str, Any]] = []
        for e, env in enumerate(self.envs):
            names = list(env.agents)
            acts = {a: actions[e, env.agent_name_mapping[a]] for a in names}
            obs, r, term, trunc, infos = env.step(acts)
            for a in names:
                i = env.agent_name_mapping[a]
                rew[e, i], cost[e, i] = r[a], infos[a]["cost"]
                done[e, i] = term[a] or trunc[a]
                trunc_mask[e, i] = trunc[a] and not term[a]
                self.ep_reached[e, i] |= term[a]
            self.ep_cost[e] += cost[e]
            final_obs.append({a: obs[a] for a in names if trunc_mask[e, env.agent_name_mapping[a]]})
            self.obs[e] = obs
        _, final_crit, _ = self.gather(final_obs) if trunc_mask.any() else (None, None, None)
        for e, env in enumerate(self.envs):
            if not env.agents:  # the episode ended: note it and start the next one
                self.finished.append({"cost": float(self.ep_cost[e].mean()),
                                      "success": float(self.ep_reached[e].all()),
                                      "arrival": float(self.ep_reached[e].mean())})
                self.ep_cost[e], self.ep_reached[e] = 0.0, False
                self.obs[e] = env.reset(seed=self._seed())[0]
        return rew, cost, done, final_crit, trunc_mask

    def take(self) -> List[Dict[str, float]]:
        out, self.finished = self.finished, []
        return out

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _gae(rew: np.ndarray, val: np.ndarray, last: np.ndarray, done: np.ndarray, gamma: float, lam: float):
    """Advantages and returns ``(T, E, N)``; ``done[t]`` cuts the chain after step ``t``."""
    adv = np.zeros_like(rew)
    run = np.zeros_like(last)
    for t in range(len(rew) - 1, -1, -1):
        nxt = last if t == len(rew) - 1 else val[t + 1]
        keep = 1.0 - done[t]
        run = rew[t] + gamma * nxt * keep - val[t] + gamma * lam * keep * run
        adv[t] = run
    return adv, adv + val


def train_mappo_lag(cfg: MarlConfig, run: RunFolder) -> Dict[str, Any]:
    """Train (or resume) MAPPO-Lagrangian as ``cfg`` says, writing into ``run``; returns the summary."""
    torch.manual_seed(cfg.seed + run.start_steps)
    rng = np.random.default_rng([cfg.seed, run.start_steps])
    envs = _Envs(cfg, rng)
    nets = MappoNets(envs.obs_dim, envs.state_dim, cfg.net_arch)
    opt = torch.optim.Adam(nets.parameters(), lr=cfg.learning_rate)
    lagrange = float(cfg.lagrange_init)
    if run.start_steps:
        ckpt = read_mappo_checkpoint(str(run.checkpoint), resume=True)
        _load_nets(nets, ckpt, str(run.checkpoint))
        try:
            opt.load_state_dict(ckpt["optimizer"])
        except (ValueError, KeyError, RuntimeError) as exc:
            raise ValueError(f"{run.checkpoint}: its optimizer state does not fit the networks ({exc})") from exc
        lagrange = float(ckpt["lagrange"])

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return nets.actor(torch.as_tensor(obs, dtype=torch.float32)).clamp(-1.0, 1.0).numpy()

    def save(path) -> None:
        torch.save({"nets": nets.state_dict(), "optimizer": opt.state_dict(), "lagrange": lagrange,
                    "obs_dim": envs.obs_dim, "state_dim": envs.state_dim, "net_arch": list(cfg.net_arch)}, path)

    T, E, N = cfg.n_steps, cfg.n_envs, cfg.n_agents
    steps, last_eval = run.start_steps, run.start_steps
    run.open_bar()
    while steps < cfg.timesteps:
        b_obs = np.zeros((T, E, N, envs.obs_dim), np.float32)
        b_crit = np.zeros((T, E, N, envs.state_dim + envs.obs_dim), np.float32)
        b_act = np.zeros((T, E, N, 2), np.float32)
        b_logp, b_alive = np.zeros((T, E, N), np.float32), np.zeros((T, E, N), bool)
        b_val, b_rew = np.zeros((T, E, N, 2), np.float32), np.zeros((T, E, N, 2), np.float32)
        b_done = np.zeros((T, E, N), np.float32)
        for t in range(T):
            obs, crit, alive = envs.gather()
            with torch.no_grad():
                o = torch.as_tensor(obs.reshape(E * N, -1))
                d = nets.dist(o)
                a = d.sample()
                b_logp[t] = d.log_prob(a).sum(-1).reshape(E, N).numpy()
                b_val[t] = nets.values(torch.as_tensor(crit.reshape(E * N, -1))).reshape(E, N, 2).numpy()
            b_act[t] = a.reshape(E, N, 2).numpy()
            b_obs[t], b_crit[t], b_alive[t] = obs, crit, alive
            r, c, done, final_crit, trunc = envs.step(b_act[t], alive)
            b_rew[t, ..., 0], b_rew[t, ..., 1] = r, c
            if trunc.any():  # time limit, not an end: bootstrap from the critics
                with torch.no_grad():
                    boot = nets.values(torch.as_tensor(final_crit[trunc])).numpy()
                b_rew[t][trunc] += cfg.gamma * boot
            b_done[t] = done
            b_val[t][~alive] = 0.0
            run.advance(E * N)
        steps += T * E * N
        _, crit, alive = envs.gather()
        with torch.no_grad():
            last = nets.values(torch.as_tensor(crit.reshape(E * N, -1))).reshape(E, N, 2).numpy()
        last[~alive] = 0.0
        done4 = b_done[..., None].repeat(2, axis=-1)
        adv, ret = _gae(b_rew, b_val, last, done4, cfg.gamma, cfg.gae_lambda)
        m = b_alive.reshape(-1)
        data = [torch.as_tensor(x.reshape(T * E * N, *x.shape[3:])[m])
                for x in (b_obs, b_crit, b_act, b_logp, adv, ret)]
        stats = _update(nets, opt, *data, lagrange=lagrange, cfg=cfg, rng=rng)
        episodes = envs.take()
        if episodes:
            j_c = float(np.mean([ep["cost"] for ep in episodes]))
            if steps > cfg.lagrange_start:
                lagrange = max(0.0, lagrange + cfg.lagrange_lr * (j_c - cfg.cost_limit))
            stats.update(episode_cost=j_c, episode_success=float(np.mean([ep["success"] for ep in episodes])),
                         episode_arrival=float(np.mean([ep["arrival"] for ep in episodes])))
        stats["lagrange"] = lagrange
        for k, v in stats.items():
            run.logger.record(f"train/{k}", v)
        run.logger.dump(steps)
        if cfg.eval_freq and steps - last_eval >= cfg.eval_freq and steps < cfg.timesteps:
            last_eval = steps
            ev = run.evaluate(act, steps, {"lagrange": lagrange})
            run.save_checkpoint(save, steps, envs.obs_dim, {"lagrange_multiplier": lagrange})
            if run.bar is not None:
                run.bar.set_postfix_str(f"success={ev['success_rate']:.2f} cost={ev['mean_cost']:.2f} "
                                        f"lambda={lagrange:.2f}")
    envs.close()
    run.evaluate(act, steps, {"lagrange": lagrange})
    run.save_checkpoint(save, steps, envs.obs_dim, {"lagrange_multiplier": lagrange})
    run.save_file(save, run.out / "model.pt")
    return run.finish(steps, envs.obs_dim, {"lagrange_multiplier": lagrange})


def _update(nets: MappoNets, opt: torch.optim.Optimizer, obs, crit, act, logp_old, adv, ret, *, lagrange: float,
            cfg: MarlConfig, rng: np.random.Generator) -> Dict[str, float]:
    """PPO epochs over one rollout's live agent steps; returns mean losses."""
    # both advantages standardised (as OmniSafe's PPO-Lag does), so lambda weighs like against like
    adv_r = (adv[:, 0] - adv[:, 0].mean()) / (adv[:, 0].std() + 1e-8)
    adv_c = (adv[:, 1] - adv[:, 1].mean()) / (adv[:, 1].std() + 1e-8)
    mixed = (adv_r - lagrange * adv_c) / (1.0 + lagrange)
    n = len(obs)
    losses: Dict[str, List[float]] = {"policy_loss": [], "value_loss": [], "cost_value_loss": [], "entropy": []}
    for _ in range(cfg.n_epochs):
        order = torch.as_tensor(rng.permutation(n))
        for start in range(0, n, cfg.batch_size):
            idx = order[start:start + cfg.batch_size]
            d = nets.dist(obs[idx])
            ratio = (d.log_prob(act[idx]).sum(-1) - logp_old[idx]).exp()
            a = mixed[idx]
            pg = -torch.min(ratio * a, ratio.clamp(1 - cfg.clip_range, 1 + cfg.clip_range) * a).mean()
            v = nets.values(crit[idx])
            v_loss = (v[:, 0] - ret[idx, 0]).pow(2).mean()
            c_loss = (v[:, 1] - ret[idx, 1]).pow(2).mean()
            ent = d.entropy().sum(-1).mean()
            loss = pg + 0.5 * (v_loss + c_loss) - cfg.ent_coef * ent
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(nets.parameters(), 0.5)
            opt.step()
            for k, x in zip(losses, (pg, v_loss, c_loss, ent)):
                losses[k].append(float(x.detach()))
    return {k: float(np.mean(v)) for k, v in losses.items()}


def read_mappo_checkpoint(path: str, resume: bool = False) -> Dict[str, Any]:
    """The content of a MAPPO-Lagrangian checkpoint, checked whole: the file (a torch zip archive)
    passes its checksums, is read with ``torch.load(weights_only=True)``, holds ``obs_dim``,
    ``state_dim``, ``net_arch`` and the networks (with ``resume``: the optimizer state and the
    multiplier too), and every tensor is finite. Anything else raises
    :class:`~agents.checkpoints.CheckpointError` (a ``ValueError``) naming the file."""
    from ..checkpoints import CheckpointError, load_tensors, open_zip, read_file_bytes

    name, raw = read_file_bytes(path, suffix="")
    open_zip(name, raw, what="MAPPO-Lagrangian checkpoint")
    ckpt = load_tensors(name, raw, "the checkpoint")
    needed = ["obs_dim", "state_dim", "net_arch", "nets"] + (["optimizer", "lagrange"] if resume else [])
    if not isinstance(ckpt, dict):
        raise CheckpointError(f"{name} is not a MAPPO-Lagrangian checkpoint (holds a {type(ckpt).__name__})")
    missing = [k for k in needed if k not in ckpt]
    if missing:
        raise CheckpointError(f"{name} is not a complete MAPPO-Lagrangian checkpoint: missing {missing}")
    try:
        dims = [int(ckpt["obs_dim"]), int(ckpt["state_dim"])] + [int(w) for w in ckpt["net_arch"]]
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{name}: obs_dim, state_dim and net_arch must be integers ({exc})") from exc
    if min(dims) < 1 or not isinstance(ckpt["nets"], dict):
        raise CheckpointError(f"{name}: sizes {dims} must be >= 1 and 'nets' a state dict")
    return ckpt


def _load_nets(nets: MappoNets, ckpt: Dict[str, Any], name: str) -> None:
    from ..checkpoints import CheckpointError

    try:
        nets.load_state_dict(ckpt["nets"])
    except RuntimeError as exc:
        raise CheckpointError(f"{name}: its networks do not match obs_dim, state_dim and net_arch ({exc})") from exc


def mappo_act(ckpt: Dict[str, Any], name: str) -> Act:
    """The deterministic action function (the actor's mean, clipped) of a checkpoint's content
    (:func:`read_mappo_checkpoint`; ``name`` names the file in errors)."""
    nets = MappoNets(int(ckpt["obs_dim"]), int(ckpt["state_dim"]), list(ckpt["net_arch"]))
    _load_nets(nets, ckpt, name)
    nets.eval()

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return nets.actor(torch.as_tensor(obs, dtype=torch.float32)).clamp(-1.0, 1.0).numpy()

    return act


def load_mappo_act(path: str) -> Act:
    """The deterministic action function of the MAPPO-Lagrangian checkpoint at ``path``."""
    return mappo_act(read_mappo_checkpoint(path), str(path))


__all__ = ["MappoNets", "load_mappo_act", "mappo_act", "read_mappo_checkpoint", "train_mappo_lag"]
