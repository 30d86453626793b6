"""Quaternion maths: identities, Drake cross-checks, limits, batch shapes."""

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix

from rlfd_drake import geometry as G


def random_quats(n, seed=0):
    rng = np.random.default_rng(seed)
    return G.quat_normalize(rng.normal(size=(n, 4)))


def drake_matrix(q):
    return RotationMatrix(Quaternion(q / np.linalg.norm(q))).matrix()


def same_rotation(a, b, atol=1e-12):
    return np.allclose(G.quat_canonical(a), G.quat_canonical(b), atol=atol)


def test_geometry_does_not_import_pydrake():
    import ast
    import inspect

    tree = ast.parse(inspect.getsource(G))
    names = [
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.Import | ast.ImportFrom)
        for alias in node.names
    ]
    modules = [node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
    assert not any("pydrake" in str(m) for m in names + modules)


def test_rotation_matrix_matches_drake_and_composition():
    qs = random_quats(20)
    for a, b in zip(qs[:10], qs[10:], strict=True):
        np.testing.assert_allclose(G.quat_to_rotation_matrix(a), drake_matrix(a), atol=1e-12)
        ab = G.quat_multiply(a, b)
        # The defining property of the paper's composition: R(a ∘ b) = R(a) R(b).
        np.testing.assert_allclose(
            G.quat_to_rotation_matrix(ab), drake_matrix(a) @ drake_matrix(b), atol=1e-12
        )
        dq = Quaternion(a).multiply(Quaternion(b))
        np.testing.assert_allclose(ab, dq.wxyz(), atol=1e-12)


def test_from_rotation_matrix_roundtrip_and_drake():
    qs = random_quats(50, seed=1)
    # Include near-180-degree rotations (w ~ 0) where the trace pivot fails.
    qs = np.vstack([qs, G.quat_from_angle_axis(np.pi - 1e-9, [0.3, -0.2, 0.9])])
    R = G.quat_to_rotation_matrix(qs)
    back = G.quat_from_rotation_matrix(R)
    assert back.shape == qs.shape
    assert np.all(back[:, 0] >= 0.0)
    for q, b in zip(qs, back, strict=True):
        assert same_rotation(q, b, atol=1e-9)
        drake_q = RotationMatrix(drake_matrix(q)).ToQuaternion().wxyz()
        assert same_rotation(drake_q, b, atol=1e-9)


def test_exp_log_identities_and_batch_shapes():
    qs = random_quats(30, seed=2).reshape(5, 6, 4)
    logs = G.quat_log(qs)
    assert logs.shape == (5, 6, 3)
    np.testing.assert_allclose(G.quat_exp(logs), qs, atol=1e-12)
    rv = G.rotation_vector_from_quat(qs)
    assert np.all(np.linalg.norm(rv, axis=-1) <= np.pi + 1e-12)
    assert same_rotation(G.quat_from_rotation_vector(rv).reshape(-1, 4), qs.reshape(-1, 4))
    # log of -q differs but the rotation vector is the same (shortest path).
    np.testing.assert_allclose(G.rotation_vector_from_quat(-qs), rv, atol=1e-12)


def test_small_angle_limits():
    for eps in (0.0, 1e-14, 1e-9, 1e-6):
        v = eps * np.array([0.6, -0.8, 0.0])
        q = G.quat_exp(v)
        assert np.all(np.isfinite(q))
        np.testing.assert_allclose(np.linalg.norm(q), 1.0, atol=1e-15)
        np.testing.assert_allclose(G.quat_log(q), v, atol=1e-20, rtol=1e-9)
    np.testing.assert_array_equal(G.quat_log(G.IDENTITY_QUAT), np.zeros(3))
    # log(-1) is a pi rotation; exp brings it back.
    np.testing.assert_allclose(
        G.quat_exp(G.quat_log(-G.IDENTITY_QUAT)), -G.IDENTITY_QUAT, atol=1e-15
    )


def test_angle_axis_per_paper():
    q = G.quat_from_angle_axis(np.pi / 2, [0.0, 0.0, 2.0])
    np.testing.assert_allclose(q, [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], atol=1e-15)
    np.testing.assert_allclose(G.rotation_vector_from_quat(q), [0, 0, np.pi / 2], atol=1e-15)
    np.testing.assert_array_equal(G.quat_from_angle_axis(1.0, np.zeros(3)), G.IDENTITY_QUAT)
    batch = G.quat_from_angle_axis(np.array([0.1, 0.2]), np.array([[1.0, 0, 0], [0, 0, 0]]))
    assert batch.shape == (2, 4)
    np.testing.assert_array_equal(batch[1], G.IDENTITY_QUAT)
    with pytest.raises(ValueError, match="alpha must be finite"):
        G.quat_from_angle_axis(np.nan, [1.0, 0, 0])
    with pytest.raises(ValueError, match="axis must be finite"):
        G.quat_from_angle_axis(0.1, [np.inf, 0, 0])


def test_slerp_endpoints_midpoint_and_shortest_path():
    q0, q1 = random_quats(2, seed=3)
    np.testing.assert_allclose(G.quat_slerp(q0, q1, 0.0), q0, atol=1e-12)
    assert same_rotation(G.quat_slerp(q0, q1, 1.0), q1)
    assert same_rotation(G.quat_slerp(q0, -q1, 1.0), q1)
    mid = G.quat_slerp(q0, q1, 0.5)
    a = np.linalg.norm(G.quat_error(mid, q0))
    b = np.linalg.norm(G.quat_error(q1, mid))
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(a + b, np.linalg.norm(G.quat_error(q1, q0)), atol=1e-12)
    many = G.quat_slerp(q0, q1, np.linspace(0, 1, 7))
    assert many.shape == (7, 4)
    # Drake (Eigen) slerp agrees.
    drake_mid = Quaternion(q0).slerp(0.5, Quaternion(q1)).wxyz()
    assert same_rotation(drake_mid, mid, atol=1e-12)


def test_quat_error_is_world_frame():
    q = random_quats(1, seed=4)[0]
    delta = np.array([0.1, -0.2, 0.05])
    q_desired = G.quat_multiply(G.quat_from_rotation_vector(delta), q)
    np.testing.assert_allclose(G.quat_error(q_desired, q), delta, atol=1e-13)
    np.testing.assert_allclose(G.quat_error(-q_desired, q), delta, atol=1e-13)


def test_make_continuous_removes_sign_flips():
    qs = G.quat_slerp(random_quats(1, seed=5)[0], random_quats(1, seed=6)[0], np.linspace(0, 1, 50))
    flipped = qs.copy()
    flipped[10:20] *= -1
    flipped[33] *= -1
    fixed = G.quat_make_continuous(flipped)
    assert np.all(np.einsum("ij,ij->i", fixed[1:], fixed[:-1]) >= 0.0)
    np.testing.assert_allclose(fixed, qs * np.sign(qs[0] @ fixed[0]), atol=1e-15)
    with pytest.raises(ValueError, match=r"shape \(N, 4\)"):
        G.quat_make_continuous(qs[:, :3])


def test_integrate_matches_constant_rate_rotation():
    q = random_quats(1, seed=7)[0]
    omega = np.array([0.3, -1.2, 0.7])
    out = q
    for _ in range(100):
        out = G.quat_integrate(out, omega, 0.01)
    expected = G.quat_multiply(G.quat_from_rotation_vector(omega * 1.0), q)
    np.testing.assert_allclose(out, expected, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out), 1.0, atol=1e-15)


def test_normalize_rejects_zero():
    with pytest.raises(ValueError, match="cannot normalise"):
        G.quat_normalize(np.zeros(4))
    np.testing.assert_allclose(G.quat_conjugate([1.0, 2, 3, 4]), [1.0, -2, -3, -4])
