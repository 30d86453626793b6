"""CartesianImpedanceController on the simulated Panda with a welded payload."""

from __future__ import annotations

import time

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from rlfd_drake.control_math import cartesian_impedance_torque, null_space_torque
from rlfd_drake.geometry import quat_error
from rlfd_drake.panda import PANDA_HAND_BODY, PANDA_HOME_Q, PANDA_TORQUE_LIMITS_NM, AddPanda
from rlfd_drake.systems.impedance import (
    CartesianImpedanceConfig,
    CartesianImpedanceController,
    MakePandaControlModel,
)

PAYLOAD_MASS_KG = 0.3
PAYLOAD_COM_H = np.array([0.0, 0.0, 0.12])
X_HE = RigidTransform([0.0, 0.0, 0.16])


class MinimumJerkLine(LeafSystem):
    """Pose set-point moving along a minimum-jerk line (test helper)."""

    def __init__(self, X_start: RigidTransform, dp: np.ndarray, t0: float, duration: float):
        super().__init__()
        self._p0 = X_start.translation().copy()
        self._q = X_start.rotation().ToQuaternion().wxyz()
        self._dp, self._t0, self._T = dp, t0, duration
        self.DeclareVectorOutputPort("X", 7, self._calc_X)
        self.DeclareVectorOutputPort("V", 6, self._calc_V)

    def s(self, t: float) -> tuple[float, float]:
        u = np.clip((t - self._t0) / self._T, 0.0, 1.0)
        s = 10 * u**3 - 15 * u**4 + 6 * u**5
        ds = (30 * u**2 - 60 * u**3 + 30 * u**4) / self._T if 0.0 < u < 1.0 else 0.0
        return s, ds

    def _calc_X(self, context, output: BasicVector) -> None:
        s, _ = self.s(context.get_time())
        output.SetFromVector(np.concatenate([self._p0 + s * self._dp, self._q]))

    def _calc_V(self, context, output: BasicVector) -> None:
        _, ds = self.s(context.get_time())
        output.SetFromVector(np.concatenate([np.zeros(3), ds * self._dp]))


def _build(config: CartesianImpedanceConfig, moving: np.ndarray | None = None):
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=0.002, discrete_contact_approximation="sap"), builder
    )
    panda = AddPanda(plant)
    # The payload: a 4 x 4 x 16 cm box of 0.3 kg whose centre is 12 cm below the hand.
    box = plant.AddRigidBody(
        "payload_box",
        panda,
        SpatialInertia.MakeFromCentralInertia(
            PAYLOAD_MASS_KG, np.zeros(3), UnitInertia.SolidBox(0.04, 0.04, 0.16) * PAYLOAD_MASS_KG
        ),
    )
    hand = plant.GetBodyByName(PANDA_HAND_BODY, panda)
    plant.WeldFrames(hand.body_frame(), box.body_frame(), RigidTransform(PAYLOAD_COM_H))
    plant.Finalize()

    control_plant = MakePandaControlModel(
        X_HE,
        PAYLOAD_MASS_KG,
        PAYLOAD_COM_H,
        UnitInertia.SolidBox(0.04, 0.04, 0.16).CopyToFullMatrix3() * PAYLOAD_MASS_KG,
    )
    controller = builder.AddSystem(CartesianImpedanceController(control_plant, config))
    # The set-point: E at the home posture, rotated 3 deg about world x.
    ctx = control_plant.CreateDefaultContext()
    control_plant.SetPositions(ctx, PANDA_HOME_Q)
    X_WE0 = control_plant.GetFrameByName("controlled_frame_E").CalcPoseInWorld(ctx)
    X_WEd = RigidTransform(
        RotationMatrix.MakeXRotation(np.radians(3.0)) @ X_WE0.rotation(),
        X_WE0.translation() + np.array([0.02, -0.01, 0.01]),
    )
    builder.Connect(plant.get_state_output_port(panda), controller.GetInputPort("panda_state"))
    if moving is None:
        X = np.concatenate([X_WEd.translation(), X_WEd.rotation().ToQuaternion().wxyz()])
        source_X = builder.AddSystem(ConstantVectorSource(X))
        source_V = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
        X_port, V_port = source_X.get_output_port(), source_V.get_output_port()
    else:
        line = builder.AddSystem(MinimumJerkLine(X_WEd, moving, 0.5, 2.0))
        X_port, V_port = line.GetOutputPort("X"), line.GetOutputPort("V")
    builder.Connect(X_port, controller.GetInputPort("X_WE_desired"))
    builder.Connect(V_port, controller.GetInputPort("V_WE_desired"))
    builder.Connect(controller.GetOutputPort("panda_torque"), plant.get_actuation_input_port(panda))
    torque_log = builder.AddSystem(VectorLogSink(7, 0.002))
    builder.Connect(controller.GetOutputPort("panda_torque"), torque_log.get_input_port())
    state_log = builder.AddSystem(VectorLogSink(14, 0.002))
    builder.Connect(plant.get_state_output_port(panda), state_log.get_input_port())
    diagram = builder.Build()
    return diagram, plant, control_plant, X_WEd, torque_log, state_log, X_port, V_port


