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

from client.agents.flat import adam_step, subnormals_flushed, views

# the columns of a stored transition; a checkpoint keeps them as arrays of these names
COLUMNS = {
    "obs": slice(0, 4),
    "action": slice(4, 5),
    "reward": slice(5, 6),
    "next_obs": slice(6, 10),
    "done": slice(10, 11),
}
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
        self.obs, self.action, self.reward, self.next_obs, self.done = (
            self.transitions[:, COLUMNS[name]] for name in COLUMNS
        )
        self.count = 0

    def add(
        self,
        obs: npt.NDArray[np.float32],
        action: float,
        reward: float,
        next_obs: npt.NDArray[np.float32],
        terminal: bool,
    ) -> None:
        i = self.count % self.size
        self.obs[i], self.next_obs[i] = obs, next_obs
        self.action[i], self.reward[i], self.done[i] = action, reward, float(terminal)
        self.count += 1

    def sample(self, batch: int) -> ReplaySample:
        index = self.rng.integers(0, min(self.count, self.size), batch)
        return ReplaySample(
            *(
                torch.from_numpy(x[index])
                for x in (self.obs, self.action, self.reward, self.next_obs, self.done)
            )
        )

    def sample_into(self, rows: npt.NDArray[np.float32]) -> None:
        """Draw ``len(rows)`` transitions as :meth:`sample` would (the same generator draws),
        as whole rows of :attr:`transitions` (the columns of :data:`COLUMNS`)."""
        index = self.rng.integers(0, min(self.count, self.size), len(rows))
        np.take(self.transitions, index, axis=0, out=rows)

    def state(self) -> dict[str, Any]:
        """The transitions held and where the generator stands: :meth:`restore` continues
        exactly from here."""
        held = min(self.count, self.size)
        return {
            "count": self.count,
            "rng": self.rng.bit_generator.state,
            **{name: getattr(self, name)[:held].copy() for name in COLUMNS},
        }

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
            self.rng.normal()
        )
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
        self.net = nn.Sequential(
            nn.Linear(4, hidden[0]),
            nn.ReLU(),
            nn.Linear(hidden[0], hidden[1]),
            nn.ReLU(),
            nn.Linear(hidden[1], 1),
            nn.Tanh(),
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs) * A_MAX  # type: ignore[no-any-return]


class Critic(nn.Module):
    def __init__(self, hidden: tuple[int, int]) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(5, hidden[0]),
            nn.ReLU(),
            nn.Linear(hidden[0], hidden[1]),
            nn.ReLU(),
            nn.Linear(hidden[1], 1),
        )

    def forward(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([obs, action / A_MAX], dim=1))  # type: ignore[no-any-return]


