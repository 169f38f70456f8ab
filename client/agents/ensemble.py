"""Several independent DDPG runs trained in lockstep as one vectorised ensemble (torch.func).

Member r starts exactly as ``DDPG(config, seeds[r])`` (the same initial networks, replay
generator and exploration noise) and learns only from its own transitions. The networks of all
members are stacked and evaluated with ``vmap``; the loss is the sum over members of each
member's own mean loss, so each member's gradient, its Adam step (element-wise) and its soft
update are those of the unbatched run. Batched arithmetic may round differently, so results
equal the unbatched path within rounding, not bit for bit.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from torch.func import functional_call, stack_module_state, vmap

from client.agents.ddpg import A_MAX, DDPG, DDPGConfig


class DDPGEnsemble:
    """R DDPG learners, one per run, updated together."""

    def __init__(self, config: DDPGConfig, seeds: Sequence[int]) -> None:
        self.config = config
        self.members = [DDPG(config, seed) for seed in seeds]
        stack = [(m.actor, m.critic, m.actor_target, m.critic_target) for m in self.members]
        self.actor, _ = stack_module_state([s[0] for s in stack])
        self.critic, _ = stack_module_state([s[1] for s in stack])
        self.actor_target = {k: v.detach().clone() for k, v in
                             stack_module_state([s[2] for s in stack])[0].items()}
        self.critic_target = {k: v.detach().clone() for k, v in
                              stack_module_state([s[3] for s in stack])[0].items()}
        self._actor_base = copy.deepcopy(self.members[0].actor).to("meta")
        self._critic_base = copy.deepcopy(self.members[0].critic).to("meta")
        self.actor_opt = torch.optim.Adam(list(self.actor.values()), lr=config.actor_lr,
                                          foreach=True)
        self.critic_opt = torch.optim.Adam(list(self.critic.values()), lr=config.critic_lr,
                                           foreach=True)
        self._online = [*self.actor.values(), *self.critic.values()]
        self._target = [*self.actor_target.values(), *self.critic_target.values()]

    def keep(self, members: Sequence[int]) -> None:
        """Go on with these members only (positions in :attr:`members`): the stacked networks,
        targets and Adam moments are sliced, so the members kept continue unchanged."""
        index = torch.tensor(list(members), dtype=torch.long)

        def rows(params: dict[str, torch.Tensor], grad: bool) -> dict[str, torch.Tensor]:
            return {k: v.detach()[index].clone().requires_grad_(grad) for k, v in params.items()}

        def moved(old: torch.optim.Adam, params: dict[str, torch.Tensor],
                  new_params: dict[str, torch.Tensor]) -> torch.optim.Adam:
            group = old.param_groups[0]
            new = torch.optim.Adam(list(new_params.values()), lr=group["lr"], foreach=True)
            for name, param in params.items():
                state = old.state.get(param)
                if state:
                    new.state[new_params[name]] = {
                        "step": state["step"].clone(),
                        "exp_avg": state["exp_avg"][index].clone(),
                        "exp_avg_sq": state["exp_avg_sq"][index].clone(),
                    }
            return new

        actor, critic = rows(self.actor, True), rows(self.critic, True)
        self.actor_opt = moved(self.actor_opt, self.actor, actor)
        self.critic_opt = moved(self.critic_opt, self.critic, critic)
        self.actor, self.critic = actor, critic
        self.actor_target = rows(self.actor_target, False)
        self.critic_target = rows(self.critic_target, False)
        self.members = [self.members[i] for i in members]
        self._online = [*self.actor.values(), *self.critic.values()]
        self._target = [*self.actor_target.values(), *self.critic_target.values()]

    def _mu(self, params: dict[str, torch.Tensor], obs: torch.Tensor) -> torch.Tensor:
        return functional_call(self._actor_base, params, (obs,))  # type: ignore[no-any-return]

    def _q(self, params: dict[str, torch.Tensor], obs: torch.Tensor,
           action: torch.Tensor) -> torch.Tensor:
        return functional_call(self._critic_base, params, (obs, action))  # type: ignore[no-any-return]

    def act(self, observations: npt.NDArray[np.float32], explore: bool = True) -> list[float]:
        """mu(z-bar) + N_OU for every member, clipped to [-2, 2]; one row of obs per member."""
        scaled = np.stack([DDPG.scale(o) for o in observations])[:, None, :]
        with torch.no_grad():
            actions = vmap(self._mu)(self.actor, torch.from_numpy(scaled))[:, 0, 0].tolist()
        if explore:
            actions = [a + m.noise() for a, m in zip(actions, self.members, strict=True)]
        return [min(max(a, -A_MAX), A_MAX) for a in actions]

    def update(self) -> dict[str, Any]:
        """One gradient step of every member: critic, actor, soft target update."""
        cfg = self.config
        # runs that finished stop filling their memory; the running ones hold the most
        if max(m.buffer.count for m in self.members) < max(cfg.warmup, cfg.batch_size):
            return {}
        batches = [m.buffer.sample(cfg.batch_size) for m in self.members]
        obs, action, reward, next_obs, done = (torch.stack(x) for x in zip(*batches, strict=True))
        with torch.no_grad():
            next_q = vmap(self._q)(self.critic_target, next_obs,
                                   vmap(self._mu)(self.actor_target, next_obs))
            target = reward + cfg.gamma * (1.0 - done) * next_q
        q = vmap(self._q)(self.critic, obs, action)
        critic_loss = ((q - target) ** 2).mean(dim=(1, 2)).sum()  # each member's own mean
        self.critic_opt.zero_grad()
        critic_loss.backward()  # type: ignore[no-untyped-call]
        self.critic_opt.step()
        actor_loss = -vmap(self._q)(self.critic, obs, vmap(self._mu)(self.actor, obs)).mean(
            dim=(1, 2)).sum()
        self.actor_opt.zero_grad()
        actor_loss.backward()  # type: ignore[no-untyped-call]
        self.actor_opt.step()
        with torch.no_grad():  # soft update: theta' <- theta' + tau (theta - theta')
            torch._foreach_lerp_(self._target, self._online, cfg.tau)
        return {"critic_loss": critic_loss.item(), "actor_loss": actor_loss.item()}
