"""A fixed input layer that rescales the observation for the networks.

The Observer's units (see ``systems/observer.py``) suit the whole approach: 2 cm of
position and 5 N m of wrist torque per unit. In contact, the features that tell a
residual which way the hole lies are small in those units: the lateral position error
(a 3 mm fixture error is 0.15) and the wrist torque of a part resting on the entrance
(about 1 N m, i.e. 0.2), against a vertical force of -1.6 and a height of 2-3. A
network's first layer starts with weights of the same size for all of them, so these
features start with a tenth of the influence. ``CONTACT_SCALES`` multiplies them to
order one, inside the network, so the env's observation (and every policy trained on
it before) stays as it was.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from rlfd_drake.systems.observer import OBSERVATION_SIZE, OBSERVATION_WRIST_TORQUE

#: Multipliers of the 26 observation entries (layout: ``systems/observer.py``), giving
#: per unit: 4 mm of lateral position, 2 cm of height, 0.2 rad of orientation error,
#: 1 N m of wrist torque, 20 N of wrist force; velocities, phase, time and the last
#: residual keep their units.
CONTACT_SCALES: tuple[float, ...] = (
    (5.0, 5.0, 1.0)  # position error x, y, z
    + (5.0, 5.0, 5.0)  # orientation error
    + (1.0, 1.0, 1.0)  # angular velocity
    + (1.0, 1.0, 1.0)  # linear velocity
    + (5.0, 5.0, 5.0)  # wrist torque
    + (2.5, 2.5, 2.5)  # wrist force
    + (1.0, 1.0)  # phase, time
    + (1.0,) * 6  # last residual
)


#: Wrist torque per unit inside the network with ``CONTACT_SCALES``, N m.
CONTACT_TORQUE_PER_UNIT_NM = 1.0


def contact_scales(torque_per_unit_nm: float = CONTACT_TORQUE_PER_UNIT_NM) -> tuple[float, ...]:
    """``CONTACT_SCALES`` with the wrist torque brought to ``torque_per_unit_nm`` per unit.

    A part's torque on the wrist when it rests on the entrance grows with its size: about
    1 N m for the 28 mm peg, 0.03-0.1 N m for the 10 g RJ-45 plug (25 N at 1-3 mm off
    centre), a twentieth of a unit at the default scale.

    Raises:
        ValueError: ``torque_per_unit_nm`` is not a positive finite number.
    """
    if not (np.isfinite(torque_per_unit_nm) and torque_per_unit_nm > 0):
        raise ValueError(f"torque_per_unit_nm must be a positive number, got {torque_per_unit_nm}")
    factor = CONTACT_TORQUE_PER_UNIT_NM / float(torque_per_unit_nm)
    scales = list(CONTACT_SCALES)
    for i in range(OBSERVATION_WRIST_TORQUE.start, OBSERVATION_WRIST_TORQUE.stop):
        scales[i] *= factor
    return tuple(scales)


def check_hidden_entries(hidden) -> tuple[int, ...]:
    """``hidden`` as a tuple of distinct observation indices in [0, 26), or a ValueError
    naming it."""
    # A bare number or string is one entry, not a sequence of them.
    iterable = hasattr(hidden, "__iter__") and not isinstance(hidden, (str, bytes))
    entries = tuple(hidden) if iterable else (hidden,)
    if not all(
        isinstance(i, (int, np.integer)) and not isinstance(i, bool) and 0 <= i < OBSERVATION_SIZE
        for i in entries
    ) or len(set(entries)) != len(entries):
        raise ValueError(
            f"hidden observation entries must be distinct integers in [0, {OBSERVATION_SIZE}), "
            f"got {hidden!r}"
        )
    return tuple(int(i) for i in entries)


class ScaledObservation(BaseFeaturesExtractor):
    """Multiplies each observation entry by a fixed scale (no trainable parameters).

    Works on a frame-stacked observation (``VecFrameStack``: newest last) by repeating
    the per-step scales over the stack. ``privileged_size`` entries appended after the
    stack (``env.PrivilegedObservation``, for a critic) keep their units, or are
    zeroed with ``hide_privileged`` (the actor's reading of the same observation).
    ``hidden`` entries of each observation (indices into the 26, every stacked step) are
    zeroed: the networks do not read them, in training or where the policy runs.

    Raises:
        ValueError: the space is not a flat Box whose size less ``privileged_size`` is a
            multiple of the scales', a scale is not a positive finite number, or a hidden
            entry is not a distinct index of the observation.
    """

    def __init__(
        self,
        observation_space: gym.spaces.Box,
        scales=CONTACT_SCALES,
        privileged_size: int = 0,
        hide_privileged: bool = False,
        hidden: tuple[int, ...] = (),
    ):
        if not isinstance(observation_space, gym.spaces.Box) or len(observation_space.shape) != 1:
            raise ValueError(f"observation_space must be a flat Box, got {observation_space}")
        size = int(observation_space.shape[0])
        if not (isinstance(privileged_size, int) and 0 <= privileged_size < size):
            raise ValueError(
                f"privileged_size must be an integer in [0, {size}), got {privileged_size!r}"
            )
        stacked = size - privileged_size
        per_step = np.asarray(scales, dtype=np.float32).reshape(-1)
        if per_step.size != OBSERVATION_SIZE or stacked % per_step.size:
            raise ValueError(
                f"scales must have {OBSERVATION_SIZE} entries dividing the observation "
                f"size {stacked}, got {per_step.size}"
            )
        if not (np.all(np.isfinite(per_step)) and np.all(per_step > 0)):
            raise ValueError(f"scales must be positive finite numbers, got {per_step.tolist()}")
        hidden = check_hidden_entries(hidden)
        per_step = per_step.copy()
        per_step[list(hidden)] = 0.0
        super().__init__(observation_space, features_dim=size)
        tail = np.full(privileged_size, 0.0 if hide_privileged else 1.0, np.float32)
        all_scales = np.concatenate([np.tile(per_step, stacked // per_step.size), tail])
        self.register_buffer("scales", torch.as_tensor(all_scales))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return observations.flatten(start_dim=1) * self.scales