class DDPG:
    """Actor, critic, their targets, the replay memory and the exploration noise of one run.

    The update is written out rather than left to autograd and ``torch.optim.Adam``, as in
    the lockstep ensemble: the gradients by hand with the operations autograd's backward
    pass runs for these networks (``addmm``'s and the activations'), every weight, gradient
    and Adam moment in one flat buffer (:mod:`client.agents.flat`; the modules' parameters
    are views of it), so that an update costs fewer calls: about half the time
    (``bench/learner_versions.py``). The weights are autograd's and ``torch.optim.Adam``'s
    bit for bit (``tests/client/test_ddpg.py``), so runs recorded before replay as they did.
    """

    def __init__(self, config: DDPGConfig, seed: int) -> None:
        self.config = config
        with torch.random.fork_rng():  # network initialisation from this run's seed only
            torch.manual_seed(seed)
            self.actor, self.critic = Actor(config.hidden), Critic(config.hidden)
            self.actor_target, self.critic_target = Actor(config.hidden), Critic(config.hidden)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        # every flat buffer holds the actor's layers, then the critic's; the modules'
        # parameters become views of the online and target buffers (equal at the start)
        networks, targets = (self.actor, self.critic), (self.actor_target, self.critic_target)
        params = [p for net in networks for p in net.parameters()]
        self._shapes = [p.shape for p in params]
        self._online = torch.cat([p.detach().reshape(-1) for p in params])
        self._target = self._online.clone()
        self._grad = torch.zeros_like(self._online)
        self._moments = torch.zeros(2, self._online.numel())  # Adam's first and second
        self._steps = torch.zeros(2)  # Adam's step counts of the actor and of the critic
        online, target = views(self._online, self._shapes), views(self._target, self._shapes)
        for modules, layers in ((networks, online), (targets, target)):
            owned = [p for net in modules for p in net.parameters()]
            for param, view in zip(owned, layers, strict=True):
                param.data = view
        split = len(params) // 2
        grads = views(self._grad, self._shapes)
        self._layers, self._target_layers = (
            (online[:split], online[split:]),
            (target[:split], target[split:]),
        )
        self._grads = grads[:split], grads[split:]
        cut = sum(p.numel() for p in self.actor.parameters())
        self._parts = slice(0, cut), slice(cut, None)  # the actor's and the critic's
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

    def remember(
        self,
        obs: npt.NDArray[np.float32],
        executed: float,
        reward: float,
        next_obs: npt.NDArray[np.float32],
        terminal: bool,
    ) -> None:
        self.buffer.add(self.scale(obs), executed, reward, self.scale(next_obs), terminal)

    def update(self) -> None:
        """One gradient step of critic and actor, then the soft target update."""
        cfg = self.config
        if self.buffer.count < max(cfg.warmup, cfg.batch_size):
            return
        with subnormals_flushed():
            self._step(self.buffer.sample(cfg.batch_size))

    def _step(self, batch: ReplaySample) -> None:
        cfg = self.config
        (actor, critic), (actor_target, critic_target) = self._layers, self._target_layers
        # critic: minimise the mean of (Q(z, a) - y)^2, y = r + gamma (1 - done) Q'(z', mu'(z'))
        next_q = _forward(
            critic_target, _critic_input(batch.next_obs, _mu(actor_target, batch.next_obs))
        )[2]
        target = batch.reward + cfg.gamma * (1.0 - batch.done) * next_q
        x = _critic_input(batch.obs, batch.action)
        h1, h2, q = _forward(critic, x)
        # mse_loss's gradient, 2 (q - y) / batch (times the loss's own gradient, 1)
        _backward(critic, x, h1, h2, (q - target) * (2.0 / q.numel()), self._grads[1])
        self._adam(1, cfg.critic_lr)
        # actor: maximise the mean of Q(z, mu(z)), through the critic just updated
        a1, a2, out = _forward(actor, batch.obs)
        squashed = torch.tanh(out)
        x = _critic_input(batch.obs, squashed * A_MAX)
        h1, h2, q = _forward(critic, x)
        g1 = _backward(critic, x, h1, h2, torch.full_like(q, -1.0 / q.numel()), None)
        # back through the critic's input (action / A_MAX) and mu's output (tanh * A_MAX),
        # each step as autograd takes it, though the two scalings cancel
        grad_action = g1.mm(critic[0])[:, 4:5] / A_MAX
        grad_out = torch.ops.aten.tanh_backward(grad_action * A_MAX, squashed)
        _backward(actor, batch.obs, a1, a2, grad_out, self._grads[0])
        self._adam(0, cfg.actor_lr)
        # soft update: theta' <- theta' + tau (theta - theta')
        self._target.lerp_(self._online, cfg.tau)

    def _adam(self, network: int, lr: float) -> None:
        """One Adam step of the actor (0) or the critic (1)."""
        part = self._parts[network]
        adam_step(
            self._online[part], self._grad[part], self._moments[:, part], self._steps[network], lr
        )


def _forward(
    layers: list[torch.Tensor],
    x: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The MLP's two hidden activations and its output, as ``nn.Linear`` computes them
    (``addmm`` of the bias, the input and the transposed weight)."""
    h1 = torch.relu(torch.addmm(layers[1], x, layers[0].t()))
    h2 = torch.relu(torch.addmm(layers[3], h1, layers[2].t()))
    return h1, h2, torch.addmm(layers[5], h2, layers[4].t())


def _backward(
    layers: list[torch.Tensor],
    x: torch.Tensor,
    h1: torch.Tensor,
    h2: torch.Tensor,
    grad_out: torch.Tensor,
    grads: list[torch.Tensor] | None,
) -> torch.Tensor:
    """Back-propagate ``grad_out`` through the MLP of :func:`_forward`, writing the gradients
    of its weights into ``grads`` where given; returns the gradient at the first layer's
    output (before its relu).

    The operations of autograd's backward of ``addmm`` and ``relu``: for ``x W^T + b``,
    ``dW = g^T x``, ``db`` the sum of ``g`` over the batch, ``dx = g W``; ``relu`` passes the
    gradient where its output is positive.
    """
    relu_backward = torch.ops.aten.threshold_backward
    g2 = relu_backward(grad_out.mm(layers[4]), h2, 0)
    g1: torch.Tensor = relu_backward(g2.mm(layers[2]), h1, 0)
    if grads is not None:
        for (w, b), inputs, g in zip(
            ((4, 5), (2, 3), (0, 1)), (h2, h1, x), (grad_out, g2, g1), strict=True
        ):
            grads[w].copy_(g.t().mm(inputs))  # mm(out=...) may round otherwise
            torch.sum(g, dim=0, out=grads[b])
    return g1


def _mu(layers: list[torch.Tensor], obs: torch.Tensor) -> torch.Tensor:
    return torch.tanh(_forward(layers, obs)[2]) * A_MAX


def _critic_input(obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    return torch.cat([obs, action / A_MAX], dim=1)
