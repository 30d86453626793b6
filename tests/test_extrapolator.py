"""QuinticExtrapolator and the Hermite maths behind it."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import VectorLogSink

from rlfd_drake.control_math import (
    hermite_fit,
    polynomial_eval,
    so3_left_jacobian,
    so3_left_jacobian_inverse,
)
from rlfd_drake.geometry import (
    quat_error,
    quat_from_rotation_vector,
    quat_multiply,
    rotation_vector_from_quat,
)
from rlfd_drake.systems.extrapolator import QuinticExtrapolator, QuinticExtrapolatorConfig

Trajectory = Callable[[float], tuple[np.ndarray, np.ndarray]]


class TrajectorySource(LeafSystem):
    """Outputs X (7) and V (6) of a trajectory function of time (test helper)."""

    def __init__(self, trajectory: Trajectory):
        super().__init__()
        self._f = trajectory
        self.DeclareVectorOutputPort("X", 7, self._X)
        self.DeclareVectorOutputPort("V", 6, self._V)

    def _X(self, context, output: BasicVector) -> None:
        output.SetFromVector(self._f(context.get_time())[0])

    def _V(self, context, output: BasicVector) -> None:
        output.SetFromVector(self._f(context.get_time())[1])


def _run(trajectory: Trajectory, duration: float = 0.5):
    """Logs the extrapolator's outputs at 500 Hz; returns times, X (N, 7), V (N, 6)."""
    builder = DiagramBuilder()
    source = builder.AddSystem(TrajectorySource(trajectory))
    extrapolator = builder.AddSystem(QuinticExtrapolator(QuinticExtrapolatorConfig(0.01)))
    builder.Connect(source.GetOutputPort("X"), extrapolator.GetInputPort("X_WE_dmp"))
    builder.Connect(source.GetOutputPort("V"), extrapolator.GetInputPort("V_WE_dmp"))
    log_X = builder.AddSystem(VectorLogSink(7, 0.002))
    log_V = builder.AddSystem(VectorLogSink(6, 0.002))
    builder.Connect(extrapolator.GetOutputPort("X_WE_desired"), log_X.get_input_port())
    builder.Connect(extrapolator.GetOutputPort("V_WE_desired"), log_V.get_input_port())
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    X, V = log_X.FindLog(context), log_V.FindLog(context)
    return X.sample_times(), X.data().T, V.data().T


def _quintic_position(t: float) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([[0.4, 0.0, 0.3], [0.1, -0.2, 0.05], [-0.3, 0.4, 0.2], [0.5, 0.1, -0.6]])
    a = np.vstack([a, [[-0.7, 0.3, 0.4], [0.8, -0.5, 0.2]]])  # (6, 3) coefficients
    k = np.arange(6)
    p = (t**k) @ a
    dp = np.concatenate([[0.0], k[1:] * t ** (k[1:] - 1)]) @ a
    return p, dp


def _fixed_axis_quintic_rotation(t: float) -> tuple[np.ndarray, np.ndarray]:
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    c = np.array([0.1, 0.8, -1.2, 2.0, -1.5, 0.6])
    k = np.arange(6)
    theta = (t**k) @ c
    dtheta = np.concatenate([[0.0], k[1:] * t ** (k[1:] - 1)]) @ c
    Q0 = np.array([0.0, 1.0, 0.0, 0.0])
    return quat_multiply(quat_from_rotation_vector(theta * axis), Q0), dtheta * axis


def test_hermite_fit_reproduces_quintic():
    rng = np.random.default_rng(1)
    coeffs = rng.normal(size=(6, 2))
    times = np.array([-2.0, -1.0, 0.0])
    values = np.array([polynomial_eval(coeffs, t)[0] for t in times])
    rates = np.array([polynomial_eval(coeffs, t)[1] for t in times])
    np.testing.assert_allclose(hermite_fit(times, values, rates), coeffs, atol=1e-12)
    with pytest.raises(ValueError, match="distinct"):
        hermite_fit(np.array([0.0, 0.0]), values[:2], rates[:2])


def test_so3_left_jacobian_inverse_and_kinematics():
    rng = np.random.default_rng(2)
    for r in [rng.normal(size=3), 1e-7 * rng.normal(size=3), np.zeros(3)]:
        np.testing.assert_allclose(
            so3_left_jacobian(r) @ so3_left_jacobian_inverse(r), np.eye(3), atol=1e-10
        )
    # w = J_l(r) dr/dt for Q(t) = Exp(r(t)) Q_ref, checked by finite differences.
    r, dr, dt = rng.normal(size=3), rng.normal(size=3), 1e-6
    Q1 = quat_from_rotation_vector(r)
    Q2 = quat_from_rotation_vector(r + dt * dr)
    w_fd = rotation_vector_from_quat(quat_multiply(Q2, np.array([1, -1, -1, -1]) * Q1)) / dt
    np.testing.assert_allclose(so3_left_jacobian(r) @ dr, w_fd, atol=1e-5)


