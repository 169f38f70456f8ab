"""Several independent DDPG runs trained in lockstep as one batched ensemble.

Member r starts exactly as ``DDPG(config, seeds[r])`` (the same initial networks, replay
generator and exploration noise) and learns only from its own transitions. The weights of all
members are stacked along a first dimension and applied with batched matrix products; the loss
is the sum over members of each member's own mean loss, so each member's gradient, its Adam
step (element-wise) and its soft update are those of the unbatched run. Batched arithmetic may
round differently, so results equal the unbatched path within rounding, not bit for bit.

The update is written out rather than left to autograd and ``torch.optim.Adam``: the gradients
by hand, with the operations autograd's backward pass runs (``tests/client/test_ensemble.py``
checks that they agree bit for bit), and every weight, gradient and Adam moment of the ensemble
in one flat buffer (:mod:`client.agents.flat`), so that Adam and the soft target update are a
few kernels over all layers instead of a few per layer. On the CPU, where these small networks
cost more in calls than in arithmetic, that makes ten members' update about 1.4-1.5 times as
fast (``bench/learner_versions.py``); subnormal numbers are flushed to zero while updating,
which gained DDPG alone in the paper's protocol another 2-22% (BENCHMARKS.md).

On a CUDA device the whole update (both losses, both backward passes, both Adam steps and the
soft update) is captured once as a CUDA graph and replayed: a few hundred kernels for every
member at the cost of one launch, which is what makes the paper's 18 million updates fit in
minutes on one GPU.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

from client.agents.ddpg import A_MAX, DDPG, TRANSITION, DDPGConfig
from client.agents.flat import adam_step, subnormals_flushed, views

Params = list[torch.Tensor]  # W1, b1, W2, b2, W3, b3, each with a leading member dimension
EAGER_UPDATES = 3  # updates run eagerly (on a side stream) before a CUDA graph is captured


def _stack(modules: Sequence[nn.Module]) -> Params:
    """The linear layers of each member's network, stacked: weights as [R, in, out] (so that
    x @ W is the layer), biases as [R, 1, out]."""
    layers = [[m for m in module.modules() if isinstance(m, nn.Linear)] for module in modules]
    params: Params = []
    for depth in range(len(layers[0])):
        for part in ("weight", "bias"):
            rows = [getattr(member[depth], part).detach() for member in layers]
            params.append(torch.stack([r.T if part == "weight" else r[None] for r in rows]))
    return params


def _forward(params: Params, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The MLP's two hidden activations and its output."""
    h1 = torch.relu(torch.baddbmm(params[1], x, params[0]))
    h2 = torch.relu(torch.baddbmm(params[3], h1, params[2]))
    return h1, h2, torch.baddbmm(params[5], h2, params[4])


def _backward(
    params: Params,
    x: torch.Tensor,
    h1: torch.Tensor,
    h2: torch.Tensor,
    grad_out: torch.Tensor,
    grads: Params | None,
) -> torch.Tensor:
    """Back-propagate ``grad_out`` through the MLP of :func:`_forward`, writing the gradients
    of its weights into ``grads`` where given; returns the gradient at the first layer's
    output (before its relu), from which the caller gets the input's.

    The operations of autograd's backward of ``baddbmm`` and ``relu``: for ``x @ W + b``,
    ``dW = x^T g``, ``db`` the sum of ``g`` over the batch, ``dx = g W^T``; ``relu`` passes
    the gradient where its output is positive.
    """
    relu_backward = torch.ops.aten.threshold_backward
    g2 = relu_backward(grad_out.bmm(params[4].transpose(1, 2)), h2, 0)
    g1: torch.Tensor = relu_backward(g2.bmm(params[2].transpose(1, 2)), h1, 0)
    if grads is not None:
        for (w, b), inputs, g in zip(
            ((4, 5), (2, 3), (0, 1)), (h2, h1, x), (grad_out, g2, g1), strict=True
        ):
            torch.bmm(inputs.transpose(1, 2), g, out=grads[w])
            torch.sum(g, dim=1, keepdim=True, out=grads[b])
    return g1


def _mu(actor: Params, obs: torch.Tensor) -> torch.Tensor:
    return torch.tanh(_forward(actor, obs)[2]) * A_MAX


