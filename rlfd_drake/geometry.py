"""Quaternion and rotation maths (pure numpy, never imports pydrake).

Conventions
-----------
- A quaternion is a numpy array ``[w, x, y, z]`` (scalar first), shape ``(4,)``; most
  functions also accept stacks of shape ``(..., 4)``.
- Rotations are *active*: ``R(q) @ v`` rotates the vector ``v``; ``R(q)`` is the matrix of
  the orientation ``q`` (the columns of ``R_WE`` are the axes of frame E expressed in W).
- The composition ``a ∘ b`` of the paper (Shuster's notation as used by Davchev et al.)
  is the Hamilton product :func:`quat_multiply`, whose defining property is
  ``R(a ∘ b) = R(a) R(b)`` for active rotation matrices: ``b`` is applied first, then
  ``a``. Left-multiplying an orientation by a delta, ``Q_f = Q_delta ∘ Q_b``, applies the
  delta in the world frame.
- ``quat_log(q)`` is the quaternion logarithm ``u * theta / 2`` of
  ``q = [cos(theta/2), u sin(theta/2)]`` (a half-angle vector, rad), and the rotation
  vector of ``q`` is ``2 log q`` (angle times unit axis, rad).
- Angular velocities ``omega`` are expressed in the world frame, so the quaternion
  kinematics read ``dq/dt = 1/2 [0, omega] ∘ q``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "quat_multiply",
    "quat_conjugate",
    "quat_normalize",
    "quat_canonical",
    "quat_log",
    "quat_exp",
    "quat_from_rotation_vector",
    "rotation_vector_from_quat",
    "quat_from_angle_axis",
    "quat_to_rotation_matrix",
    "quat_from_rotation_matrix",
    "quat_slerp",
    "quat_error",
    "quat_make_continuous",
    "quat_integrate",
    "IDENTITY_QUAT",
]

#: The identity quaternion ``[1, 0, 0, 0]``, shape (4,).
IDENTITY_QUAT = np.array([1.0, 0.0, 0.0, 0.0])
IDENTITY_QUAT.setflags(write=False)

# Below this vector-part norm the logarithm uses its Taylor expansion.
_SMALL = 1e-10


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a ∘ b`` (the paper's composition, Shuster notation).

    ``R(a ∘ b) = R(a) @ R(b)`` for active rotation matrices: ``b`` acts first.

    Args:
        a: quaternion(s) [w, x, y, z], shape (..., 4).
        b: quaternion(s) [w, x, y, z], shape (..., 4), broadcastable with ``a``.

    Returns:
        The product, shape (..., 4).
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate ``[w, -x, -y, -z]`` (the inverse of a unit quaternion), shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) ``q / |q|``, shape (..., 4).

    Raises:
        ValueError: if a quaternion has zero or non-finite norm.
    """
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(n)) or np.any(n == 0.0):
        raise ValueError(f"cannot normalise quaternion(s) with norm {np.ravel(n)[:4]}")
    return q / n


def quat_canonical(q: np.ndarray) -> np.ndarray:
    """The representative with ``w >= 0`` of ``q`` and ``-q`` (same rotation), shape (..., 4)."""
    q = np.asarray(q, dtype=float)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_log(q: np.ndarray) -> np.ndarray:
    """Quaternion logarithm of a unit quaternion, ``u * theta / 2`` (rad), shape (..., 3).

    For ``q = [cos(theta/2), u sin(theta/2)]`` with ``theta/2`` in ``[0, pi]``; the sign of
    ``q`` is respected (``log(-q) != log(q)``); see :func:`rotation_vector_from_quat` for
    the shortest rotation. Robust at ``theta -> 0`` (Taylor expansion).
    """
    q = np.asarray(q, dtype=float)
    w = q[..., 0]
    v = q[..., 1:]
    n = np.linalg.norm(v, axis=-1)
    half_angle = np.arctan2(n, w)
    safe_n = np.where(n > _SMALL, n, 1.0)
    # atan2(n, w) / n -> 1/w (1 - n^2 / (3 w^2)) for n -> 0 and w > 0.
    safe_w = np.where(np.abs(w) > _SMALL, w, 1.0)
    taylor = (1.0 - n * n / (3.0 * safe_w * safe_w)) / safe_w
    factor = np.where(n > _SMALL, half_angle / safe_n, np.where(w > 0.0, taylor, 0.0))
    out = v * factor[..., None]
    # log(-1) = pi * (any unit axis): pick x so that exp(log(q)) == q.
    minus_one = (n <= _SMALL) & (w < 0.0)
    if np.any(minus_one):
        out = np.where(minus_one[..., None], np.array([np.pi, 0.0, 0.0]), out)
    return out