def test_reproduces_quintic_exactly():
    def trajectory(t):
        p, dp = _quintic_position(t)
        Q, w = _fixed_axis_quintic_rotation(t)
        return np.concatenate([p, Q]), np.concatenate([w, dp])

    times, X, V = _run(trajectory, 0.3)
    checked = 0
    for t, x, v in zip(times, X, V, strict=True):
        if t < 0.02 + 1e-9:  # three samples needed (the log at 0.02 precedes its update)
            continue
        x_true, v_true = trajectory(t)
        np.testing.assert_allclose(x[:3], x_true[:3], atol=1e-9)
        assert np.linalg.norm(quat_error(x_true[3:], x[3:])) < 1e-9
        np.testing.assert_allclose(v, v_true, atol=1e-8)
        checked += 1
    assert checked > 100


def test_smooth_sine_and_rotation_within_tolerance():
    """A 1 Hz sine (5 cm amplitude) and a rotation with a turning axis."""
    w0 = 2 * np.pi

    def trajectory(t):
        p = np.array([0.5 + 0.05 * np.sin(w0 * t), 0.05 * np.cos(w0 * t), 0.3])
        dp = np.array([0.05 * w0 * np.cos(w0 * t), -0.05 * w0 * np.sin(w0 * t), 0.0])
        # Q(t) = Exp(a t z) o Exp(b t x): angular velocity a z + b Exp(a t z) x.
        a, b = 0.8, 0.5
        Qz = quat_from_rotation_vector(np.array([0.0, 0.0, a * t]))
        Q = quat_multiply(Qz, quat_from_rotation_vector(np.array([b * t, 0.0, 0.0])))
        R_z = np.array(
            [[np.cos(a * t), -np.sin(a * t), 0], [np.sin(a * t), np.cos(a * t), 0], [0, 0, 1]]
        )
        w = np.array([0.0, 0.0, a]) + b * R_z @ np.array([1.0, 0.0, 0.0])
        return np.concatenate([p, Q]), np.concatenate([w, dp])

    times, X, V = _run(trajectory, 1.0)
    pos_err, ang_err, norm_err = [], [], []
    for t, x in zip(times, X, strict=True):
        if t < 0.02 + 1e-9:
            continue
        x_true, _ = trajectory(t)
        pos_err.append(np.linalg.norm(x[:3] - x_true[:3]))
        ang_err.append(np.linalg.norm(quat_error(x_true[3:], x[3:])))
        norm_err.append(abs(np.linalg.norm(x[3:]) - 1.0))
    print(f"sine: max position error {max(pos_err):.2e} m, orientation {max(ang_err):.2e} rad")
    # Extrapolating 10 ms ahead of a 5 cm, 1 Hz sine: error ~ (2 pi)^6 A h^6 ~ 3e-9 m.
    assert max(pos_err) < 1e-7
    assert max(ang_err) < 1e-6
    assert max(norm_err) < 1e-12


def test_first_samples_hold_and_extrapolate_linearly():
    def trajectory(t):
        return np.array([1.0 + 0.1 * t, 0, 0, 1, 0, 0, 0]), np.array([0, 0, 0, 0.1, 0, 0])

    times, X, V = _run(trajectory, 0.02)
    # Linear extrapolation from the first sample is exact for a straight line.
    np.testing.assert_allclose(X[:, 0], 1.0 + 0.1 * times, atol=1e-12)
    np.testing.assert_allclose(V[:, 3], 0.1, atol=1e-12)


def test_output_cost_and_rejects_nan():
    extrapolator = QuinticExtrapolator()
    context = extrapolator.CreateDefaultContext()
    X_in = np.array([0.5, 0.0, 0.4, 0.0, 1.0, 0.0, 0.0])
    extrapolator.GetInputPort("X_WE_dmp").FixValue(context, X_in)
    extrapolator.GetInputPort("V_WE_dmp").FixValue(context, np.full(6, 0.01))
    simulator = Simulator(extrapolator, context)
    simulator.AdvanceTo(0.03)
    X_port = extrapolator.GetOutputPort("X_WE_desired")
    V_port = extrapolator.GetOutputPort("V_WE_desired")
    n = 1000
    start = time.perf_counter()
    for i in range(n):
        context.SetTime(0.03 + 1e-6 * i)  # new time: no cache hit
        X_port.Eval(context)
        V_port.Eval(context)
    per_call_us = (time.perf_counter() - start) / n * 1e6
    print(f"QuinticExtrapolator X + V outputs: {per_call_us:.1f} us per 500 Hz tick")
    extrapolator.GetInputPort("X_WE_dmp").FixValue(context, np.full(7, np.nan))
    with pytest.raises(RuntimeError, match="non-finite"):
        simulator.Initialize()
