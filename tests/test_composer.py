"""ResidualComposer and the residual maths."""

from __future__ import annotations

import time

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix

from rlfd_drake.control_math import compose_residual_pose, residual_quaternion, scale_residual
from rlfd_drake.systems.composer import ResidualComposer, ResidualComposerConfig


def _random_pose(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return np.concatenate([rng.normal(size=3), q / np.linalg.norm(q)])


def _outputs(composer, X, V, residual, t):
    context = composer.CreateDefaultContext()
    context.SetTime(t)
    composer.GetInputPort("X_WE_base").FixValue(context, X)
    composer.GetInputPort("V_WE_base").FixValue(context, V)
    composer.GetInputPort("residual").FixValue(context, residual)
    return (
        composer.GetOutputPort("X_WE_desired").Eval(context),
        composer.GetOutputPort("V_WE_desired").Eval(context),
    )


def test_matches_drake_rotation_maths():
    rng = np.random.default_rng(3)
    config = ResidualComposerConfig(activation_time_s=0.0)
    composer = ResidualComposer(config)
    for _ in range(50):
        X, V = _random_pose(rng), rng.normal(size=6)
        a = rng.uniform(-1, 1, size=6)
        X_f, V_f = _outputs(composer, X, V, a, 1.0)
        rotvec = a[3:] * config.max_rotation_rad
        alpha = np.linalg.norm(rotvec)
        R_delta = RotationMatrix(Quaternion(residual_quaternion(rotvec)))
        # Drake: R_f = R_delta R_b, with R_delta the rotation of angle alpha about rotvec.
        np.testing.assert_allclose(R_delta.matrix() @ rotvec, rotvec, atol=1e-12)
        np.testing.assert_allclose(np.arccos((np.trace(R_delta.matrix()) - 1) / 2), alpha)
        R_f = R_delta @ RotationMatrix(Quaternion(X[3:]))
        np.testing.assert_allclose(
            RotationMatrix(Quaternion(X_f[3:])).matrix(), R_f.matrix(), atol=1e-12
        )
        np.testing.assert_allclose(X_f[:3], X[:3] + a[:3] * config.max_translation_m)
        np.testing.assert_allclose(np.linalg.norm(X_f[3:]), 1.0, atol=1e-12)
        np.testing.assert_array_equal(V_f, V)
        # The pure-numpy composition agrees.
        p_f, Q_f = compose_residual_pose(X[:3], X[3:], a[:3] * config.max_translation_m, rotvec)
        np.testing.assert_allclose(np.concatenate([p_f, Q_f]), X_f, atol=1e-12)


def test_zero_residual_is_exact_and_activation_respected():
    rng = np.random.default_rng(4)
    X, V = _random_pose(rng), rng.normal(size=6)
    composer = ResidualComposer(ResidualComposerConfig(activation_time_s=5.0))
    X_f, _ = _outputs(composer, X, V, np.zeros(6), 6.0)
    np.testing.assert_array_equal(X_f, X)
    a = np.full(6, 0.5)
    X_before, _ = _outputs(composer, X, V, a, 4.999)
    np.testing.assert_array_equal(X_before, X)
    X_after, _ = _outputs(composer, X, V, a, 5.0)
    assert np.linalg.norm(X_after[:3] - X[:3]) > 0.01


def test_modes_touch_only_their_part_and_inputs_are_clipped():
    rng = np.random.default_rng(5)
    X, V = _random_pose(rng), np.zeros(6)
    a = np.array([0.3, -0.2, 0.9, 0.4, 0.1, -0.7])
    X_t, _ = _outputs(
        ResidualComposer(ResidualComposerConfig(mode="translation", activation_time_s=0.0)),
        X,
        V,
        a,
        0.0,
    )
    np.testing.assert_array_equal(X_t[3:], X[3:])
    assert np.linalg.norm(X_t[:3] - X[:3]) > 0.0
    X_o, _ = _outputs(
        ResidualComposer(ResidualComposerConfig(mode="orientation", activation_time_s=0.0)),
        X,
        V,
        a,
        0.0,
    )
    np.testing.assert_array_equal(X_o[:3], X[:3])
    assert np.linalg.norm(X_o[3:] - X[3:]) > 0.0
    X_off, _ = _outputs(
        ResidualComposer(ResidualComposerConfig(mode="off", activation_time_s=0.0)), X, V, a, 0.0
    )
    np.testing.assert_array_equal(X_off, X)
    full = ResidualComposer(ResidualComposerConfig(activation_time_s=0.0))
    X_big, _ = _outputs(full, X, V, 7.0 * a / np.abs(a).max(), 0.0)
    X_one, _ = _outputs(full, X, V, np.clip(7.0 * a / np.abs(a).max(), -1, 1), 0.0)
    np.testing.assert_array_equal(X_big, X_one)
    # The rotation angle is bounded by pi even for huge scales.
    _, rotvec = scale_residual(np.ones(6), 0.02, 10.0)
    assert np.linalg.norm(rotvec) == pytest.approx(np.pi)
    with pytest.raises(ValueError, match="mode"):
        ResidualComposer(ResidualComposerConfig(mode="both"))


def test_nan_residual_raises_and_cost():
    composer = ResidualComposer(ResidualComposerConfig(activation_time_s=0.0))
    X = np.array([0.5, 0.0, 0.4, 0.0, 1.0, 0.0, 0.0])
    with pytest.raises(RuntimeError, match="'residual'"):
        _outputs(composer, X, np.zeros(6), np.array([0, 0, np.nan, 0, 0, 0]), 1.0)
    context = composer.CreateDefaultContext()
    composer.GetInputPort("X_WE_base").FixValue(context, X)
    composer.GetInputPort("V_WE_base").FixValue(context, np.zeros(6))
    composer.GetInputPort("residual").FixValue(context, np.full(6, 0.1))
    X_port, V_port = composer.GetOutputPort("X_WE_desired"), composer.GetOutputPort("V_WE_desired")
    n = 1000
    start = time.perf_counter()
    for i in range(n):
        context.SetTime(1.0 + 1e-6 * i)
        X_port.Eval(context)
        V_port.Eval(context)
    per_call_us = (time.perf_counter() - start) / n * 1e6
    print(f"ResidualComposer X + V (active residual): {per_call_us:.1f} us")


def test_a_push_bound_limits_only_the_downward_translation():
    """``max_push_m`` caps dp's world -z part; lifting and the other axes keep the range."""
    down = np.array([0.5, -0.5, -1.0, 0.2, 0.0, 0.0])
    dp, rotvec = scale_residual(down, 0.01, 0.035, max_push_m=0.002)
    np.testing.assert_allclose(dp, [0.005, -0.005, -0.002])
    np.testing.assert_allclose(rotvec, [0.007, 0.0, 0.0])
    up = np.array([0.0, 0.0, 0.8, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(scale_residual(up, 0.01, 0.035, max_push_m=0.0)[0], [0, 0, 0.008])
    assert scale_residual(down, 0.01, 0.035, max_push_m=0.0)[0][2] == 0.0
    np.testing.assert_allclose(scale_residual(down, 0.01, 0.035)[0], [0.005, -0.005, -0.01])
    rng = np.random.default_rng(3)
    X, V = _random_pose(rng), np.zeros(6)
    config = ResidualComposerConfig(max_translation_m=0.01, activation_time_s=0.0, max_push_m=0.0)
    X_f, _ = _outputs(ResidualComposer(config), X, V, down, 0.0)
    np.testing.assert_allclose(X_f[:3] - X[:3], [0.005, -0.005, 0.0], atol=1e-15)
    for bad in (-0.001, float("nan")):
        with pytest.raises(ValueError, match="max_push_m"):
            ResidualComposer(ResidualComposerConfig(max_push_m=bad))
