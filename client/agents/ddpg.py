"""DDPG (Lillicrap et al. 2016) as the paper configures it (section 3.2), on the CPU.

Adam with learning rates 1e-4 (actor) and 1e-3 (critic) and a discount of 0.95 are the paper's;
the sizes it does not give are Lillicrap's defaults [REC] (soft target updates tau = 1e-3,
batches of 64, Ornstein-Uhlenbeck noise theta = 0.15, sigma = 0.2) except the networks: two
hidden layers of 64 units, for the 18 million updates of the full protocol on a CPU. The
replay memory stores the action that was executed (after the shield), as off-policy learning
requires.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

# the columns of a stored transition; a checkpoint keeps them as arrays of these names
COLUMNS = {"obs": slice(0, 4), "action": slice(4, 5), "reward": slice(5, 6),
           "next_obs": slice(6, 10), "done": slice(10, 11)}
TRANSITION = 11
OBS_SCALE = np.array([32.0, 200.0, 32.0, 2.0], dtype=np.float32)  # z-bar: Eq. 9 normalised
A_MAX = 2.0  # [m/s^2]


@dataclass(frozen=True)
class DDPGConfig:
    """Hyperparameters; the paper's values where it gives them."""

    actor_lr: float = 1e-4  # paper
    critic_lr: float = 1e-3  # paper
    gamma: float = 0.95  # paper
    tau: float = 1e-3  # [REC] Lillicrap
    batch_size: int = 64  # [REC]
    buffer_size: int = 100_000  # [REC] omega
    hidden: tuple[int, int] = (64, 64)  # small networks: 400/300 cost 3.5x more per update
    ou_theta: float = 0.15  # [REC]
    ou_sigma: float = 0.2  # [REC]
    warmup: int = 1000  # transitions stored before the first update
    # Not in the paper: each step's update runs before the step instead of after it, so it
    # draws its batch from the transitions stored so far, without the step's own (the next
    # update can draw it). What it buys: the update no longer waits for the shield's answer,
    # so the client runs it while a shield service computes the step (BENCHMARKS.md). Off:
    # the usual order, which every experiment recorded before it used
    update_first: bool = False


class ReplaySample(NamedTuple):
    obs: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    next_obs: torch.Tensor
    done: torch.Tensor


class ReplayBuffer:
    """A ring buffer of (z-bar, executed action, reward, next z-bar, terminal).

    The transitions are the rows of one array, in the columns of :data:`COLUMNS`, so that a
    batch is a single gather; ``obs``, ``action`` and the others are views of its columns.
    """

    def __init__(self, size: int, seed: int) -> None:
        self.size = size
        self.rng = np.random.default_rng(seed)
        self.transitions = np.zeros((size, TRANSITION), np.float32)
        t = self.transitions
        self.obs, self.action, self.reward = (t[:, COLUMNS[c]] for c in ("obs", "action", "reward"))
        self.next_obs, self.done = t[:, COLUMNS["next_obs"]], t[:, COLUMNS["done"]]
        self.count = 0

    def add(self, obs: npt.NDArray[np.float32], action: float, reward: float,
            next_obs: npt.NDArray[np.float32], terminal: bool) -> None:
        i = self.count % self.size
        self.obs[i], self.next_obs[i] = obs, next_obs
        self.action[i], self.reward[i], self.done[i] = action, reward, float(terminal)
        self.count += 1

    def sample(self, batch: int) -> ReplaySample:
        index = self.rng.integers(0, min(self.count, self.size), batch)
        return ReplaySample(*(torch.from_numpy(x[index]) for x in
                              (self.obs, self.action, self.reward, self.next_obs, self.done)))

    def sample_into(self, rows: npt.NDArray[np.float32]) -> None:
        """Draw ``len(rows)`` transitions as :meth:`sample` would (the same generator draws),
        as whole rows of :attr:`transitions` (the columns of :data:`COLUMNS`)."""
        index = self.rng.integers(0, min(self.count, self.size), len(rows))
        np.take(self.transitions, index, axis=0, out=rows)

    def state(self) -> dict[str, Any]:
        """The transitions held and where the generator stands: :meth:`restore` continues
        exactly from here."""
        held = min(self.count, self.size)
        return {"count": self.count, "rng": self.rng.bit_generator.state,
                **{name: getattr(self, name)[:held].copy() for name in COLUMNS}}

    def restore(self, state: dict[str, Any]) -> None:
        held = min(state["count"], self.size)
        for name in COLUMNS:
            getattr(self, name)[:held] = state[name]
        self.count = state["count"]
        self.rng.bit_generator.state = state["rng"]


