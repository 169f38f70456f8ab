"""Networks laid out in flat buffers, and the optimiser step over them.

Both learners (:class:`~client.agents.ddpg.DDPG` and the lockstep
:class:`~client.agents.ensemble.DDPGEnsemble`) keep every weight, gradient and Adam moment
in one flat tensor each, the layers being views of it: Adam and the soft target update are
then a few kernels over all layers instead of a few per layer, which is most of their cost
for the small networks of the paper on a CPU.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Sequence

import torch
from torch.optim.adam import adam

BETAS, EPS = (0.9, 0.999), 1e-8  # torch.optim.Adam's defaults, which DDPG keeps


def views(flat: torch.Tensor, shapes: Sequence[torch.Size]) -> list[torch.Tensor]:
    """Tensors of these shapes laid one after another in ``flat``, as views of it."""
    out, start = [], 0
    for shape in shapes:
        size = math.prod(shape)
        out.append(flat[start : start + size].view(shape))
        start += size
    return out


def adam_step(
    online: torch.Tensor,
    grad: torch.Tensor,
    moments: torch.Tensor,
    step: torch.Tensor,
    lr: float,
    capturable: bool = False,
) -> None:
    """One step of ``torch.optim.Adam`` (its arithmetic, through its functional form) of the
    weights ``online``: ``moments`` holds Adam's first and second moments as two rows,
    ``step`` its step count (a one-element tensor, counted here)."""
    adam(
        [online],
        [grad],
        [moments[0]],
        [moments[1]],
        [],
        [step],
        foreach=True,
        capturable=capturable,
        amsgrad=False,
        beta1=BETAS[0],
        beta2=BETAS[1],
        lr=lr,
        weight_decay=0.0,
        eps=EPS,
        maximize=False,
    )


@contextlib.contextmanager
def subnormals_flushed() -> Iterator[None]:
    """Subnormal numbers read and written as zero on the CPU, inside the block.

    Adam's moments of units that stopped learning decay into subnormals, whose arithmetic
    costs the CPU many times a normal number's; flushed to zero while updating, they changed
    no weight in any test or run compared (``tests/client/test_ensemble.py``, BENCHMARKS.md).
    """
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(False)
