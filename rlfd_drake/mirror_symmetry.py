"""PPO's actor-critic made mirror-symmetric across the world's x-z plane (y -> -y).

Why: the peg's from-zero policies leave their failed starts on one or two sides of the
hole, a different side for each training seed (``results/full_pose_study.md`` section
56): each seed learns to search in the directions its own episodes happened to reward.
The tasks are symmetric across the vertical plane through the robot's base and the
fixture: the Panda's kinematic chain is (its link offsets lie in x and z), the fixture
sits on that plane, the table's slope turns about y (a turn about the mirror's normal
is its own mirror image) and the fixture errors are drawn symmetrically. A policy that
searches correctly toward +y should then search toward -y as the mirror image.

The policy is made exactly symmetric by averaging over the two-element group {identity,
mirror} (symmetrisation; a soft version of the same constraint is the mirror loss of Yu,
Turk and Liu, "Learning Symmetric and Low-Energy Locomotion", SIGGRAPH 2018):

    mean(s)  = (f(s) + A f(O s)) / 2        so  mean(O s) = A mean(s)
    value(s) = (v(s) + v(O s)) / 2          so  value(O s) = value(s)

with O and A the sign flips the mirror makes on the observation and on the action. In
world coordinates the mirror M = diag(1, -1, 1) maps a polar vector (position,
velocity, force, translation) to M x, and an axial vector (rotation vector, angular
velocity, torque) to det(M) M x = -M x: x and z flip, y stays. Every experience thus
trains the policy for its mirror image too. What it cannot do: act on a difference
between the two sides, e.g. the demonstration's own path (the peg's demonstration starts
6 cm off the plane with a 20 deg yaw), which the DMP follows with no residual needed.
A deviation from the paper's PPO.
"""

from __future__ import annotations

import numpy as np
import torch
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy

from rlfd_drake.control_math import RESIDUAL_PARTS
from rlfd_drake.systems.observer import OBSERVATION_SIZE

#: Sign flips of the mirror y -> -y on a polar vector (position, velocity, force).
POLAR_SIGNS = (1.0, -1.0, 1.0)
#: ... and on an axial vector (rotation vector, angular velocity, torque): -M.
AXIAL_SIGNS = (-1.0, 1.0, -1.0)


def observation_mirror_signs(history: int = 1) -> tuple[float, ...]:
    """The mirror's sign on each entry of the observation (layout:
    ``systems/observer.py``), repeated over ``history`` stacked observations."""
    if not (isinstance(history, (int, np.integer)) and history >= 1):
        raise ValueError(f"history must be an integer >= 1, got {history!r}")
    one = (
        POLAR_SIGNS  # position error
        + AXIAL_SIGNS  # orientation error (rotation vector)
        + AXIAL_SIGNS  # angular velocity
        + POLAR_SIGNS  # linear velocity
        + AXIAL_SIGNS  # wrist torque
        + POLAR_SIGNS  # wrist force
        + (1.0, 1.0)  # phase, time
        + action_mirror_signs("full")  # the residual input (the action's layout)
    )
    assert len(one) == OBSERVATION_SIZE
    return one * int(history)


def action_mirror_signs(residual_mode: str, applied_action_only: bool = False) -> tuple[float, ...]:
    """The mirror's sign on each entry of the action: the 6-D residual [dp; rotation
    vector] (world), or only its applied 3-D part (``applied_action_only``)."""
    if residual_mode not in ("full", *RESIDUAL_PARTS):
        raise ValueError(
            f"residual_mode must be 'full' or one of {tuple(RESIDUAL_PARTS)}, got {residual_mode!r}"
        )
    if applied_action_only and residual_mode in RESIDUAL_PARTS:
        return POLAR_SIGNS if residual_mode == "translation" else AXIAL_SIGNS
    return POLAR_SIGNS + AXIAL_SIGNS


