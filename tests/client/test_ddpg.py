"""The per-run DDPG learner: its written-out update is autograd's and Adam's."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from client.agents.ddpg import DDPG, Actor, Critic, DDPGConfig, ReplayBuffer
from tests.client.test_ensemble import assert_moments_are_adams


class AutogradDDPG:
    """One run's update as autograd and ``torch.optim.Adam`` compute it on ``nn.Module``
    networks: the form the written-out update replaced, from the same seed's networks and
    drawing the same batches from a memory of the same seed."""

    def __init__(self, config: DDPGConfig, seed: int) -> None:
        self.config = config
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            self.actor, self.critic = Actor(config.hidden), Critic(config.hidden)
            self.actor_target, self.critic_target = Actor(config.hidden), Critic(config.hidden)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=config.actor_lr, foreach=True)
        self.critic_opt = torch.optim.Adam(
            self.critic.parameters(), lr=config.critic_lr, foreach=True
        )
        self.buffer = ReplayBuffer(config.buffer_size, seed + 1)

    def online(self) -> list[torch.Tensor]:
        return [*self.actor.parameters(), *self.critic.parameters()]

    def update(self) -> None:
        cfg = self.config
        batch = self.buffer.sample(cfg.batch_size)
        with torch.no_grad():
            next_q = self.critic_target(batch.next_obs, self.actor_target(batch.next_obs))
            target = batch.reward + cfg.gamma * (1.0 - batch.done) * next_q
        critic_loss = nn.functional.mse_loss(self.critic(batch.obs, batch.action), target)
        self.critic_opt.zero_grad()
        critic_loss.backward()  # type: ignore[no-untyped-call]
        self.critic_opt.step()
        self.critic.requires_grad_(False)
        actor_loss = -self.critic(batch.obs, self.actor(batch.obs)).mean()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        self.critic.requires_grad_(True)
        with torch.no_grad():
            targets: list[torch.Tensor] = [
                *self.actor_target.parameters(),
                *self.critic_target.parameters(),
            ]
            torch._foreach_lerp_(targets, self.online(), cfg.tau)

    def moments(self, name: str) -> torch.Tensor:
        """One of Adam's moments of every layer, laid out as the learner's flat buffers."""
        return torch.cat(
            [
                opt.state[p][name].reshape(-1)
                for opt, net in ((self.actor_opt, self.actor), (self.critic_opt, self.critic))
                for p in net.parameters()
            ]
        )


def flat(params: list[torch.Tensor]) -> torch.Tensor:
    return torch.cat([p.detach().reshape(-1) for p in params])


def test_the_update_is_autograds_and_adams_bit_for_bit() -> None:
    """Weights and targets agree with autograd's and ``torch.optim.Adam``'s exactly, update
    after update, long enough for units to die and Adam's moments to decay into subnormal
    numbers, which the learner flushes to zero (where the CPU can): nothing else differs."""
    torch.set_num_threads(1)
    config = DDPGConfig(warmup=64)
    learner, reference = DDPG(config, 4), AutogradDDPG(config, 4)
    rng = np.random.default_rng(0)
    for _ in range(500):
        transition = (
            rng.uniform(0, 30, 4).astype(np.float32),
            rng.uniform(-2, 2),
            rng.uniform(-3, 0),
            rng.uniform(0, 30, 4).astype(np.float32),
            rng.random() < 0.05,
        )
        learner.buffer.add(*transition)
        reference.buffer.add(*transition)
    assert torch.equal(flat(reference.online()), learner._online)
    for _ in range(1000):
        learner.update()
        reference.update()
    assert torch.equal(flat(reference.online()), learner._online)
    assert torch.equal(
        flat([*reference.actor_target.parameters(), *reference.critic_target.parameters()]),
        learner._target,
    )
    # the modules are views of the flat buffers: what acts is what learned
    assert torch.equal(
        flat([*learner.actor.parameters(), *learner.critic.parameters()]), learner._online
    )
    obs = np.array([20.0, 30.0, 18.0, 0.5], np.float32)
    with torch.no_grad():
        acted = float(reference.actor(torch.from_numpy(DDPG.scale(obs))[None])[0, 0])
    assert learner.act(obs, explore=False) == acted
    assert learner._steps.tolist() == [1000.0, 1000.0]
    assert_moments_are_adams(learner._moments, reference.moments)