def _pose_errors(control_plant, states, X_WEd: RigidTransform):
    """Position (m) and orientation (rad) errors of E over logged states (14, N)."""
    ctx = control_plant.CreateDefaultContext()
    frame = control_plant.GetFrameByName("controlled_frame_E")
    q_d = X_WEd.rotation().ToQuaternion().wxyz()
    pos, ang = [], []
    for x in states.T:
        control_plant.SetPositions(ctx, x[:7])
        X = frame.CalcPoseInWorld(ctx)
        pos.append(np.linalg.norm(X.translation() - X_WEd.translation()))
        ang.append(np.linalg.norm(quat_error(q_d, X.rotation().ToQuaternion().wxyz())))
    return np.array(pos), np.array(ang)


def test_holds_pose_under_gravity():
    diagram, plant, control_plant, X_WEd, torque_log, state_log, _, _ = _build(
        CartesianImpedanceConfig()
    )
    simulator = Simulator(diagram)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(2.0)
    print(f"hold: 2 s simulated in {time.perf_counter() - start:.2f} s")
    context = simulator.get_context()
    tau = torque_log.FindLog(context).data()
    states = state_log.FindLog(context).data()
    assert np.all(np.abs(tau) <= PANDA_TORQUE_LIMITS_NM[:, None] + 1e-9)
    assert np.max(np.abs(states[7:])) < 3.0  # rad/s: no blow-up
    pos, ang = _pose_errors(control_plant, states[:, -1:], X_WEd)
    assert pos[-1] < 1e-3
    assert np.degrees(ang[-1]) < 0.5
    # It has converged: the arm is at rest.
    assert np.max(np.abs(states[7:, -1])) < 1e-3


def test_tracks_moving_setpoint_with_feedforward():
    dp = np.array([0.1, 0.0, 0.0])  # 10 cm minimum-jerk line in 2 s
    diagram, plant, control_plant, X_WEd, torque_log, state_log, X_port, _ = _build(
        CartesianImpedanceConfig(), moving=dp
    )
    simulator = Simulator(diagram)
    simulator.Initialize()
    simulator.AdvanceTo(3.0)
    context = simulator.get_context()
    tau = torque_log.FindLog(context).data()
    log = state_log.FindLog(context)
    states, times = log.data(), log.sample_times()
    assert np.all(np.abs(tau) <= PANDA_TORQUE_LIMITS_NM[:, None] + 1e-9)
    assert np.max(np.abs(states[7:])) < 3.0
    # Compare with the moving set-point during and after the motion (t >= 0.5 s, the
    # initial 2 cm step has settled by then).
    line = X_port.get_system()
    errors = []
    for t, x in zip(times[::10], states.T[::10], strict=True):
        if t < 0.5:
            continue
        s, _ = line.s(t)
        X_t = RigidTransform(X_WEd.rotation(), X_WEd.translation() + s * dp)
        pos, ang = _pose_errors(control_plant, x[:, None], X_t)
        errors.append((pos[0], ang[0]))
    errors = np.array(errors)
    print(
        f"tracking: max error {1e3 * errors[:, 0].max():.2f} mm, "
        f"{np.degrees(errors[:, 1].max()):.2f} deg"
    )
    # Lag from the uncompensated inertia (no feed-forward acceleration, Lambda_x ~ 12 kg
    # with the armature: 12 kg * 0.14 m/s^2 / 2000 N/m ~ 0.9 mm) and joint damping.
    assert errors[:, 0].max() < 2.5e-3  # m, while moving at up to 9.4 cm/s
    assert np.degrees(errors[:, 1].max()) < 0.5
    assert errors[-1, 0] < 1e-3