def check_mirror_symmetric_task(task) -> None:
    """Raises a ValueError naming the field unless the world's x-z plane is a plane of
    symmetry of the task's scene: the fixture on it, unturned, and the table's slope
    (if any) about y. (The part's and fixture's shapes are not checked: the shipped
    ones are symmetric across it.)"""
    pose = task.X_WFixture
    if abs(float(pose.position_m[1])) > 1e-9:
        raise ValueError(
            "a mirror-symmetric policy needs the fixture on the world's x-z plane: "
            f"X_WFixture.position_m[1] must be 0, got {pose.position_m[1]}"
        )
    if any(abs(float(angle)) > 1e-9 for angle in pose.rpy_deg):
        raise ValueError(
            "a mirror-symmetric policy needs the fixture unturned: X_WFixture.rpy_deg must "
            f"be [0, 0, 0], got {list(pose.rpy_deg)}"
        )
    slope = task.fixture_error
    axis = np.asarray(slope.table_slope_axis, dtype=float)
    if slope.table_slope_deg != 0.0 and (abs(axis[0]) > 1e-9 or abs(axis[2]) > 1e-9):
        raise ValueError(
            "a mirror-symmetric policy needs the table's slope about y: fixture_error."
            f"table_slope_axis must be [0, +-1, 0], got {list(slope.table_slope_axis)}"
        )


class MirrorSymmetricPolicy(ActorCriticPolicy):
    """SB3's MLP actor-critic whose mean action is equivariant and whose value is
    invariant under the mirror (module docstring). The log std is a per-axis
    magnitude, which the mirror leaves unchanged.

    Args (besides ActorCriticPolicy's; state-dependent exploration is refused):
        observation_signs: the mirror's sign on each observation entry
            (``observation_mirror_signs``).
        action_signs: the mirror's sign on each action entry (``action_mirror_signs``).
    """

    def __init__(
        self,
        observation_space,
        action_space,
        lr_schedule,
        observation_signs,
        action_signs,
        **kwargs,
    ):
        for name, signs, space in (
            ("observation_signs", observation_signs, observation_space),
            ("action_signs", action_signs, action_space),
        ):
            values = np.asarray(signs, dtype=float)
            if values.shape != tuple(space.shape) or not np.all(np.abs(values) == 1.0):
                raise ValueError(
                    f"{name} must be {space.shape[0]} signs (+-1), one per entry, got "
                    f"{tuple(np.atleast_1d(values))}"
                )
        if kwargs.get("use_sde"):
            raise ValueError("use_sde=True: a mirror-symmetric policy needs Gaussian noise")
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)
        if not isinstance(self.action_dist, DiagGaussianDistribution):
            raise ValueError(
                f"a mirror-symmetric policy needs a Gaussian action, got {type(self.action_dist)}"
            )
        self.observation_signs = tuple(float(v) for v in observation_signs)
        self.action_signs = tuple(float(v) for v in action_signs)
        # Not in the state dict: the same networks load into a plain policy's shape.
        self.register_buffer(
            "_observation_signs", torch.tensor(self.observation_signs), persistent=False
        )
        self.register_buffer("_action_signs", torch.tensor(self.action_signs), persistent=False)

    def _with_mirror(self, obs: torch.Tensor) -> torch.Tensor:
        """The batch followed by its mirror image."""
        obs = obs.float()
        return torch.cat([obs, obs * self._observation_signs.to(obs.dtype)], dim=0)

    def _mean_actions(self, obs: torch.Tensor) -> torch.Tensor:
        features = super().extract_features(self._with_mirror(obs), self.pi_features_extractor)
        mean = self.action_net(self.mlp_extractor.forward_actor(features))
        n = mean.shape[0] // 2
        return 0.5 * (mean[:n] + mean[n:] * self._action_signs.to(mean.dtype))

    def _values(self, obs: torch.Tensor) -> torch.Tensor:
        features = super().extract_features(self._with_mirror(obs), self.vf_features_extractor)
        values = self.value_net(self.mlp_extractor.forward_critic(features))
        n = values.shape[0] // 2
        return 0.5 * (values[:n] + values[n:])

    def _distribution(self, obs: torch.Tensor):
        return self.action_dist.proba_distribution(self._mean_actions(obs), self.log_std)

    def forward(self, obs: torch.Tensor, deterministic: bool = False):
        distribution = self._distribution(obs)
        actions = distribution.get_actions(deterministic=deterministic)
        log_prob = distribution.log_prob(actions)
        actions = actions.reshape((-1, *self.action_space.shape))
        return actions, self._values(obs), log_prob

    def evaluate_actions(self, obs: torch.Tensor, actions: torch.Tensor):
        distribution = self._distribution(obs)
        return self._values(obs), distribution.log_prob(actions), distribution.entropy()

    def get_distribution(self, obs: torch.Tensor):
        return self._distribution(obs)

    def predict_values(self, obs: torch.Tensor) -> torch.Tensor:
        return self._values(obs)

    def _get_constructor_parameters(self) -> dict:
        data = super()._get_constructor_parameters()
        data.update(observation_signs=self.observation_signs, action_signs=self.action_signs)
        return data
