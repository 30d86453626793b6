"""The paper's Random baseline: uniform random residual corrections in task space
(Davchev et al. 2022, Tables II and IV), and the zero residual.

Both are residual policies: callables ``obs (n,) -> action (6,)`` in [-1, 1], the
action being a translation (0:3) and a rotation vector (3:6), scaled to physical
units by the diagram's ResidualComposer.
"""

from __future__ import annotations

import numpy as np

from rlfd_drake.diagram import RESIDUAL_SIZE

__all__ = ["RandomResidualPolicy", "ZeroPolicy"]


class RandomResidualPolicy:
    """Uniform random corrections in [-1, 1] on the selected parts of the residual.

    Args:
        seed: seed of the policy's own generator (numpy PCG64).
        translation: randomise the translation part (0:3); zeros otherwise.
        orientation: randomise the rotation part (3:6); zeros otherwise.

    Table IV's combinations: translation only (Random / None), orientation only
    (e.g. Linear / Random with the Linear policy on translation), both
    (Random / Random). Each call draws a fresh action; ``reset()`` (called by the
    diagram at every initialisation) does not reseed, so successive episodes see
    different draws; build a new policy with a new seed per episode for episode-level
    reproducibility.
    """

    def __init__(self, seed: int, translation: bool = True, orientation: bool = True):
        self.seed = seed
        self.translation = translation
        self.orientation = orientation
        self._rng = np.random.default_rng(seed)
        self._mask = np.zeros(RESIDUAL_SIZE)
        self._mask[0:3] = 1.0 if translation else 0.0
        self._mask[3:6] = 1.0 if orientation else 0.0

    def reset(self) -> None:
        """Start of an episode: nothing to reset (the generator keeps its stream)."""

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """A random action (6,) in [-1, 1]; ``observation`` is ignored."""
        return self._rng.uniform(-1.0, 1.0, size=RESIDUAL_SIZE) * self._mask

    def __repr__(self) -> str:
        return (
            f"RandomResidualPolicy(seed={self.seed}, translation={self.translation}, "
            f"orientation={self.orientation})"
        )


class ZeroPolicy:
    """The zero residual (the DMP alone) as a policy object: always zeros (6,)."""

    def reset(self) -> None:
        """Stateless."""

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """Zeros (6,); ``observation`` is ignored."""
        return np.zeros(RESIDUAL_SIZE)

    def __repr__(self) -> str:
        return "ZeroPolicy()"
