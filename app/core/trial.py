"""The shield's trial of itself: episodes it shields against episodes it leaves to the
controller, so that turning it on cannot make the controller fail more often for long.

The shield's record (:mod:`app.core.record`) compares its revised steps with the proposals it
passed. That cannot see every harm: it revises the riskier steps, a step's outcome depends on
every step after it, and where it revises nearly every step there is nothing to compare with.
What a user asks is simpler: does an episode fail more often with the shield than without it?
The trial asks that directly.

At the start of each episode (once a failure was learned and an episode has ended) the shield
draws whether to act in it or to **audit** it, passing every proposal (``reason: "audit"``, the
revision it would have made in ``suggested``). Per arm it counts the episodes and those in which
any failure happened, and draws by Thompson sampling: one draw from each arm's posterior failure
rate (a Beta distribution from a uniform prior), auditing when the audited arm's draw is the
lower. The steps of an audited episode are the trial's, kept out of the record. Where the shield
helps, audits become rare as the evidence grows (about the logarithm of the episodes, the fewer
the farther apart the arms are); where it harms, it audits nearly every episode, and an audited
episode is the controller's own.

Every draw is a function of the configuration's seed and the model's step count, so a model
decides the same for the same input, also after a snapshot. An audit that lasts more than
:data:`LONGEST` times the mean episode length ends, uncounted: a stream whose episodes rarely
end is not left unshielded.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core.errors import InvalidSnapshot

NONE, SHIELDED, AUDITED = -1, 0, 1  # an episode's arm (NONE: not in the trial)
ARMS = ("shielded", "audited")
COLUMNS = ("episodes", "failed")
LONGEST = 2.0  # an audit ends, uncounted, after this many times the mean episode length


class Trial:
    """Per arm (:data:`ARMS`) the episodes counted and those that failed (:data:`COLUMNS`)."""

    def __init__(self, seed: int) -> None:
        self.seed = seed
        self.counts = np.zeros((len(ARMS), len(COLUMNS)), dtype=np.int64)

    def draw(self, at: int) -> int:
        """The arm of an episode starting at the model's step ``at``: :data:`AUDITED` when a
        draw from the audited episodes' posterior failure rate is below one from the shielded
        episodes'."""
        rng = np.random.default_rng((self.seed, at))
        (shielded, shielded_failed), (audited, audited_failed) = self.counts.tolist()
        rate_shielded = rng.beta(1 + shielded_failed, 1 + shielded - shielded_failed)
        rate_audited = rng.beta(1 + audited_failed, 1 + audited - audited_failed)
        return AUDITED if rate_audited < rate_shielded else SHIELDED

    def count(self, arm: int, failed: bool) -> None:
        """An episode of ``arm`` ended, with a failure in it (``failed``) or not."""
        if arm != NONE:
            self.counts[arm, 0] += 1
            self.counts[arm, 1] += failed

    def view(self) -> dict[str, dict[str, int]]:
        """The counts by arm, as plain data."""
        return {
            arm: dict(zip(COLUMNS, row, strict=True))
            for arm, row in zip(ARMS, self.counts.tolist(), strict=True)
        }

    def snapshot(self) -> npt.NDArray[np.int64]:
        return self.counts.copy()

    @classmethod
    def restore(cls, seed: int, data: Any, episodes: int) -> Trial:
        """Rebuild from :meth:`snapshot` output (None, a snapshot from before the trial:
        nothing counted), no more episodes counted than the model's ``episodes``."""
        self = cls(seed)
        if data is None:
            return self
        counts = stored.ints(data, "trial", self.counts.shape, low=0, high=episodes)
        if (counts[:, 1] > counts[:, 0]).any():
            raise InvalidSnapshot("more failed episodes than episodes in an arm", field="trial")
        if counts[:, 0].sum() > episodes:
            raise InvalidSnapshot("more episodes in the trial than the model's", field="trial")
        self.counts = counts.copy()
        return self
