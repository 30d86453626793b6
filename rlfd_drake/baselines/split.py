"""Table IV's "translation policy / orientation policy" rows: one policy's translation
with another's rotation (e.g. Linear / Random)."""

from __future__ import annotations

import numpy as np

from rlfd_drake.diagram import RESIDUAL_SIZE

__all__ = ["SplitResidualPolicy"]


class SplitResidualPolicy:
    """The residual ``[translation(obs)[0:3], orientation(obs)[3:6]]``.

    Args:
        translation, orientation: residual policies ``obs (n,) -> action (6,)``, or None
            for no correction of that part. ``reset()`` resets both.
    """

    def __init__(self, translation, orientation):
        self.translation = translation
        self.orientation = orientation

    def reset(self) -> None:
        for part in (self.translation, self.orientation):
            reset = getattr(part, "reset", None)
            if callable(reset):
                reset()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        action = np.zeros(RESIDUAL_SIZE)
        if self.translation is not None:
            action[0:3] = np.asarray(self.translation(observation), dtype=float).reshape(-1)[0:3]
        if self.orientation is not None:
            action[3:6] = np.asarray(self.orientation(observation), dtype=float).reshape(-1)[3:6]
        return action

    def __repr__(self) -> str:
        return f"SplitResidualPolicy({self.translation!r}, {self.orientation!r})"
