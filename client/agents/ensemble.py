"""Several independent DDPG runs trained in lockstep as one batched ensemble.

Member r starts exactly as ``DDPG(config, seeds[r])`` (the same initial networks, replay
generator and exploration noise) and learns only from its own transitions. The weights of all
members are stacked along a first dimension and applied with batched matrix products; the loss
is the sum over members of each member's own mean loss, so each member's gradient, its Adam
step (element-wise) and its soft update are those of the unbatched run. Batched arithmetic may
round differently, so results equal the unbatched path within rounding, not bit for bit.

On a CUDA device the whole update (both losses, both backward passes, both Adam steps and the
soft update) is captured once as a CUDA graph and replayed: a few hundred kernels for every
member at the cost of one launch, which is what makes the paper's 18 million updates fit in
minutes on one GPU.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

from client.agents.ddpg import A_MAX, DDPG, DDPGConfig

Params = list[torch.Tensor]  # W1, b1, W2, b2, W3, b3, each with a leading member dimension
TRANSITION = 11  # columns of a stored transition: obs 4, action 1, reward 1, next obs 4, done 1
EAGER_UPDATES = 3  # updates run eagerly (on a side stream) before a CUDA graph is captured


def _stack(modules: Sequence[nn.Module], device: torch.device, grad: bool) -> Params:
    """The linear layers of each member's network, stacked: weights as [R, in, out] (so that
    x @ W is the layer), biases as [R, 1, out]."""
    layers = [[m for m in module.modules() if isinstance(m, nn.Linear)] for module in modules]
    params: Params = []
    for depth in range(len(layers[0])):
        for part in ("weight", "bias"):
            rows = [getattr(member[depth], part).detach() for member in layers]
            stacked = torch.stack([r.T if part == "weight" else r[None] for r in rows])
            params.append(stacked.contiguous().to(device).requires_grad_(grad))
    return params


def _mlp(params: Params, x: torch.Tensor) -> torch.Tensor:
    h = torch.relu(torch.baddbmm(params[1], x, params[0]))
    h = torch.relu(torch.baddbmm(params[3], h, params[2]))
    return torch.baddbmm(params[5], h, params[4])


def _mu(actor: Params, obs: torch.Tensor) -> torch.Tensor:
    return torch.tanh(_mlp(actor, obs)) * A_MAX


def _q(critic: Params, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    return _mlp(critic, torch.cat([obs, action / A_MAX], dim=2))


class DDPGEnsemble:
    """R DDPG learners, one per run, updated together on ``device`` ("cpu" or "cuda")."""

    def __init__(self, config: DDPGConfig, seeds: Sequence[int], device: str = "cpu") -> None:
        self.config = config
        self.device = torch.device(device)
        self.members = [DDPG(config, seed) for seed in seeds]
        self.actor = _stack([m.actor for m in self.members], self.device, True)
        self.critic = _stack([m.critic for m in self.members], self.device, True)
        self.actor_target = _stack([m.actor_target for m in self.members], self.device, False)
        self.critic_target = _stack([m.critic_target for m in self.members], self.device, False)
        self.actor_opt = self._adam(self.actor, config.actor_lr)
        self.critic_opt = self._adam(self.critic, config.critic_lr)
        self._prepare()

    def _adam(self, params: Params, lr: float) -> torch.optim.Adam:
        return torch.optim.Adam(params, lr=lr, foreach=True,
                                capturable=self.device.type == "cuda")

    def _prepare(self) -> None:
        """Buffers for the sampled batch, sized for the current members; no graph yet."""
        shape = (len(self.members), self.config.batch_size, TRANSITION)
        self._staging = np.zeros(shape, np.float32)
        self._batch = torch.zeros(shape, device=self.device)
        self._graph: torch.cuda.CUDAGraph | None = None
        self._eager_left = EAGER_UPDATES

    def keep(self, members: Sequence[int]) -> None:
        """Go on with these members only (positions in :attr:`members`): the stacked networks,
        targets and Adam moments are sliced, so the members kept continue unchanged."""
        index = torch.tensor(list(members), dtype=torch.long, device=self.device)

        def rows(params: Params, grad: bool) -> Params:
            return [p.detach()[index].clone().requires_grad_(grad) for p in params]

        def moved(old: torch.optim.Adam, params: Params, new_params: Params,
                  lr: float) -> torch.optim.Adam:
            new = self._adam(new_params, lr)
            for param, new_param in zip(params, new_params, strict=True):
                state = old.state.get(param)
                if state:
                    new.state[new_param] = {
                        "step": state["step"].clone(),
                        "exp_avg": state["exp_avg"][index].clone(),
                        "exp_avg_sq": state["exp_avg_sq"][index].clone(),
                    }
            return new

        actor, critic = rows(self.actor, True), rows(self.critic, True)
        self.actor_opt = moved(self.actor_opt, self.actor, actor, self.config.actor_lr)
        self.critic_opt = moved(self.critic_opt, self.critic, critic, self.config.critic_lr)
        self.actor, self.critic = actor, critic
        self.actor_target = rows(self.actor_target, False)
        self.critic_target = rows(self.critic_target, False)
        self.members = [self.members[i] for i in members]
        self._prepare()

    def state(self) -> dict[str, Any]:
        """Everything the members have learned and drawn so far (networks, targets, Adam
        moments, replay memories, exploration noise), on the CPU: :meth:`restore` on an
        ensemble of the same members continues exactly from here."""
        def cpu(params: Params) -> Params:
            return [p.detach().cpu().clone() for p in params]

        return {"actor": cpu(self.actor), "critic": cpu(self.critic),
                "actor_target": cpu(self.actor_target), "critic_target": cpu(self.critic_target),
                "actor_opt": copy.deepcopy(self.actor_opt.state_dict()),  # moments change in place
                "critic_opt": copy.deepcopy(self.critic_opt.state_dict()),
                "memories": [m.buffer.state() for m in self.members],
                "noises": [m.noise.state() for m in self.members]}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state`."""
        if len(state["memories"]) != len(self.members):
            raise ValueError(f"a state of {len(state['memories'])} members, not "
                             f"{len(self.members)}")

        def placed(params: Params, grad: bool) -> Params:
            return [p.to(self.device).requires_grad_(grad) for p in params]

        self.actor, self.critic = placed(state["actor"], True), placed(state["critic"], True)
        self.actor_target = placed(state["actor_target"], False)
        self.critic_target = placed(state["critic_target"], False)
        self.actor_opt = self._adam(self.actor, self.config.actor_lr)
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt = self._adam(self.critic, self.config.critic_lr)
        self.critic_opt.load_state_dict(state["critic_opt"])
        for member, memory, noise in zip(self.members, state["memories"], state["noises"],
                                         strict=True):
            member.buffer.restore(memory)
            member.noise.restore(noise)
        self._prepare()

    def act(self, observations: npt.NDArray[np.float32], explore: bool = True) -> list[float]:
        """mu(z-bar) + N_OU for every member, clipped to [-2, 2]; one row of obs per member."""
        scaled = np.stack([DDPG.scale(o) for o in observations])[:, None, :]
        with torch.no_grad():
            obs = torch.from_numpy(scaled).to(self.device)
            actions: list[float] = _mu(self.actor, obs)[:, 0, 0].tolist()
        if explore:
            actions = [a + m.noise() for a, m in zip(actions, self.members, strict=True)]
        return [min(max(a, -A_MAX), A_MAX) for a in actions]

    def update(self) -> None:
        """One gradient step of every member: critic, actor, soft target update."""
        cfg = self.config
        # runs that finished stop filling their memory; the running ones hold the most
        if max(m.buffer.count for m in self.members) < max(cfg.warmup, cfg.batch_size):
            return
        for member, rows in zip(self.members, self._staging, strict=True):
            member.buffer.sample_into(rows)
        self._batch.copy_(torch.from_numpy(self._staging))
        if self.device.type != "cuda":
            self._step()
        elif self._graph is not None:
            self._graph.replay()
        elif self._eager_left > 0:  # warm-up outside any graph, as capture requires
            self._eager_left -= 1
            side = torch.cuda.Stream(self.device)  # type: ignore[no-untyped-call]
            side.wait_stream(torch.cuda.current_stream(self.device))
            with torch.cuda.stream(side):
                self._step()
            torch.cuda.current_stream(self.device).wait_stream(side)
        else:
            self.actor_opt.zero_grad(set_to_none=True)
            self.critic_opt.zero_grad(set_to_none=True)
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):  # recorded, not run: the replay below runs it
                self._step()
            self._graph = graph
            graph.replay()

    def _step(self) -> None:
        cfg, batch = self.config, self._batch
        obs, action, reward = batch[..., 0:4], batch[..., 4:5], batch[..., 5:6]
        next_obs, done = batch[..., 6:10], batch[..., 10:11]
        with torch.no_grad():
            next_q = _q(self.critic_target, next_obs, _mu(self.actor_target, next_obs))
            target = reward + cfg.gamma * (1.0 - done) * next_q
        critic_loss = ((_q(self.critic, obs, action) - target) ** 2).mean(dim=(1, 2)).sum()
        self.critic_opt.zero_grad()
        critic_loss.backward()  # type: ignore[no-untyped-call]
        self.critic_opt.step()
        for p in self.critic:  # the actor's loss needs no gradient of the critic's weights
            p.requires_grad_(False)
        actor_loss = -_q(self.critic, obs, _mu(self.actor, obs)).mean(dim=(1, 2)).sum()
        self.actor_opt.zero_grad()
        actor_loss.backward()  # type: ignore[no-untyped-call]
        self.actor_opt.step()
        for p in self.critic:
            p.requires_grad_(True)
        with torch.no_grad():  # soft update: theta' <- theta' + tau (theta - theta')
            torch._foreach_lerp_([*self.actor_target, *self.critic_target],
                                 [*self.actor, *self.critic], cfg.tau)
