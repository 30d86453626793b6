"""Cartesian impedance controller (Jacobian transpose) of the Panda, 500 Hz.

The law, for the controlled frame E (e.g. the tip of the grasped part):

    tau = J^T (K e + D (V_d - V)) + N (Kp_n (q_n - q) - Kd_n v) - tau_g(q)

* ``e = [rotation vector of Q_d o conj(Q_WE); p_d - p_WE]`` (rad, m), world frame,
  the orientation error being the quaternion log on SO(3);
* ``V = J v`` is E's spatial velocity ``[w; v]`` in the world; ``V_d`` is the desired
  twist when ``feedforward_twist`` is on, else zero (pure damping);
* K, D diagonal (6); D is critically damped, ``D_i = 2 zeta sqrt(K_i Lambda_i)`` with
  ``Lambda_i`` the diagonal of the operational-space inertia
  ``Lambda = (J M^-1 J^T)^-1``, evaluated at the nominal posture once (default) or at
  every step (``update_damping_each_step``);
* ``N = I - J^T (J^+)^T`` the simple null-space projector with ``J^+ = J^T (J J^T)^-1``
  (it removes any static wrench at E; the dynamically consistent projector would need
  M^-1 at every step);
* ``tau_g`` from the controller's own model of the arm, which knows its payload;
* the torque is clipped to ``PANDA_TORQUE_LIMITS_NM``.

The controller never sees the fixture: it owns a separate MultibodyPlant
(:func:`MakePandaControlModel`) and a scratch Context of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    JacobianWrtVariable,
    RotationalInertia,
    SpatialInertia,
    UnitInertia,
)
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

from rlfd_drake.control_math import (
    critical_damping,
    operational_space_inertia,
    rotation_vector_between,
)
from rlfd_drake.panda import PANDA_HAND_BODY, PANDA_HOME_Q, PANDA_TORQUE_LIMITS_NM, AddPanda

try:
    # The LAPACK solve behind np.linalg.solve (the same numbers), without its per-call
    # checks and error-state switching: 5 % of an episode at 500 Hz. A singular J J^T
    # gives non-finite numbers, which _update refuses.
    from numpy.linalg._umath_linalg import solve1 as _solve
except ImportError:  # pragma: no cover - a numpy that moved it
    _solve = np.linalg.solve

#: Name of the controlled frame E in the control model.
CONTROL_FRAME_NAME = "controlled_frame_E"
#: Name of the payload body of the control model.
PAYLOAD_BODY_NAME = "payload"


def MakePandaControlModel(
    X_HE: RigidTransform | None = None,
    payload_mass_kg: float = 0.0,
    payload_com_H: np.ndarray | None = None,
    payload_inertia_Hcm_H: np.ndarray | None = None,
    finger_opening_m: float = 0.0,
) -> MultibodyPlant:
    """The controller's model of the arm: the Panda, its payload, a frame E on the hand.

    Args:
        X_HE: pose of the controlled frame E in the hand frame H (default identity).
        payload_mass_kg: mass of the grasped part (0 for none), kg.
        payload_com_H: (3,) position of the payload's centre of mass in H, m.
        payload_inertia_Hcm_H: (3, 3) rotational inertia about the centre of mass,
            expressed in H, kg m^2 (default: that of a solid 2 cm sphere of the mass;
            it hardly matters for a slow insertion).
        finger_opening_m: finger opening of :func:`AddPanda`.

    Returns:
        A finalized continuous-time MultibodyPlant (no SceneGraph) with frame
        ``CONTROL_FRAME_NAME`` and, if the mass is positive, the welded body
        ``PAYLOAD_BODY_NAME``.
    """
    plant = MultibodyPlant(0.0)
    panda = AddPanda(plant, finger_opening_m=finger_opening_m)
    hand = plant.GetBodyByName(PANDA_HAND_BODY, panda)
    if payload_mass_kg < 0.0:
        raise ValueError(f"payload_mass_kg must be >= 0, got {payload_mass_kg}")
    if payload_mass_kg > 0.0:
        p_HPcm = np.zeros(3) if payload_com_H is None else np.asarray(payload_com_H, float)
        if payload_inertia_Hcm_H is None:
            I_cm = UnitInertia.SolidSphere(0.02) * payload_mass_kg
        else:
            I = np.asarray(payload_inertia_Hcm_H, dtype=float)
            I_cm = RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
        # The payload body frame coincides with H; its COM is offset by p_HPcm.
        M_PPo = SpatialInertia.MakeFromCentralInertia(payload_mass_kg, p_HPcm, I_cm)
        payload = plant.AddRigidBody(PAYLOAD_BODY_NAME, panda, M_PPo)
        plant.WeldFrames(hand.body_frame(), payload.body_frame(), RigidTransform())
    plant.AddFrame(
        FixedOffsetFrame(
            CONTROL_FRAME_NAME, hand.body_frame(), X_HE if X_HE is not None else RigidTransform()
        )
    )
    plant.Finalize()
    return plant


@dataclass(frozen=True)
class CartesianImpedanceConfig:
    """Gains of :class:`CartesianImpedanceController`.

    Attributes:
        period_s: control period (500 Hz), s.
        rotational_stiffness_Nm_per_rad: (3,) diagonal of K for rotation (world axes).
        translational_stiffness_N_per_m: (3,) diagonal of K for translation.
        damping_ratio: zeta of the critical-damping rule.
        update_damping_each_step: recompute Lambda (and D) at every step (~15 us more
            per call) instead of once at ``nominal_q``.
        feedforward_twist: damp the velocity error V_d - V instead of V.
        nullspace_stiffness_Nm_per_rad: posture stiffness Kp_n toward ``nominal_q``.
        nullspace_damping_Nms_per_rad: posture damping Kd_n.
        nominal_q: (7,) posture of the null-space term, rad.
    """

    period_s: float = 0.002
    rotational_stiffness_Nm_per_rad: tuple[float, float, float] = (150.0, 150.0, 150.0)
    translational_stiffness_N_per_m: tuple[float, float, float] = (2000.0, 2000.0, 2000.0)
    damping_ratio: float = 1.0
    update_damping_each_step: bool = False
    feedforward_twist: bool = True
    nullspace_stiffness_Nm_per_rad: float = 10.0
    nullspace_damping_Nms_per_rad: float = 1.0
    nominal_q: tuple[float, ...] = tuple(float(x) for x in PANDA_HOME_Q)


class CartesianImpedanceController(LeafSystem):
    """Cartesian impedance control of the Panda at a fixed rate (zero-order hold).

    .. pydrake_system::

        name: CartesianImpedanceController
        input_ports:
        - panda_state
        - X_WE_desired
        - V_WE_desired
        output_ports:
        - panda_torque
        - tracking_error

    * ``panda_state`` (14): q (rad) then v (rad/s) of the 7 arm joints.
    * ``X_WE_desired`` (7): desired pose of E, position (m) then quaternion [w, x, y, z].
    * ``V_WE_desired`` (6): desired spatial velocity of E, [w (rad/s); v (m/s)], world.
    * ``panda_torque`` (7): joint torques, N m, clipped to the torque limits.
    * ``tracking_error`` (3): ``p_d - p_WE`` (m, world) of the last update, the
      translational error the torque was computed from (read by a phase-stopped DMP).

    The torque is computed into the discrete state at each periodic update (and at
    initialisation) and the output reads the state: a sampled controller with a
    one-sample delay against a discrete plant updating at the same instants.
    """

    def __init__(
        self,
        control_plant: MultibodyPlant,
        config: CartesianImpedanceConfig = CartesianImpedanceConfig(),  # noqa: B008
    ):
        super().__init__()
        if control_plant.num_positions() != 7 or control_plant.num_velocities() != 7:
            raise ValueError(
                "the control model must have exactly the 7 Panda joints, got "
                f"{control_plant.num_positions()} positions"
            )
        self.config = config
        self._plant = control_plant
        self._plant_context = control_plant.CreateDefaultContext()
        self._frame_E = control_plant.GetFrameByName(CONTROL_FRAME_NAME)
        self._world = control_plant.world_frame()
        self._K = np.array(
            [*config.rotational_stiffness_Nm_per_rad, *config.translational_stiffness_N_per_m]
        )
        self._q_nominal = np.asarray(config.nominal_q, dtype=float)
        if self._q_nominal.shape != (7,):
            raise ValueError(f"nominal_q must have 7 entries, got {self._q_nominal.shape}")
        self._limits = PANDA_TORQUE_LIMITS_NM.copy()
        self._neg_limits = -self._limits
        self._kp_null = float(config.nullspace_stiffness_Nm_per_rad)
        self._kd_null = float(config.nullspace_damping_Nms_per_rad)
        self._zero3 = np.zeros(3)
        self._error = np.zeros(6)  # scratch: [rotation vector; position error]
        # Damping from Lambda at the nominal posture.
        control_plant.SetPositions(self._plant_context, self._q_nominal)
        self._D = self._damping()
        self.nominal_damping = self._D.copy()

        self._state_port = self.DeclareVectorInputPort("panda_state", 14)
        self._X_port = self.DeclareVectorInputPort("X_WE_desired", 7)
        self._V_port = self.DeclareVectorInputPort("V_WE_desired", 6)
        state_index = self.DeclareDiscreteState(7)
        self._error_index = self.DeclareDiscreteState(3)
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        self.DeclareStateOutputPort("panda_torque", state_index)
        self.DeclareStateOutputPort("tracking_error", self._error_index)

    def _damping(self) -> np.ndarray:
        """(6,) critical damping at the posture stored in the scratch context."""
        J = self._plant.CalcJacobianSpatialVelocity(
            self._plant_context,
            JacobianWrtVariable.kV,
            self._frame_E,
            self._zero3,
            self._world,
            self._world,
        )
        M = self._plant.CalcMassMatrix(self._plant_context)
        Lambda = operational_space_inertia(J, M)
        return critical_damping(self._K, np.diag(Lambda), self.config.damping_ratio)

    def CalcTorque(
        self, x: np.ndarray, X_WE_desired: np.ndarray, V_WE_desired: np.ndarray
    ) -> np.ndarray:
        """(7,) torque for the arm state x (14,) and the set-point (7,), (6,).

        The same law as :func:`rlfd_drake.control_math.cartesian_impedance_torque`
        (a test holds them equal), written with scalar quaternion maths and one
        linear solve, since it runs at 500 Hz on tiny arrays.
        """
        plant, ctx = self._plant, self._plant_context
        plant.SetPositionsAndVelocities(ctx, x)
        v = x[7:]
        X_WE = self._frame_E.CalcPoseInWorld(ctx)
        J = plant.CalcJacobianSpatialVelocity(
            ctx, JacobianWrtVariable.kV, self._frame_E, self._zero3, self._world, self._world
        )
        e = self._error
        e[:3] = rotation_vector_between(X_WE_desired[3:], X_WE.rotation().ToQuaternion().wxyz())
        e[3:] = X_WE_desired[:3] - X_WE.translation()
        V_error = V_WE_desired - J @ v if self.config.feedforward_twist else -(J @ v)
        D = self._damping() if self.config.update_damping_each_step else self._D
        wrench = self._K * e + D * V_error
        tau_posture = self._kp_null * (self._q_nominal - x[:7]) - self._kd_null * v
        # J^T wrench + N tau_posture - tau_g with N tau0 = tau0 - J^T (J J^T)^-1 J tau0.
        y = _solve(J @ J.T, J @ tau_posture)
        tau = J.T @ (wrench - y) + tau_posture - plant.CalcGravityGeneralizedForces(ctx)
        return np.minimum(np.maximum(tau, self._neg_limits), self._limits)

    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        tau = self.CalcTorque(
            self._state_port.Eval(context), self._X_port.Eval(context), self._V_port.Eval(context)
        )
        # tau is clipped, so only a NaN can make its square non-finite (np.all of
        # np.isfinite costs 3 us, 2 % of an episode at 500 Hz).
        if not math.isfinite(tau @ tau):
            raise RuntimeError(f"CartesianImpedanceController: non-finite torque {tau}")
        discrete_state.set_value(0, tau)
        discrete_state.set_value(self._error_index, self._error[3:])
