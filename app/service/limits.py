"""What a model of this server may be: bounds on the sizes of a configuration, so that no
caller can make a model whose tables exhaust the server's memory or whose step takes seconds.

The core bounds every configuration on its own (:mod:`app.core.config`); a server allows less:
the states, action bins and observation dimensions of a model, and the memory its tables take
once it holds ``limits.max_states`` states and ``limits.max_streams`` streams
(:func:`table_bytes`). A configuration beyond them is refused with :class:`InvalidConfig`
naming the field to lower, on creation and on restore alike.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.core import InvalidConfig, ShieldConfig, reach

STREAM_OVERHEAD = 1024  # [bytes] a stream's Python objects beside its arrays (a generous guess)


@dataclass(frozen=True)
class ModelLimits:
    """A server's bounds on the configuration of each of its models."""

    max_states: int = 100_000  # limits.max_states
    max_action_bins: int = 256  # q, the action's bins
    max_dimensions: int = 64  # observation names and features together
    max_model_bytes: int = 256 * 2**20  # table_bytes at the model's limits

    def check(self, config: ShieldConfig) -> None:
        """Refuse a configuration beyond these bounds, naming the field to lower."""
        spec = config.observation
        checks = (
            (
                config.limits.max_states <= self.max_states,
                "limits.max_states",
                f"this server allows at most {self.max_states} states a model",
            ),
            (
                config.action.n_bins <= self.max_action_bins,
                "action.step",
                f"this server allows at most {self.max_action_bins} action bins a model "
                f"(this range and step make {config.action.n_bins})",
            ),
            (
                spec.size + len(spec.features) <= self.max_dimensions,
                "observation.names",
                f"this server allows at most {self.max_dimensions} observation names and "
                "features together",
            ),
        )
        for ok, field, message in checks:
            if not ok:
                raise InvalidConfig(message, field=field)
        needed = table_bytes(config)
        if needed > self.max_model_bytes:
            raise InvalidConfig(
                f"a model of this configuration holds up to {needed / 2**20:.0f} MiB of tables "
                f"at its limits.max_states and limits.max_streams; this server allows "
                f"{self.max_model_bytes / 2**20:.0f} MiB a model: lower limits.max_states (or "
                "limits.max_streams, the action bins, the dimensions)",
                field="limits.max_states",
            )


def table_bytes(config: ShieldConfig) -> int:
    """The memory [bytes] of a model's tables once it holds ``limits.max_states`` states and
    ``limits.max_streams`` streams: the arrays each part of the core keeps per state and per
    stream (tests/service/test_limits.py holds it above a full model's). Not counted: the
    lazy matrices' learned entries, which grow with what is learned (about
    ``belief_top_k`` squared a step at most, far fewer once the rows are known)."""
    n, s = config.limits.max_states, config.limits.max_streams
    q, c, k = config.action.n_bins, len(config.criteria), config.limits.belief_top_k
    spec = config.observation
    d = spec.size * spec.cluster_raw + len(spec.features)  # the clustering space
    per_state = d + 6  # clustering: centre, five numbers, support
    per_state += 3 + c  # flags: flag, visits, entries, failures per criterion
    per_stream = 2 * k + d  # the previous step's belief and observation
    if config.limits.tpm_backend == "dense":
        per_state += 2 * q * (n + 1)  # P and F_o; a new state copies them once
    else:
        per_state += 12 * q + 1  # per row: created, padding, scales, counts; scratch
    fixed = 4 * q + 256  # per action and per model: decays, midpoints, extents
    if config.reviser.method == "risk":
        m = d + 2  # [1, z, u]
        # weights, two covariances, tries, boxes per bin, dynamics
        per_state += c * m + 2 * m * m + q + 2 * q * d + d * m
        per_stream += (config.risk.horizon + 1) * (2 * k + m) + 2  # the unlabelled steps
        fixed += c * reach.MAX_POINTS * d  # failure points
    return 8 * (n * per_state + s * per_stream + fixed) + s * STREAM_OVERHEAD
