"""DmpSystem in a Drake Simulator reproduces dmp.rollout; start pose from port or setter."""

import dataclasses

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from rlfd_drake import dmp
from rlfd_drake import geometry as G
from rlfd_drake.bench.dmp import synthetic_demonstration
from rlfd_drake.systems.dmp_system import DmpSystem


@pytest.fixture(scope="module")
def model():
    return dmp.fit_cartesian_dmp(*synthetic_demonstration(duration_s=2.0))


def build(model, start=None, coupling=None, **kwargs):
    builder = DiagramBuilder()
    system = builder.AddSystem(DmpSystem(model, **kwargs))
    if start is not None:
        src = builder.AddSystem(ConstantVectorSource(start))
        builder.Connect(src.get_output_port(), system.GetInputPort("X_WE_start"))
    if coupling is not None:
        src = builder.AddSystem(ConstantVectorSource(coupling))
        builder.Connect(src.get_output_port(), system.GetInputPort("coupling"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    return system, simulator


def outputs(system, simulator):
    ctx = system.GetMyContextFromRoot(simulator.get_context())
    return (
        system.GetOutputPort("X_WE_desired").Eval(ctx),
        system.GetOutputPort("V_WE_desired").Eval(ctx),
        system.GetOutputPort("phase").Eval(ctx)[0],
    )


def compare(system, simulator, rollout, n_steps):
    t, p, v, q, w = rollout
    x, vel, phase = outputs(system, simulator)
    np.testing.assert_allclose(x, np.concatenate([p[0], q[0]]), atol=1e-12)
    assert phase == 1.0
    for k in range(1, n_steps + 1):
        simulator.AdvanceTo(t[k])
        x, vel, phase = outputs(system, simulator)
        np.testing.assert_allclose(x[:3], p[k], atol=1e-9)
        np.testing.assert_allclose(x[3:], q[k], atol=1e-9)
        np.testing.assert_allclose(vel[:3], w[k], atol=1e-9)  # Drake order [w; v]
        np.testing.assert_allclose(vel[3:], v[k], atol=1e-9)


def test_ports_and_no_feedthrough(model):
    system = DmpSystem(model)
    assert [system.get_input_port(i).get_name() for i in range(2)] == ["coupling", "X_WE_start"]
    names = [system.get_output_port(i).get_name() for i in range(3)]
    assert names == ["X_WE_desired", "V_WE_desired", "phase"]
    assert not system.HasAnyDirectFeedthrough()
    with pytest.raises(ValueError, match="period_s"):
        DmpSystem(model, period_s=0.0)


def test_matches_rollout_from_demo_start(model):
    system, simulator = build(model)
    simulator.Initialize()
    ro = dmp.rollout(model, dt=0.01, duration=2.5)
    compare(system, simulator, ro, n_steps=250)


def test_start_pose_from_input_port_and_goal_tau(model):
    start_q = G.quat_multiply(G.quat_from_angle_axis(0.5, [1.0, 0.2, 0.0]), model.q0)
    start = np.concatenate([model.y0 + [0.05, -0.08, 0.03], start_q])
    goal = model.g + [0.01, 0.02, -0.01]
    coupling = np.array([0.2, 0.0, -0.1, 0.0, 0.05, 0.0])
    system, simulator = build(
        model, start=start, coupling=coupling, goal_position=goal, tau=3.0, period_s=0.02
    )
    simulator.Initialize()
    ro = dmp.rollout(
        model, start[:3], start[3:], goal, tau=3.0, dt=0.02, duration=1.0, coupling=coupling
    )
    compare(system, simulator, ro, n_steps=50)


def test_set_start_pose_survives_initialize(model):
    system, simulator = build(model)
    start_q = G.quat_from_angle_axis(0.3, [0.0, 0.0, 1.0])
    start_p = model.y0 + [0.1, 0.0, 0.0]
    ctx = system.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    system.SetStartPose(ctx, start_p, start_q)
    simulator.Initialize()
    ro = dmp.rollout(model, start_p, start_q, dt=0.01, duration=0.5)
    compare(system, simulator, ro, n_steps=50)


def test_phase_stop_time_scale_is_one_plus_gain_times_excess_squared():
    assert dmp.phase_stop_time_scale(np.array([0.003, 0.0, 0.004]), 0.0, 0.0) == 1.0
    assert dmp.phase_stop_time_scale(np.array([0.001, 0.0, 0.0]), 1e6, 0.0015) == 1.0
    # |e| = 5 mm, 3 mm past a 2 mm deadband: 1 + 1e6 * (3e-3)^2 = 10.
    scale = dmp.phase_stop_time_scale(np.array([0.003, 0.0, 0.004]), 1e6, 0.002)
    assert scale == pytest.approx(10.0, rel=1e-12)
    with pytest.raises(ValueError, match="gain_per_m2"):
        dmp.phase_stop_time_scale(np.zeros(3), -1.0)
    with pytest.raises(ValueError, match="deadband_m"):
        dmp.phase_stop_time_scale(np.zeros(3), 1.0, float("nan"))
    with pytest.raises(ValueError, match="tracking_error_m"):
        dmp.phase_stop_time_scale(np.array([np.nan, 0.0, 0.0]), 1.0)
    with pytest.raises(ValueError, match="tracking_error_m"):
        dmp.phase_stop_time_scale(np.zeros(2), 1.0)


def build_with_tracking_error(model, error, **kwargs):
    builder = DiagramBuilder()
    system = builder.AddSystem(DmpSystem(model, **kwargs))
    src = builder.AddSystem(ConstantVectorSource(error))
    builder.Connect(src.get_output_port(), system.GetInputPort("tracking_error"))
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    return system, simulator


def test_phase_stopping_runs_the_whole_dmp_with_a_longer_tau(model):
    # A constant error 2 mm past the deadband: tau x (1 + 2.5e5 * 4e-6) = tau x 2, so the
    # phase-stopped DMP is the open-loop DMP with twice the demonstration's tau.
    error = np.array([0.0, 0.003, 0.0])
    system, simulator = build_with_tracking_error(
        model, error, phase_stop_gain_per_m2=2.5e5, phase_stop_deadband_m=0.001
    )
    ro = dmp.rollout(model, dt=0.01, duration=1.0, tau=2.0 * model.tau)
    compare(system, simulator, ro, n_steps=100)
    ctx = system.GetMyContextFromRoot(simulator.get_context())
    assert system.time_scale(ctx) == pytest.approx(2.0, rel=1e-12)
    assert system.phase_stop_gain_per_m2 == 2.5e5


def test_phase_stopping_off_or_within_the_deadband_is_the_paper_dmp(model):
    ro = dmp.rollout(model, dt=0.01, duration=1.0)
    for kwargs in ({}, {"phase_stop_gain_per_m2": 1e6, "phase_stop_deadband_m": 0.005}):
        system, simulator = build_with_tracking_error(model, np.array([0.0, 0.0, 0.004]), **kwargs)
        compare(system, simulator, ro, n_steps=100)
    with pytest.raises(ValueError, match="gain_per_m2"):
        DmpSystem(model, phase_stop_gain_per_m2=-1.0)
    with pytest.raises(ValueError, match="deadband_m"):
        DmpSystem(model, phase_stop_gain_per_m2=1.0, phase_stop_deadband_m=-0.001)


def test_forcing_weights_are_swapped_and_nothing_else(model):
    """One diagram serves the episodic baselines' rollouts: only the weights change."""
    system, simulator = build(model)
    other = dmp.with_weights(model, 2.0 * dmp.get_weights(model))
    system.SetForcingWeights(other)
    assert system.model is other
    moved = dataclasses.replace(model, y0=model.y0 + 0.01)
    with pytest.raises(ValueError, match="only the forcing weights may change: y0"):
        system.SetForcingWeights(moved)
