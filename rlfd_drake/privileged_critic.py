"""PPO's actor-critic with a privileged critic (an asymmetric actor-critic).

Pinto et al., "Asymmetric Actor Critic for Image-Based Robot Learning" (RSS 2018): in
simulation the critic may read the true state, here the part's pose relative to the
fixture's true goal and the fixture's calibration error (``env.PrivilegedObservation``
appends them to the observation), while the actor reads only the robot's observation.
Only the critic's value estimates, hence PPO's advantages, use them; the trained actor
runs in the diagram on the 26 observed entries (``policies.DeployedPolicy`` pads the
privileged ones with zeros, which the actor multiplies by zero). A deviation from the
paper's PPO, whose critic reads what the actor reads.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.policies import ActorCriticPolicy

from rlfd_drake.observation_scaling import ScaledObservation
from rlfd_drake.systems.observer import OBSERVATION_SIZE

#: ActorCriticPolicy's arguments that PrivilegedCriticPolicy sets itself.
_SET_HERE = ("share_features_extractor", "features_extractor_class", "features_extractor_kwargs")


class PrivilegedCriticPolicy(ActorCriticPolicy):
    """An MLP actor-critic with separate input layers: the critic's reads the whole
    observation (the stacked observation, then ``privileged_size`` privileged
    entries), the actor's the same with the privileged entries zeroed.

    Args (besides ActorCriticPolicy's; ``share_features_extractor`` and the features
    extractor are set here):
        privileged_size: entries appended to the observation for the critic (>= 1).
        observation_scales: (26,) fixed input scales (``observation_scaling``), or None
            for the observation as is.
    """

    def __init__(
        self,
        observation_space,
        action_space,
        lr_schedule,
        privileged_size: int,
        observation_scales=None,
        **kwargs,
    ):
        if not (isinstance(privileged_size, int) and privileged_size >= 1):
            raise ValueError(f"privileged_size must be an integer >= 1, got {privileged_size!r}")
        for name in _SET_HERE:
            if name in kwargs:
                raise ValueError(f"{name} is set by PrivilegedCriticPolicy, got {kwargs[name]!r}")
        scales = (
            tuple(np.ones(OBSERVATION_SIZE)) if observation_scales is None else observation_scales
        )
        reading = dict(scales=scales, privileged_size=privileged_size)
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            share_features_extractor=False,
            features_extractor_class=ScaledObservation,
            features_extractor_kwargs=reading,
            **kwargs,
        )
        # The actor's input layer: the same scales, the privileged entries zeroed. No
        # trainable parameters, so the optimiser built above is unaffected.
        actor_reading = ScaledObservation(observation_space, hide_privileged=True, **reading)
        self.features_extractor = self.pi_features_extractor = actor_reading
        self.privileged_size = privileged_size
        self.observation_scales = observation_scales

    @property
    def actor_observation_size(self) -> int:
        """Entries the actor reads: the observation without the privileged ones."""
        return int(self.observation_space.shape[0]) - self.privileged_size

    def _get_constructor_parameters(self) -> dict:
        data = super()._get_constructor_parameters()
        for name in _SET_HERE:
            data.pop(name, None)
        data.update(
            privileged_size=self.privileged_size, observation_scales=self.observation_scales
        )
        return data
