"""The scalar hot-loop maths of control_math against the array implementations."""

import numpy as np
import pytest

from rlfd_drake.control_math import (
    quat_exp_rotation_vector,
    quat_multiply_scalar,
    rotation_vector_between,
    so3_left_jacobian_inverse,
    so3_left_jacobian_inverse_apply,
)
from rlfd_drake.geometry import (
    quat_conjugate,
    quat_from_rotation_vector,
    quat_multiply,
    quat_normalize,
    rotation_vector_from_quat,
)

RNG = np.random.default_rng(7)


def _random_quats(n: int) -> np.ndarray:
    return quat_normalize(RNG.normal(size=(n, 4)))


def test_quat_multiply_scalar_matches_array_product():
    for a, b in zip(_random_quats(50), _random_quats(50), strict=True):
        np.testing.assert_allclose(quat_multiply_scalar(a, b), quat_multiply(a, b), atol=1e-14)


def test_rotation_vector_between_matches_log_of_relative_rotation():
    for q, q_ref in zip(_random_quats(50), _random_quats(50), strict=True):
        expected = rotation_vector_from_quat(quat_multiply(q, quat_conjugate(q_ref)))
        np.testing.assert_allclose(rotation_vector_between(q, q_ref), expected, atol=1e-12)
        # Unnormalised inputs and the double cover give the same rotation vector.
        np.testing.assert_allclose(
            rotation_vector_between(-3.0 * q, 0.5 * q_ref), expected, atol=1e-12
        )
    assert rotation_vector_between(np.array([1.0, 0, 0, 0]), np.array([1.0, 0, 0, 0])) == (
        0.0,
        0.0,
        0.0,
    )


def test_quat_exp_rotation_vector_matches_exponential_map():
    for r in [*RNG.normal(size=(30, 3)), np.zeros(3), np.full(3, 1e-14)]:
        q = np.array(quat_exp_rotation_vector(*r))
        np.testing.assert_allclose(np.linalg.norm(q), 1.0, atol=1e-14)
        expected = quat_from_rotation_vector(r)
        sign = 1.0 if q @ expected >= 0 else -1.0
        np.testing.assert_allclose(q, sign * expected, atol=1e-12)


def test_left_jacobian_inverse_apply_matches_matrix():
    for r in [*RNG.uniform(-3.0, 3.0, size=(30, 3)), np.zeros(3), np.full(3, 1e-7)]:
        w = RNG.normal(size=3)
        np.testing.assert_allclose(
            so3_left_jacobian_inverse_apply(r, w), so3_left_jacobian_inverse(r) @ w, atol=1e-10
        )


def test_keep_residual_part_keeps_one_half_and_names_a_bad_mode():
    from rlfd_drake.control_math import keep_residual_part

    action = np.arange(1.0, 7.0)
    np.testing.assert_array_equal(keep_residual_part(action, "full"), action)
    np.testing.assert_array_equal(keep_residual_part(action, "translation"), [1, 2, 3, 0, 0, 0])
    np.testing.assert_array_equal(keep_residual_part(action, "orientation"), [0, 0, 0, 4, 5, 6])
    np.testing.assert_array_equal(keep_residual_part(action, "off"), np.zeros(6))
    with pytest.raises(ValueError, match="'twist'"):
        keep_residual_part(action, "twist")
    with pytest.raises(ValueError, match="6 numbers"):
        keep_residual_part(action[:3], "full")
