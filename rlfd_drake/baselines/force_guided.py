"""A hand-written force-guided search: a reference for what the observation allows.

Not one of the paper's baselines. It answers a question the RL numbers raise: can a
residual that only sees the Observer's 26 numbers find a hole the DMP misses? When
the part is pressed onto the fixture (the wrist feels more than ``contact_force_n``
downward), the rule lifts the set-point by ``lift`` of the residual's range, to
unload the friction that holds the part, and pushes sideways with ``push`` of the
range away from the centre of pressure, where the part rests on the entrance: the
hole is on the other side.

The Observer reports the load the part puts on the wrist (pressing down: F_z < 0).
For a vertical load F = (0, 0, F_z) whose centre of pressure lies at r from the wrist,
tau = r x F = (r_y F_z, -r_x F_z, 0), so (-tau_y, tau_x) = F_z r_xy points from the
centre of pressure across the part (F_z < 0): toward the hole.

A part with a hole that goes onto a shaft (the gear) is the mirror image: it rests on
the shaft's top where the two overlap, so the shaft lies on the centre of pressure's
side and the search must push toward it (``toward_pressure``). The one direction that
helps one kind of task is the one that hurts the other (``results/full_pose_study.md``,
section 32).
"""

from __future__ import annotations

import numpy as np

from rlfd_drake.diagram import RESIDUAL_SIZE
from rlfd_drake.systems.observer import (
    OBSERVATION_WRIST_FORCE,
    OBSERVATION_WRIST_TORQUE,
    ObserverConfig,
)

__all__ = ["ForceGuidedSearch"]


class ForceGuidedSearch:
    """obs (26,) -> residual (6,): translation only, zero until contact.

    Args:
        contact_force_n: downward wrist force that counts as resting on the fixture, N.
        min_torque_nm: lateral torque below which the direction is not trusted, N m
            (the part is centred, or not yet loaded): lift only.
        lift: upward residual while in contact, in [0, 1] of the residual's range.
        push: sideways residual while in contact, in [0, 1] of the residual's range.
        toward_pressure: push toward the centre of pressure instead of away from it
            (a hole going onto a shaft rather than a part going into a hole).
        observer: the Observer's units (to read the wrench in N and N m); None = defaults.

    Raises:
        ValueError: a threshold is not a positive number, or ``lift``/``push`` is
            outside [0, 1].
    """

    def __init__(
        self,
        contact_force_n: float = 10.0,
        min_torque_nm: float = 0.05,
        lift: float = 1.0,
        push: float = 1.0,
        toward_pressure: bool = False,
        observer: ObserverConfig | None = None,
    ):
        for name, value in (("contact_force_n", contact_force_n), ("min_torque_nm", min_torque_nm)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        for name, value in (("lift", lift), ("push", push)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value}")
        self.contact_force_n = float(contact_force_n)
        self.min_torque_nm = float(min_torque_nm)
        self.lift = float(lift)
        self.push = float(push)
        self.toward_pressure = bool(toward_pressure)
        observer = observer if observer is not None else ObserverConfig()
        self._torque_scale = observer.torque_scale_Nm
        self._force_scale = observer.force_scale_N

    def reset(self) -> None:
        """Stateless."""

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        obs = np.asarray(observation, dtype=float).reshape(-1)
        torque = obs[OBSERVATION_WRIST_TORQUE] * self._torque_scale
        force = obs[OBSERVATION_WRIST_FORCE] * self._force_scale
        action = np.zeros(RESIDUAL_SIZE)
        if -force[2] < self.contact_force_n:
            return action
        action[2] = self.lift
        across = np.array([-torque[1], torque[0]])
        size = float(np.linalg.norm(across))
        if size >= self.min_torque_nm:
            push = -self.push if self.toward_pressure else self.push
            action[0:2] = (push / size) * across
        return action

    def __repr__(self) -> str:
        return (
            f"ForceGuidedSearch(contact_force_n={self.contact_force_n}, "
            f"min_torque_nm={self.min_torque_nm}, lift={self.lift}, push={self.push}, "
            f"toward_pressure={self.toward_pressure})"
        )