def quat_exp(v: np.ndarray) -> np.ndarray:
    """Quaternion exponential ``[cos|v|, v sin|v| / |v|]`` of a 3-vector (rad), shape (..., 4).

    The inverse of :func:`quat_log`; exact (via ``np.sinc``) at ``|v| -> 0``.
    """
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v, axis=-1)
    return np.concatenate([np.cos(n)[..., None], v * np.sinc(n / np.pi)[..., None]], axis=-1)


def quat_from_rotation_vector(r: np.ndarray) -> np.ndarray:
    """Unit quaternion of the rotation vector ``r`` (angle * axis, rad): ``exp(r / 2)``."""
    return quat_exp(0.5 * np.asarray(r, dtype=float))


def rotation_vector_from_quat(q: np.ndarray) -> np.ndarray:
    """Shortest rotation vector (angle in ``[0, pi]`` times axis, rad) of ``q``: ``2 log q``.

    The sign of ``q`` is canonicalised first (``w >= 0``), so ``q`` and ``-q`` give the same
    result. Shape (..., 3).
    """
    return 2.0 * quat_log(quat_canonical(q))


def quat_from_angle_axis(alpha, axis) -> np.ndarray:
    """Quaternion ``[cos(alpha/2), r/|r| sin(alpha/2)]`` of the paper (Section III-D).

    Args:
        alpha: angle (rad), scalar or shape (...,).
        axis: rotation axis ``r``, shape (..., 3); need not be unit. A zero axis gives the
            identity quaternion (no rotation).

    Returns:
        Unit quaternion(s), shape (..., 4).

    Raises:
        ValueError: if ``alpha`` or ``axis`` contains NaN or inf.
    """
    alpha = np.asarray(alpha, dtype=float)
    axis = np.asarray(axis, dtype=float)
    if axis.shape[-1:] != (3,):
        raise ValueError(f"axis must have shape (..., 3), got {axis.shape}")
    if not np.all(np.isfinite(alpha)):
        raise ValueError(f"alpha must be finite, got {alpha}")
    if not np.all(np.isfinite(axis)):
        raise ValueError(f"axis must be finite, got {axis}")
    n = np.linalg.norm(axis, axis=-1)
    zero = n < 1e-12
    unit = axis / np.where(zero, 1.0, n)[..., None]
    half = 0.5 * np.where(zero, 0.0, alpha)
    return np.concatenate([np.cos(half)[..., None], unit * np.sin(half)[..., None]], axis=-1)