def _critic_input(obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    return torch.cat([obs, action / A_MAX], dim=2)


class DDPGEnsemble:
    """R DDPG learners, one per run, updated together on ``device`` ("cpu" or "cuda")."""

    def __init__(self, config: DDPGConfig, seeds: Sequence[int], device: str = "cpu") -> None:
        self.config = config
        self.device = torch.device(device)
        self.members = [DDPG(config, seed) for seed in seeds]
        actor, critic = (
            _stack([m.actor for m in self.members]),
            _stack([m.critic for m in self.members]),
        )
        targets = [
            *_stack([m.actor_target for m in self.members]),
            *_stack([m.critic_target for m in self.members]),
        ]
        self._shapes = [p.shape for p in [*actor, *critic]]
        # every flat buffer holds the actor's layers, then the critic's
        self._online = self._flat([*actor, *critic])
        self._target = self._flat(targets)
        # Adam's first and second moments, and its step count of the actor and of the critic
        self._moments = torch.zeros(2, self._online.numel(), device=self.device)
        self._grad = torch.zeros_like(self._online)
        self._steps = torch.zeros(2, device=self.device)
        self._bind()
        self._prepare()

    def _flat(self, params: Params) -> torch.Tensor:
        return torch.cat([p.reshape(-1) for p in params]).to(self.device)

    def _bind(self) -> None:
        """The layers as views of the flat buffers: what the update reads and writes."""
        layers = len(self._shapes) // 2
        online, target = views(self._online, self._shapes), views(self._target, self._shapes)
        grad = views(self._grad, self._shapes)
        self.actor, self.critic = online[:layers], online[layers:]
        self.actor_target, self.critic_target = target[:layers], target[layers:]
        self._actor_grad, self._critic_grad = grad[:layers], grad[layers:]
        split = sum(math.prod(s) for s in self._shapes[:layers])
        self._parts = [slice(0, split), slice(split, None)]  # the actor's and the critic's

    def _adam(self, network: int, lr: float) -> None:
        """One Adam step of the actor (0) or the critic (1), over the network's share of the
        flat buffers."""
        part = self._parts[network]
        adam_step(
            self._online[part],
            self._grad[part],
            self._moments[:, part],
            self._steps[network],
            lr,
            capturable=self.device.type == "cuda",
        )

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

        def rows(flat: torch.Tensor) -> torch.Tensor:
            return torch.cat([v[index].reshape(-1) for v in views(flat, self._shapes)])

        self._online, self._target = rows(self._online), rows(self._target)
        self._moments = torch.stack([rows(m) for m in self._moments])
        self._grad = torch.zeros_like(self._online)
        self._shapes = [torch.Size((len(members), *s[1:])) for s in self._shapes]
        self.members = [self.members[i] for i in members]
        self._bind()
        self._prepare()

    def state(self) -> dict[str, Any]:
        """Everything the members have learned and drawn so far (networks, targets, Adam
        moments and counts, replay memories, exploration noise), on the CPU: :meth:`restore`
        on an ensemble of the same members continues exactly from here."""
        return {
            "online": self._online.cpu().clone(),
            "target": self._target.cpu().clone(),
            "moments": self._moments.cpu().clone(),
            "steps": self._steps.cpu().clone(),
            "memories": [m.buffer.state() for m in self.members],
            "noises": [m.noise.state() for m in self.members],
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state`."""
        if len(state["memories"]) != len(self.members):
            raise ValueError(
                f"a state of {len(state['memories'])} members, not {len(self.members)}"
            )
        for mine, saved in (
            (self._online, "online"),
            (self._target, "target"),
            (self._moments, "moments"),
            (self._steps, "steps"),
        ):
            mine.copy_(state[saved])
        for member, memory, noise in zip(
            self.members, state["memories"], state["noises"], strict=True
        ):
            member.buffer.restore(memory)
            member.noise.restore(noise)
        self._prepare()

    def act(self, observations: npt.NDArray[np.float32], explore: bool = True) -> list[float]:
        """mu(z-bar) + N_OU for every member, clipped to [-2, 2]; one row of obs per member."""
        scaled = np.stack([DDPG.scale(o) for o in observations])[:, None, :]
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
            with subnormals_flushed():
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
            graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(graph):  # recorded, not run: the replay below runs it
                self._step()
            self._graph = graph
            graph.replay()

    def _step(self) -> None:
        cfg, batch = self.config, self._batch
        obs, action, reward = batch[..., 0:4], batch[..., 4:5], batch[..., 5:6]
        next_obs, done = batch[..., 6:10], batch[..., 10:11]
        size = 1.0 / cfg.batch_size  # each member's loss is a mean over its batch
        # critic: minimise the mean of (Q(z, a) - y)^2, y = r + gamma (1 - done) Q'(z', mu'(z'))
        next_q = _forward(
            self.critic_target, _critic_input(next_obs, _mu(self.actor_target, next_obs))
        )[2]
        target = reward + cfg.gamma * (1.0 - done) * next_q
        x = _critic_input(obs, action)
        h1, h2, q = _forward(self.critic, x)
        _backward(self.critic, x, h1, h2, (q - target) * 2 * size, self._critic_grad)
        self._adam(1, cfg.critic_lr)
        # actor: maximise the mean of Q(z, mu(z)), through the critic just updated
        a1, a2, out = _forward(self.actor, obs)
        squashed = torch.tanh(out)
        x = _critic_input(obs, squashed * A_MAX)
        h1, h2, q = _forward(self.critic, x)
        g1 = _backward(self.critic, x, h1, h2, torch.full_like(q, -size), None)
        grad_x = g1.bmm(self.critic[0].transpose(1, 2))
        # back through the critic's input (action / A_MAX) and mu's output (tanh * A_MAX),
        # each step as autograd takes it, though the two scalings cancel
        grad_action = grad_x[..., 4:5] / A_MAX
        grad_out = torch.ops.aten.tanh_backward(grad_action * A_MAX, squashed)
        _backward(self.actor, obs, a1, a2, grad_out, self._actor_grad)
        self._adam(0, cfg.actor_lr)
        # soft update: theta' <- theta' + tau (theta - theta')
        self._target.lerp_(self._online, cfg.tau)