def test_impedance_law_matches_definition():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(6, 7))
    tau0 = rng.normal(size=7)
    # The null-space term produces no wrench at E: (J^+)^T N tau0 = 0.
    J_pinv = J.T @ np.linalg.inv(J @ J.T)
    np.testing.assert_allclose(J_pinv.T @ null_space_torque(J, tau0), 0.0, atol=1e-12)
    e, dV = rng.normal(size=6), rng.normal(size=6)
    K, D = np.full(6, 100.0), np.full(6, 10.0)
    g = rng.normal(size=7)
    expected = J.T @ (K * e + D * dV) + null_space_torque(J, tau0) - g
    limits = np.full(7, 1e9)
    tau = cartesian_impedance_torque(J, e, dV, K, D, tau0, g, limits)
    np.testing.assert_allclose(tau, expected, atol=1e-12)
    small = np.full(7, 0.5)
    assert np.all(np.abs(cartesian_impedance_torque(J, e, dV, K, D, tau0, g, small)) <= 0.5)


def test_rejects_wrong_model_and_reports_cost():
    with pytest.raises(ValueError, match="payload_mass_kg"):
        MakePandaControlModel(payload_mass_kg=-1.0)
    controller = CartesianImpedanceController(MakePandaControlModel(X_HE, 0.3, PAYLOAD_COM_H))
    x = np.concatenate([PANDA_HOME_Q, np.full(7, 0.1)])
    X_d = np.array([0.5, 0.0, 0.4, 0.0, 1.0, 0.0, 0.0])
    V_d = np.zeros(6)
    n = 500
    start = time.perf_counter()
    for _ in range(n):
        tau = controller.CalcTorque(x, X_d, V_d)
    per_call_us = (time.perf_counter() - start) / n * 1e6
    print(f"CartesianImpedanceController.CalcTorque: {per_call_us:.1f} us per call")
    assert tau.shape == (7,)
    assert np.all(np.isfinite(tau))


def test_tracking_error_output_is_the_translational_error_of_the_last_update():
    control_plant = MakePandaControlModel(X_HE, PAYLOAD_MASS_KG, PAYLOAD_COM_H)
    controller = CartesianImpedanceController(control_plant)
    ctx = control_plant.CreateDefaultContext()
    control_plant.SetPositions(ctx, PANDA_HOME_Q)
    X_WE = control_plant.GetFrameByName("controlled_frame_E").CalcPoseInWorld(ctx)
    dp = np.array([0.003, -0.002, 0.001])
    context = controller.CreateDefaultContext()
    controller.GetInputPort("panda_state").FixValue(
        context, np.concatenate([PANDA_HOME_Q, np.zeros(7)])
    )
    desired = np.concatenate([X_WE.translation() + dp, X_WE.rotation().ToQuaternion().wxyz()])
    controller.GetInputPort("X_WE_desired").FixValue(context, desired)
    controller.GetInputPort("V_WE_desired").FixValue(context, np.zeros(6))
    np.testing.assert_array_equal(controller.GetOutputPort("tracking_error").Eval(context), 0.0)
    simulator = Simulator(controller, context)
    simulator.Initialize()  # the initialisation update computes torque and error
    error = controller.GetOutputPort("tracking_error").Eval(simulator.get_context())
    np.testing.assert_allclose(error, dp, atol=1e-12)
    assert not controller.HasDirectFeedthrough(
        controller.GetInputPort("X_WE_desired").get_index(),
        controller.GetOutputPort("tracking_error").get_index(),
    )