def quat_to_rotation_matrix(q: np.ndarray) -> np.ndarray:
    """Active rotation matrix of unit quaternion(s), shape (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def quat_from_rotation_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (``w >= 0``) of rotation matrix/matrices, shape (..., 4).

    Shepperd's method: uses the largest of ``w, x, y, z`` as pivot, vectorised.
    """
    R = np.asarray(R, dtype=float)
    r00, r11, r22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    trace = r00 + r11 + r22
    # 4 * (squares of w, x, y, z).
    cand = np.stack(
        [1.0 + trace, 1.0 + 2.0 * r00 - trace, 1.0 + 2.0 * r11 - trace, 1.0 + 2.0 * r22 - trace],
        axis=-1,
    )
    k = np.argmax(cand, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(cand, k[..., None], axis=-1)[..., 0], 1e-300))
    d21, d02, d10 = (
        R[..., 2, 1] - R[..., 1, 2],
        R[..., 0, 2] - R[..., 2, 0],
        R[..., 1, 0] - R[..., 0, 1],
    )
    s01, s02, s12 = (
        R[..., 0, 1] + R[..., 1, 0],
        R[..., 0, 2] + R[..., 2, 0],
        R[..., 1, 2] + R[..., 2, 1],
    )
    options = np.stack(
        [
            np.stack([0.25 * s, d21 / s, d02 / s, d10 / s], axis=-1),
            np.stack([d21 / s, 0.25 * s, s01 / s, s02 / s], axis=-1),
            np.stack([d02 / s, s01 / s, 0.25 * s, s12 / s], axis=-1),
            np.stack([d10 / s, s02 / s, s12 / s, 0.25 * s], axis=-1),
        ],
        axis=-2,
    )
    q = np.take_along_axis(options, k[..., None, None], axis=-2)[..., 0, :]
    return quat_canonical(quat_normalize(q))


def quat_slerp(q0: np.ndarray, q1: np.ndarray, s) -> np.ndarray:
    """Spherical linear interpolation along the shortest arc from ``q0`` (s=0) to ``q1`` (s=1).

    Computed as ``exp(s log(d)) ∘ q0`` with ``d = canonical(q1 ∘ conj(q0))``: at ``s = 1``
    the result is ``q1`` or ``-q1`` (same rotation; ``-q1`` when ``q0 · q1 < 0``).

    Args:
        q0, q1: unit quaternions, shape (..., 4).
        s: interpolation parameter(s), scalar or shape (...,), usually in [0, 1].

    Returns:
        Shape (..., 4) (broadcast of the inputs).
    """
    q0 = np.asarray(q0, dtype=float)
    d = quat_canonical(quat_multiply(q1, quat_conjugate(q0)))
    s = np.asarray(s, dtype=float)[..., None]
    return quat_multiply(quat_exp(s * quat_log(d)), q0)


def quat_error(q_desired: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World-frame orientation error (rad), shape (..., 3).

    The shortest rotation vector of ``q_desired ∘ conj(q)``: rotating ``q`` about the world
    axis by this vector gives ``q_desired``.
    """
    return rotation_vector_from_quat(quat_multiply(q_desired, quat_conjugate(q)))


def quat_make_continuous(qs: np.ndarray) -> np.ndarray:
    """Flip signs along a sequence so that consecutive dot products are ``>= 0``.

    Args:
        qs: quaternions over time, shape (N, 4). The first sample keeps its sign.

    Returns:
        A new array, shape (N, 4), same rotations, no ``q -> -q`` jumps.
    """
    qs = np.asarray(qs, dtype=float)
    if qs.ndim != 2 or qs.shape[1] != 4:
        raise ValueError(f"qs must have shape (N, 4), got {qs.shape}")
    if len(qs) < 2:
        return qs.copy()
    dots = np.einsum("ij,ij->i", qs[1:], qs[:-1])
    signs = np.concatenate([[1.0], np.cumprod(np.where(dots < 0.0, -1.0, 1.0))])
    return qs * signs[:, None]


def quat_integrate(q: np.ndarray, omega_world: np.ndarray, dt: float) -> np.ndarray:
    """Integrate ``dq/dt = 1/2 omega ∘ q`` over ``dt`` (s): ``exp(dt/2 * omega) ∘ q``.

    Args:
        q: unit quaternion(s), shape (..., 4).
        omega_world: angular velocity in the world frame (rad/s), shape (..., 3).
        dt: time step (s).

    Returns:
        Unit quaternion(s), shape (..., 4) (renormalised against round-off).
    """
    step = quat_exp(0.5 * dt * np.asarray(omega_world, dtype=float))
    return quat_normalize(quat_multiply(step, q))
