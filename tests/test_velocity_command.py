"""VelocityCommandSetpoint: the pure-RL and hybrid baselines' set-point (Table III)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from rlfd_drake.diagram import BuildRlfdDiagram, RlfdDiagramConfig, SetEpisodeStart
from rlfd_drake.episode import demo_start_pose
from rlfd_drake.systems.velocity_command import VelocityCommandConfig, VelocityCommandSetpoint

BASE_X = np.array([0.4, 0.1, 0.3, 0.0, 1.0, 0.0, 0.0])
BASE_V = np.array([0.1, 0.2, 0.3, 0.01, 0.02, 0.03])


def _simulate(config: VelocityCommandConfig, command: np.ndarray, t_end: float):
    builder = DiagramBuilder()
    system = builder.AddSystem(VelocityCommandSetpoint(config))
    for name, value in (("X_WE_base", BASE_X), ("V_WE_base", BASE_V), ("residual", command)):
        source = builder.AddSystem(ConstantVectorSource(value))
        builder.Connect(source.get_output_port(), system.GetInputPort(name))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.Initialize()
    simulator.AdvanceTo(t_end)
    context = system.GetMyContextFromRoot(simulator.get_context())
    return (
        system.GetOutputPort("X_WE_desired").Eval(context),
        system.GetOutputPort("V_WE_desired").Eval(context),
    )


def test_passes_the_base_through_before_activation():
    config = VelocityCommandConfig(activation_time_s=0.5)
    X, V = _simulate(config, np.full(6, 0.7), 0.3)
    np.testing.assert_array_equal(X, BASE_X)
    np.testing.assert_array_equal(V, BASE_V)


def test_integrates_a_constant_command_from_the_latched_pose():
    config = VelocityCommandConfig(activation_time_s=0.2, max_speed_m_s=0.05)
    command = np.array([0.5, -1.0, 0.2, 0.3, -0.6, 0.9])
    t_end = 1.2
    X, V = _simulate(config, command, t_end)
    # Latched at 0.2 s, then one update per 2 ms tick up to (not including) t_end.
    moving = t_end - config.activation_time_s
    v = command[:3] * config.max_speed_m_s
    w = command[3:] * config.max_angular_speed_rad_s
    np.testing.assert_allclose(X[:3], BASE_X[:3] + v * moving, atol=1e-9)
    # exp(w t) o Q_base, against Drake's rotation maths.
    angle = np.linalg.norm(w * moving)
    axis = w / np.linalg.norm(w)
    R_delta = RotationMatrix(
        Quaternion(np.concatenate([[np.cos(angle / 2)], axis * np.sin(angle / 2)]))
    )
    R_expected = R_delta @ RotationMatrix(Quaternion(BASE_X[3:]))
    R_actual = RotationMatrix(Quaternion(X[3:] / np.linalg.norm(X[3:])))
    np.testing.assert_allclose(R_actual.matrix(), R_expected.matrix(), atol=1e-9)
    np.testing.assert_allclose(V, np.concatenate([w, v]))  # feed-forward twist [w; v]


def test_translation_mode_leaves_the_orientation_where_it_was_latched():
    config = VelocityCommandConfig(activation_time_s=0.0, mode="translation")
    X, V = _simulate(config, np.ones(6), 0.5)
    np.testing.assert_allclose(X[3:], BASE_X[3:], atol=1e-12)
    assert np.all(X[:3] > BASE_X[:3])
    np.testing.assert_array_equal(V[:3], 0.0)


def test_non_finite_command_raises_and_bad_config_names_the_field():
    with pytest.raises(RuntimeError, match="non-finite"):
        _simulate(VelocityCommandConfig(), np.full(6, np.nan), 0.01)
    with pytest.raises(ValueError, match="max_speed_m_s"):
        VelocityCommandSetpoint(VelocityCommandConfig(max_speed_m_s=-1.0))
    with pytest.raises(ValueError, match="mode"):
        VelocityCommandSetpoint(VelocityCommandConfig(mode="twist"))
    with pytest.raises(ValueError, match="composition"):
        RlfdDiagramConfig(composition="mixed")


@pytest.mark.parametrize("composition", ["pure", "hybrid"])
def test_pure_and_hybrid_diagrams_hold_the_setpoint_without_commands(composition, peg_easy, dmp):
    """Zero commands: the pure set-point stays at the start (the DMP never moves it);
    the hybrid's follows the DMP until the switch, then stays where the DMP was."""
    config = RlfdDiagramConfig(composition=composition, residual_activation_s=1.0)
    rlfd = BuildRlfdDiagram(peg_easy, dmp, config)
    assert type(rlfd.composer) is VelocityCommandSetpoint
    simulator = Simulator(rlfd.diagram)
    context = simulator.get_mutable_context()
    rlfd.diagram.GetInputPort("residual").FixValue(context, np.zeros(6))
    X_start = demo_start_pose(dmp)
    SetEpisodeStart(rlfd, context, X_start)
    simulator.Initialize()
    setpoints = {}
    for t in (0.5, 1.5, 2.5):
        simulator.AdvanceTo(t)
        setpoints[t] = (
            rlfd.diagram.GetOutputPort("X_WE_desired").Eval(context).copy(),
            rlfd.diagram.GetOutputPort("X_WE_base").Eval(context).copy(),
        )
    base_moved = np.linalg.norm(setpoints[2.5][1][:3] - setpoints[0.5][1][:3])
    assert base_moved > 0.01  # the DMP moves on...
    if composition == "pure":
        for X, _ in setpoints.values():  # ...but not the pure set-point (the IK's start)
            np.testing.assert_array_equal(X, setpoints[0.5][0])
            np.testing.assert_allclose(X[:3], X_start.translation(), atol=1e-4)
    else:
        np.testing.assert_array_equal(setpoints[0.5][0], setpoints[0.5][1])
        np.testing.assert_allclose(setpoints[2.5][0], setpoints[1.5][0], atol=1e-12)
        assert np.linalg.norm(setpoints[1.5][0][:3] - setpoints[0.5][1][:3]) > 1e-3
