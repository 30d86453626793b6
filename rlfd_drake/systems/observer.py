"""Observation, sparse reward, success and contact-force metrics of an episode."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.common.value import Value
from pydrake.math import RigidTransform
from pydrake.multibody.math import SpatialForce, SpatialVelocity
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import BodyIndex, JointIndex, ModelInstanceIndex
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

#: Size of the observation vector (see :class:`Observer`).
OBSERVATION_SIZE = 26
#: Where the wrist wrench sits in the observation (see :class:`Observer`).
OBSERVATION_WRIST_TORQUE = slice(12, 15)
OBSERVATION_WRIST_FORCE = slice(15, 18)
#: Where the residual input (the last held action, or a rate residual's held offset) sits.
OBSERVATION_RESIDUAL = slice(20, 26)
# Force-metric state layout.
_PEAK_F, _SUM_F, _COUNT, _PEAK_TAU, _SUCCESS, _FILTERED_F, _PEAK_FILTERED_F = range(7)


@dataclass(frozen=True)
class ObserverConfig:
    """Attributes:
    kappa_m: success radius of the sparse reward, m.
    force_metrics_period_s: update period of the force metrics, s (the plant's step:
        contact peaks last a few steps).
    success_period_s: update period of the success latch, s (the part moves less than
        a millimetre in 10 ms; reading the pose costs as much as the force metrics).
    force_filter_time_constant_s: time constant of the low-passed contact force that
        force limits are checked against, s. A 2 ms plant step resolves impact spikes
        of one sample that a real part (and a real F/T sensor) would not feel as such.
    episode_time_s: episode length used to normalise time, s.
    position_scale_m: position error per unit of observation, m.
    angular_velocity_scale_rad_per_s, linear_velocity_scale_m_per_s: twist scales.
    torque_scale_Nm, force_scale_N: wrist wrench scales.
    """

    kappa_m: float = 0.005
    force_metrics_period_s: float = 0.002
    success_period_s: float = 0.01
    force_filter_time_constant_s: float = 0.02
    episode_time_s: float = 10.0
    position_scale_m: float = 0.02
    angular_velocity_scale_rad_per_s: float = 1.0
    linear_velocity_scale_m_per_s: float = 0.1
    torque_scale_Nm: float = 5.0
    force_scale_N: float = 50.0


class Observer(LeafSystem):
    """Turns plant outputs into the RL observation, reward and metrics.

    .. pydrake_system::

        name: Observer
        input_ports:
        - body_poses
        - body_spatial_velocities
        - reaction_forces
        - contact_results
        - generalized_contact_forces
        - phase
        - residual
        output_ports:
        - observation
        - reward
        - success
        - force_metrics
        - distance_to_goal

    Inputs: the plant's ``get_body_poses_output_port``,
    ``get_body_spatial_velocities_output_port``, ``get_reaction_forces_output_port``,
    ``get_contact_results_output_port``, ``get_generalized_contact_forces_output_port(arm)``
    (n_v of the arm), the DMP phase (1) and the residual action (6).

    ``observation`` (26), P being the part frame (X_WP = X_WB X_BP):

    ====== ====================================================================
    0:3    (p_WP - p_WGoal_nominal) / position_scale_m (the nominal goal is the
           demonstration's: the robot does not know the fixture error)
    3:6    rotation vector of Q_WP o conj(Q_WGoal_nominal), rad, world
    6:9    angular velocity of P / angular_velocity_scale_rad_per_s, world
    9:12   linear velocity of P / linear_velocity_scale_m_per_s, world
    12:15  wrist torque / torque_scale_Nm: reaction at the weld joint on its child,
           about the joint's child frame origin, expressed in world
    15:18  wrist force / force_scale_N, same convention
    18     DMP phase (1 -> 0)
    19     time / episode_time_s
    20:26  the residual input: the last held action (with an incremental residual,
           ``residual_rate_per_s``, the offset its integrator holds)
    ====== ====================================================================

    ``reward`` (1): sparse ``1[|p_WP - p_WGoal_true| <= kappa_m]``.
    ``success`` (1): 1 once the reward has been 1 at a success update (latched).
    ``force_metrics`` (4): [peak contact force (N), time-averaged contact force (N),
    peak |generalised contact torque| over the arm joints (N m), peak of the
    contact force low-passed with ``force_filter_time_constant_s`` (N)] since
    initialisation; the contact force at an instant is the sum over contact
    surfaces/points of |F| (magnitudes, so opposing wall forces do not cancel).
    ``distance_to_goal`` (1): |p_WP - p_WGoal_true|, m.

    The true goal is X_WGoal_true = X_WB X_BGoal of the body ``goal_body_index`` (the
    fixture; the world body for a fixed goal), read from ``body_poses``.
    """

    def __init__(
        self,
        plant: MultibodyPlant,
        part_body_index: BodyIndex,
        X_BP: RigidTransform,
        goal_body_index: BodyIndex,
        X_BGoal: RigidTransform,
        X_WGoal_nominal: RigidTransform,
        wrist_joint_index: JointIndex,
        arm_instance: ModelInstanceIndex,
        config: ObserverConfig = ObserverConfig(),  # noqa: B008
    ):
        super().__init__()
        self.config = config
        self._body = int(part_body_index)
        self._X_BP = X_BP
        self._p_BP = X_BP.translation().copy()
        # The true goal rides on a body (the fixture), read from the plant's poses: the
        # fixture's pose is a parameter of the context (scene.SetFixtureError).
        self._goal_body = int(goal_body_index)
        self._X_BGoal = X_BGoal
        self._p_goal_nominal = X_WGoal_nominal.translation().copy()
        self._R_goal_nominal_inv = X_WGoal_nominal.rotation().inverse()
        joint = plant.get_joint(wrist_joint_index)
        self._joint = int(wrist_joint_index)
        self._joint_child_body = int(joint.child_body().index())
        self._X_CJc = joint.frame_on_child().GetFixedPoseInBodyFrame()
        self._obs_scale = np.ones(18)
        self._obs_scale[0:3] = 1.0 / config.position_scale_m
        self._obs_scale[6:9] = 1.0 / config.angular_velocity_scale_rad_per_s
        self._obs_scale[9:12] = 1.0 / config.linear_velocity_scale_m_per_s
        self._obs_scale[OBSERVATION_WRIST_TORQUE] = 1.0 / config.torque_scale_Nm
        self._obs_scale[OBSERVATION_WRIST_FORCE] = 1.0 / config.force_scale_N
        n_arm = plant.num_velocities(arm_instance)
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", Value([RigidTransform()] * plant.num_bodies())
        )
        self._velocities = self.DeclareAbstractInputPort(
            "body_spatial_velocities", Value([SpatialVelocity()] * plant.num_bodies())
        )
        self._reactions = self.DeclareAbstractInputPort(
            "reaction_forces", Value([SpatialForce()] * plant.num_joints())
        )
        self._contacts = self.DeclareAbstractInputPort("contact_results", Value(ContactResults()))
        self._tau_contact = self.DeclareVectorInputPort("generalized_contact_forces", n_arm)
        self._phase = self.DeclareVectorInputPort("phase", 1)
        self._residual = self.DeclareVectorInputPort("residual", 6)
        self.DeclareDiscreteState(7)
        self.DeclarePeriodicDiscreteUpdateEvent(
            config.force_metrics_period_s, 0.0, self._update_metrics
        )
        self.DeclarePeriodicDiscreteUpdateEvent(config.success_period_s, 0.0, self._update_success)
        self.DeclareVectorOutputPort("observation", OBSERVATION_SIZE, self._calc_observation)
        self.DeclareVectorOutputPort("reward", 1, self._calc_reward)
        self.DeclareVectorOutputPort(
            "success", 1, self._calc_success, prerequisites_of_calc={self.all_state_ticket()}
        )
        self.DeclareVectorOutputPort(
            "force_metrics", 4, self._calc_force_metrics, {self.all_state_ticket()}
        )
        self.DeclareVectorOutputPort("distance_to_goal", 1, self._calc_distance)

    # -- helpers ------------------------------------------------------------------
    def _X_WP(self, context: Context) -> RigidTransform:
        return self._poses.Eval(context)[self._body] @ self._X_BP

    def DistanceToGoal(self, context: Context) -> float:
        """|p_WP - p_WGoal_true| (m)."""
        p_goal_true = (self._poses.Eval(context)[self._goal_body] @ self._X_BGoal).translation()
        return float(np.linalg.norm(self._X_WP(context).translation() - p_goal_true))

    @staticmethod
    def TotalContactForce(contact_results: ContactResults) -> float:
        """Sum of the contact force magnitudes (N) of all surfaces and points."""
        total = 0.0
        for i in range(contact_results.num_hydroelastic_contacts()):
            f = contact_results.hydroelastic_contact_info(i).F_Ac_W().translational()
            total += math.sqrt(f @ f)
        for i in range(contact_results.num_point_pair_contacts()):
            f = contact_results.point_pair_contact_info(i).contact_force()
            total += math.sqrt(f @ f)
        return total

    # -- discrete update ------------------------------------------------------------
    def _update_metrics(self, context: Context, discrete_state: DiscreteValues) -> None:
        x = context.get_discrete_state(0).get_value()
        # EvalAbstract: the results by reference, not copied into Python (500 Hz).
        force = self.TotalContactForce(self._contacts.EvalAbstract(context).get_value())
        # Python's max over 7 floats: a third of numpy's max(abs()) at 500 Hz.
        tau = max(map(abs, self._tau_contact.Eval(context).tolist()))
        # Each event writes its own entries only: when both fire at once, Drake hands
        # them the same copy of the state.
        new = discrete_state.get_mutable_value(0)
        new[_PEAK_F] = max(x[_PEAK_F], force)
        new[_SUM_F] = x[_SUM_F] + force
        new[_COUNT] = x[_COUNT] + 1.0
        new[_PEAK_TAU] = max(x[_PEAK_TAU], tau)
        dt = self.config.force_metrics_period_s
        gain = dt / (self.config.force_filter_time_constant_s + dt)
        new[_FILTERED_F] = x[_FILTERED_F] + gain * (force - x[_FILTERED_F])
        new[_PEAK_FILTERED_F] = max(x[_PEAK_FILTERED_F], new[_FILTERED_F])

    def _update_success(self, context: Context, discrete_state: DiscreteValues) -> None:
        if context.get_discrete_state(0).get_value()[_SUCCESS] > 0.5:
            return
        if self.DistanceToGoal(context) <= self.config.kappa_m:
            discrete_state.get_mutable_value(0)[_SUCCESS] = 1.0

    # -- outputs --------------------------------------------------------------------
    def _calc_observation(self, context: Context, output: BasicVector) -> None:
        X_WB = self._poses.Eval(context)[self._body]
        X_WP = X_WB @ self._X_BP
        V_WB = self._velocities.Eval(context)[self._body]
        V_WP = V_WB.Shift(X_WB.rotation() @ self._p_BP)
        F_CJc_Jc = self._reactions.Eval(context)[self._joint]
        R_WJc = (
            self._poses.Eval(context)[self._joint_child_body].rotation() @ self._X_CJc.rotation()
        )
        aa = AngleAxis((X_WP.rotation() @ self._R_goal_nominal_inv).ToQuaternion())
        obs = output.get_mutable_value()
        raw = np.empty(18)
        raw[0:3] = X_WP.translation() - self._p_goal_nominal
        raw[3:6] = aa.angle() * aa.axis()
        raw[6:12] = V_WP.get_coeffs()
        F_CJc_W = F_CJc_Jc.Rotate(R_WJc)
        raw[OBSERVATION_WRIST_TORQUE] = F_CJc_W.rotational()
        raw[OBSERVATION_WRIST_FORCE] = F_CJc_W.translational()
        obs[:18] = raw * self._obs_scale
        obs[18] = self._phase.Eval(context)[0]
        obs[19] = context.get_time() / self.config.episode_time_s
        obs[OBSERVATION_RESIDUAL] = self._residual.Eval(context)

    def _calc_reward(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, 1.0 if self.DistanceToGoal(context) <= self.config.kappa_m else 0.0)

    def _calc_success(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, context.get_discrete_state(0).get_value()[_SUCCESS])

    def _calc_force_metrics(self, context: Context, output: BasicVector) -> None:
        x = context.get_discrete_state(0).get_value()
        mean = x[_SUM_F] / x[_COUNT] if x[_COUNT] > 0 else 0.0
        output.SetFromVector([x[_PEAK_F], mean, x[_PEAK_TAU], x[_PEAK_FILTERED_F]])

    def _calc_distance(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, self.DistanceToGoal(context))