class OrnsteinUhlenbeckNoise:
    """Temporally correlated exploration noise, from its own generator."""

    def __init__(self, theta: float, sigma: float, seed: int, dt: float = 1.0) -> None:
        self.theta, self.sigma, self.dt = theta, sigma, dt
        self.rng = np.random.default_rng(seed)
        self.x = 0.0

    def __call__(self) -> float:
        self.x += self.theta * -self.x * self.dt + self.sigma * np.sqrt(self.dt) * float(
            self.rng.normal())
        return self.x

    def reset(self) -> None:
        self.x = 0.0

    def state(self) -> dict[str, Any]:
        return {"x": self.x, "rng": self.rng.bit_generator.state}

    def restore(self, state: dict[str, Any]) -> None:
        self.x = state["x"]
        self.rng.bit_generator.state = state["rng"]


class Actor(nn.Module):
    def __init__(self, hidden: tuple[int, int]) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(4, hidden[0]), nn.ReLU(),
                                 nn.Linear(hidden[0], hidden[1]), nn.ReLU(),
                                 nn.Linear(hidden[1], 1), nn.Tanh())

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs) * A_MAX  # type: ignore[no-any-return]


class Critic(nn.Module):
    def __init__(self, hidden: tuple[int, int]) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(5, hidden[0]), nn.ReLU(),
                                 nn.Linear(hidden[0], hidden[1]), nn.ReLU(),
                                 nn.Linear(hidden[1], 1))

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([obs, action / A_MAX], dim=1))  # type: ignore[no-any-return]


class DDPG:
    """Actor, critic, their targets, the replay memory and the exploration noise of one run."""

    def __init__(self, config: DDPGConfig, seed: int) -> None:
        self.config = config
        with torch.random.fork_rng():  # network initialisation from this run's seed only
            torch.manual_seed(seed)
            self.actor, self.critic = Actor(config.hidden), Critic(config.hidden)
            self.actor_target, self.critic_target = Actor(config.hidden), Critic(config.hidden)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=config.actor_lr,
                                          foreach=True)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=config.critic_lr,
                                           foreach=True)
        self._online: list[torch.Tensor] = [*self.actor.parameters(), *self.critic.parameters()]
        self._target: list[torch.Tensor] = [*self.actor_target.parameters(),
                                            *self.critic_target.parameters()]
        self.buffer = ReplayBuffer(config.buffer_size, seed + 1)
        self.noise = OrnsteinUhlenbeckNoise(config.ou_theta, config.ou_sigma, seed + 2)

    @staticmethod
    def scale(obs: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        return (np.asarray(obs, np.float32) / OBS_SCALE).astype(np.float32)

    def act(self, obs: npt.NDArray[np.float32], explore: bool = True) -> float:
        """mu(z-bar) + N_OU, clipped to [-2, 2]."""
        with torch.no_grad():
            a = float(self.actor(torch.from_numpy(self.scale(obs))[None])[0, 0])
        if explore:
            a += self.noise()
        return min(max(a, -A_MAX), A_MAX)

    def remember(self, obs: npt.NDArray[np.float32], executed: float, reward: float,
                 next_obs: npt.NDArray[np.float32], terminal: bool) -> None:
        self.buffer.add(self.scale(obs), executed, reward, self.scale(next_obs), terminal)

    def update(self) -> dict[str, float]:
        """One gradient step of critic and actor, then the soft target update."""
        cfg = self.config
        if self.buffer.count < max(cfg.warmup, cfg.batch_size):
            return {}
        batch = self.buffer.sample(cfg.batch_size)
        with torch.no_grad():
            next_q = self.critic_target(batch.next_obs, self.actor_target(batch.next_obs))
            target = batch.reward + cfg.gamma * (1.0 - batch.done) * next_q
        critic_loss = nn.functional.mse_loss(self.critic(batch.obs, batch.action), target)
        self.critic_opt.zero_grad()
        critic_loss.backward()  # type: ignore[no-untyped-call]
        self.critic_opt.step()
        self.critic.requires_grad_(False)  # the actor's loss needs no critic gradients
        actor_loss = -self.critic(batch.obs, self.actor(batch.obs)).mean()
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        self.critic.requires_grad_(True)
        with torch.no_grad():  # soft update: theta' <- theta' + tau (theta - theta')
            torch._foreach_lerp_(self._target, self._online, cfg.tau)
        return {"critic_loss": critic_loss.item(), "actor_loss": actor_loss.item()}
