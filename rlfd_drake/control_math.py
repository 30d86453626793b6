"""Pure maths of the rLfD control systems (numpy only, no pydrake).

The LeafSystems in ``rlfd_drake.systems`` read their Context and call these
functions; everything here is unit-tested directly.

Conventions: quaternions are ``[w, x, y, z]`` (see ``rlfd_drake.geometry``); a
spatial velocity or wrench is ``[angular; linear]`` (Drake's SpatialVelocity /
SpatialForce order); rotation vectors are full-angle (``angle * unit_axis``, rad)
and world-frame where they perturb a pose from the left, ``q = exp(r) o q_ref``.

Contents:

* Hermite polynomial fit/eval (the extrapolator's quintic through the last three
  DMP samples, positions and velocities);
* the left Jacobian of SO(3) and its inverse (rotation-vector rates <-> angular
  velocity), for fitting orientations on the manifold;
* residual scaling and composition (Section III-D of the paper);
* the Cartesian impedance law with gravity compensation and a null-space posture
  term, and critical damping from the operational-space inertia.
"""

from __future__ import annotations

import math

import numpy as np

from rlfd_drake.geometry import quat_multiply

# ---------------------------------------------------------------------------
# Hermite polynomial fit / evaluation
# ---------------------------------------------------------------------------


def hermite_matrix(sample_times: np.ndarray) -> np.ndarray:
    """The (2n, 2n) matrix mapping polynomial coefficients to Hermite conditions.

    For n sample times t_j and the polynomial ``p(t) = sum_k c_k t^k`` of degree
    2n - 1, row j is ``p(t_j)`` and row n + j is ``p'(t_j)``.

    Args:
        sample_times: (n,) distinct times (any unit; scale them to O(1) for good
            conditioning, e.g. in units of the sample period).
    """
    t = np.asarray(sample_times, dtype=float).reshape(-1)
    n = t.size
    if n == 0:
        raise ValueError("hermite_matrix needs at least one sample time")
    if np.unique(t).size != n:
        raise ValueError(f"sample times must be distinct, got {t}")
    k = np.arange(2 * n, dtype=float)
    values = t[:, None] ** k[None, :]
    derivatives = np.zeros_like(values)
    derivatives[:, 1:] = k[None, 1:] * t[:, None] ** (k[None, 1:] - 1.0)
    return np.vstack([values, derivatives])


def hermite_fit(
    sample_times: np.ndarray, values: np.ndarray, derivatives: np.ndarray
) -> np.ndarray:
    """Coefficients of the degree 2n-1 polynomial through values and derivatives.

    Args:
        sample_times: (n,) distinct times.
        values: (n, d) values at the sample times.
        derivatives: (n, d) first derivatives (per unit of ``sample_times``).

    Returns:
        (2n, d) coefficients, lowest order first: ``p(t) = sum_k c[k] t^k``.
        With n = 3 this is the quintic that reproduces any polynomial of degree
        <= 5 exactly.
    """
    values = np.atleast_2d(np.asarray(values, dtype=float).T).T
    derivatives = np.atleast_2d(np.asarray(derivatives, dtype=float).T).T
    rhs = np.vstack([values, derivatives])
    return np.linalg.solve(hermite_matrix(sample_times), rhs)


def polynomial_eval(coefficients: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Value and first derivative of ``sum_k c[k] t^k``.

    Args:
        coefficients: (m, d) coefficients, lowest order first.
        t: evaluation time (same unit as the fit).

    Returns:
        (value (d,), derivative (d,)).
    """
    m = coefficients.shape[0]
    powers = t ** np.arange(m, dtype=float)
    dpowers = np.zeros(m)
    dpowers[1:] = np.arange(1, m, dtype=float) * powers[:-1]
    return powers @ coefficients, dpowers @ coefficients


# ---------------------------------------------------------------------------
# SO(3) Jacobians
# ---------------------------------------------------------------------------


def skew(w: np.ndarray) -> np.ndarray:
    """(3, 3) cross-product matrix [w]x with [w]x u = w x u."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def so3_left_jacobian(r: np.ndarray) -> np.ndarray:
    """(3, 3) left Jacobian of SO(3) at the rotation vector r (rad).

    If ``R(t) = Exp(r(t)) R_ref`` then the world-frame angular velocity is
    ``w = J_l(r) dr/dt``.
    """
    theta2 = float(r @ r)
    S = skew(r)
    if theta2 < 1e-10:
        return np.eye(3) + 0.5 * S + (1.0 / 6.0) * (S @ S)
    theta = np.sqrt(theta2)
    a = (1.0 - np.cos(theta)) / theta2
    b = (theta - np.sin(theta)) / (theta2 * theta)
    return np.eye(3) + a * S + b * (S @ S)


def so3_left_jacobian_apply(r: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``J_l(r) @ u`` (3,) without forming the matrix (scalar maths, for hot loops).

    ``J_l(r) u = u + a (r x u) + b (r x (r x u))`` with ``a = (1 - cos t)/t^2``,
    ``b = (t - sin t)/t^3``, ``t = |r|``.
    """
    rx, ry, rz = float(r[0]), float(r[1]), float(r[2])
    ux, uy, uz = float(u[0]), float(u[1]), float(u[2])
    theta2 = rx * rx + ry * ry + rz * rz
    if theta2 < 1e-10:
        a, b = 0.5, 1.0 / 6.0
    else:
        theta = math.sqrt(theta2)
        a = (1.0 - math.cos(theta)) / theta2
        b = (theta - math.sin(theta)) / (theta2 * theta)
    cx, cy, cz = ry * uz - rz * uy, rz * ux - rx * uz, rx * uy - ry * ux
    dx, dy, dz = ry * cz - rz * cy, rz * cx - rx * cz, rx * cy - ry * cx
    return np.array([ux + a * cx + b * dx, uy + a * cy + b * dy, uz + a * cz + b * dz])


def rotation_vector_between(q: np.ndarray, q_ref: np.ndarray) -> tuple[float, float, float]:
    """Rotation vector (rad, world) of ``q o conj(q_ref)``, shortest (angle <= pi).

    Scalar maths on two wxyz quaternions (need not be unit: both are normalised), for
    the 500 Hz loops where numpy's per-call overhead dominates on 4-vectors.
    """
    aw, ax, ay, az = float(q[0]), float(q[1]), float(q[2]), float(q[3])
    bw, bx, by, bz = float(q_ref[0]), -float(q_ref[1]), -float(q_ref[2]), -float(q_ref[3])
    inv_norm = 1.0 / math.sqrt(
        (aw * aw + ax * ax + ay * ay + az * az) * (bw * bw + bx * bx + by * by + bz * bz)
    )
    w = (aw * bw - ax * bx - ay * by - az * bz) * inv_norm
    x = (aw * bx + ax * bw + ay * bz - az * by) * inv_norm
    y = (aw * by - ax * bz + ay * bw + az * bx) * inv_norm
    z = (aw * bz + ax * by - ay * bx + az * bw) * inv_norm
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    sin_half = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(sin_half, w) / sin_half if sin_half > 1e-12 else 2.0
    return scale * x, scale * y, scale * z


def quat_multiply_scalar(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float, float]:
    """``a o b`` of two wxyz quaternions with scalar maths (hot loops; see
    :func:`rlfd_drake.geometry.quat_multiply` for arrays)."""
    aw, ax, ay, az = float(a[0]), float(a[1]), float(a[2]), float(a[3])
    bw, bx, by, bz = float(b[0]), float(b[1]), float(b[2]), float(b[3])
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_exp_rotation_vector(rx: float, ry: float, rz: float) -> tuple[float, float, float, float]:
    """Unit quaternion (wxyz) of the rotation vector r (rad): ``[cos(t/2), r/t sin(t/2)]``."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return 1.0, 0.5 * rx, 0.5 * ry, 0.5 * rz  # first order: unit to machine precision
    s = math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), s * rx, s * ry, s * rz


def so3_left_jacobian_inverse_apply(r: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``J_l^-1(r) @ w`` (3,) without forming the matrix (scalar maths, for hot loops).

    ``J_l^-1(r) w = w - (r x w)/2 + c (r x (r x w))`` with
    ``c = 1/t^2 - (1 + cos t) / (2 t sin t)``, ``t = |r|`` (series ``1/12`` near 0).
    """
    rx, ry, rz = float(r[0]), float(r[1]), float(r[2])
    wx, wy, wz = float(w[0]), float(w[1]), float(w[2])
    theta2 = rx * rx + ry * ry + rz * rz
    if theta2 < 1e-10:
        c = 1.0 / 12.0
    else:
        theta = math.sqrt(theta2)
        c = 1.0 / theta2 - (1.0 + math.cos(theta)) / (2.0 * theta * math.sin(theta))
    cx, cy, cz = ry * wz - rz * wy, rz * wx - rx * wz, rx * wy - ry * wx
    dx, dy, dz = ry * cz - rz * cy, rz * cx - rx * cz, rx * cy - ry * cx
    return np.array([wx - 0.5 * cx + c * dx, wy - 0.5 * cy + c * dy, wz - 0.5 * cz + c * dz])


def so3_left_jacobian_inverse(r: np.ndarray) -> np.ndarray:
    """(3, 3) inverse of :func:`so3_left_jacobian`: ``dr/dt = J_l^-1(r) w``.

    Valid for |r| < 2 pi (rotation vectors from a log map have |r| <= pi).
    """
    theta2 = float(r @ r)
    S = skew(r)
    if theta2 < 1e-10:
        return np.eye(3) - 0.5 * S + (1.0 / 12.0) * (S @ S)
    theta = np.sqrt(theta2)
    c = 1.0 / theta2 - (1.0 + np.cos(theta)) / (2.0 * theta * np.sin(theta))
    return np.eye(3) - 0.5 * S + c * (S @ S)


# ---------------------------------------------------------------------------
# Residual scaling and composition (paper Section III-D)
# ---------------------------------------------------------------------------

RESIDUAL_MODES: tuple[str, ...] = ("full", "translation", "orientation", "off")

#: How the policy's action sets the set-point: "residual" (rLfD: added to the DMP's),
#: "hybrid" (the DMP until the activation time, then the action is a velocity command
#: from where the DMP was) or "pure" (velocity commands from the start, no DMP): the
#: paper's Table III.
COMPOSITIONS: tuple[str, ...] = ("residual", "hybrid", "pure")

#: The contact force a training peak-force cost may charge: "low_passed" (20 ms, what
#: force limits check) or "one_step" (the 2 ms samples whose peak evaluations report;
#: impacts that the low-pass smooths away show in it).
PEAK_FORCE_SIGNALS: tuple[str, ...] = ("low_passed", "one_step")


#: Where a 3-D action of a translation-only or orientation-only policy sits in the 6-D
#: residual.
RESIDUAL_PARTS: dict[str, slice] = {"translation": slice(0, 3), "orientation": slice(3, 6)}


def pad_residual_part(action: np.ndarray, mode: str) -> np.ndarray:
    """The 6-D residual of a policy that sets only the ``mode`` part ("translation" or
    "orientation"): its (3,) action there, zeros elsewhere."""
    if mode not in RESIDUAL_PARTS:
        raise ValueError(
            f"residual mode must be one of {tuple(RESIDUAL_PARTS)} for a 3-D action, got {mode!r}"
        )
    action = np.asarray(action, dtype=float).reshape(-1)
    if action.shape != (3,):
        raise ValueError(f"action must be 3 numbers ({mode}), got {action!r}")
    full = np.zeros(6)
    full[RESIDUAL_PARTS[mode]] = action
    return full


def keep_residual_part(action: np.ndarray, mode: str) -> np.ndarray:
    """The 6-D residual ``action`` with only its ``mode`` part kept ("full": all of it;
    "translation" / "orientation": that half, the other zero; "off": none)."""
    if mode not in RESIDUAL_MODES:
        raise ValueError(f"residual mode must be one of {RESIDUAL_MODES}, got {mode!r}")
    action = np.asarray(action, dtype=float).reshape(-1)
    if action.shape != (6,):
        raise ValueError(f"action must be 6 numbers, got {action!r}")
    kept = np.zeros(6)
    if mode in ("full", "translation"):
        kept[RESIDUAL_PARTS["translation"]] = action[RESIDUAL_PARTS["translation"]]
    if mode in ("full", "orientation"):
        kept[RESIDUAL_PARTS["orientation"]] = action[RESIDUAL_PARTS["orientation"]]
    return kept


def scale_residual(
    residual: np.ndarray,
    max_translation_m: float,
    max_rotation_rad: float,
    mode: str = "full",
    max_push_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Maps a normalised residual action to a physical pose correction.

    Args:
        residual: (6,) action; entries are clipped to [-1, 1]. The first three
            scale to a translation, the last three to a rotation vector
            ``alpha * r/|r|`` (angle-axis), alpha clipped to [0, pi].
        max_translation_m: translation per unit action, m.
        max_rotation_rad: rotation-vector component per unit action, rad.
        mode: one of ``RESIDUAL_MODES``; "translation" zeroes the rotation,
            "orientation" the translation, "off" both.
        max_push_m: if given, the translation's world -z component (down, into the
            fixtures) is at most this, m (>= 0); None = ``max_translation_m``.

    Returns:
        (dp (3,) m, rotation vector (3,) rad), world frame.
    """
    a = np.clip(keep_residual_part(residual, mode), -1.0, 1.0)
    dp = a[:3] * max_translation_m
    if max_push_m is not None:
        dp[2] = max(dp[2], -max_push_m)
    rotvec = a[3:] * max_rotation_rad
    alpha = float(np.sqrt(rotvec @ rotvec))
    if alpha > np.pi:
        rotvec = rotvec * (np.pi / alpha)
    return dp, rotvec


def residual_quaternion(rotvec: np.ndarray) -> np.ndarray:
    """Q_delta = [cos(alpha/2), r/|r| sin(alpha/2)] for rotvec = alpha r/|r|."""
    alpha = float(np.sqrt(rotvec @ rotvec))
    if alpha == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    half = 0.5 * alpha
    return np.concatenate([[np.cos(half)], rotvec * (np.sin(half) / alpha)])


def compose_residual_pose(
    p_b: np.ndarray, Q_b: np.ndarray, dp: np.ndarray, rotvec: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Final set-point ``p_f = p_b + dp``, ``Q_f = Q_delta o Q_b``.

    Args:
        p_b: (3,) base position, m. Q_b: (4,) base quaternion [w, x, y, z].
        dp: (3,) translation residual, m. rotvec: (3,) rotation residual, rad,
            world frame (it multiplies Q_b from the left).

    Returns:
        (p_f (3,), Q_f (4,)). A zero residual returns copies of the inputs exactly.
    """
    p_f = p_b + dp
    if not rotvec.any():
        return p_f, np.array(Q_b, dtype=float)
    return p_f, quat_multiply(residual_quaternion(rotvec), Q_b)


# ---------------------------------------------------------------------------
# Cartesian impedance
# ---------------------------------------------------------------------------


def operational_space_inertia(J: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(6, 6) Lambda = (J M^-1 J^T)^-1 for a (6, n) Jacobian and (n, n) mass matrix."""
    return np.linalg.inv(J @ np.linalg.solve(M, J.T))


def low_pass_gain(period_s: float, time_constant_s: float) -> float:
    """Gain g of the discrete first-order filter ``y += g (u - y)``: the exact step of
    ``tau dy/dt = u - y`` over ``period_s`` for an input held over the period."""
    return float(-np.expm1(-period_s / time_constant_s))


def critical_damping(
    stiffness: np.ndarray, effective_inertia: np.ndarray, damping_ratio: float = 1.0
) -> np.ndarray:
    """Diagonal damping D_i = 2 zeta sqrt(K_i Lambda_i) (diagonal approximation).

    Args:
        stiffness: (6,) diagonal of K, [N m/rad]*3 + [N/m]*3.
        effective_inertia: (6,) diagonal of Lambda, [kg m^2]*3 + [kg]*3.
        damping_ratio: zeta.

    Returns:
        (6,) diagonal of D, [N m s/rad]*3 + [N s/m]*3.
    """
    return 2.0 * damping_ratio * np.sqrt(np.asarray(stiffness) * np.asarray(effective_inertia))


def null_space_torque(J: np.ndarray, tau0: np.ndarray) -> np.ndarray:
    """Projects tau0 (n,) with the simple projector N = I - J^T (J^+)^T.

    J^+ = J^T (J J^T)^-1 (right pseudo-inverse of a full-row-rank (6, n) J), so
    ``N tau0 = tau0 - J^T (J J^T)^-1 J tau0``. The result produces no wrench
    at the controlled frame in static equilibrium: (J^+)^T N = 0.
    """
    return tau0 - J.T @ np.linalg.solve(J @ J.T, J @ tau0)


def cartesian_impedance_torque(
    J: np.ndarray,
    pose_error: np.ndarray,
    velocity_error: np.ndarray,
    stiffness: np.ndarray,
    damping: np.ndarray,
    tau_posture: np.ndarray,
    tau_gravity: np.ndarray,
    torque_limits: np.ndarray,
) -> np.ndarray:
    """tau = J^T (K e + D (V_d - V)) + N tau_posture - tau_gravity, clipped.

    Args:
        J: (6, n) spatial-velocity Jacobian of the controlled frame E in the world,
            rows [angular; linear].
        pose_error: (6,) e = [rotation vector of Q_d o conj(Q); p_d - p] (rad, m), world.
        velocity_error: (6,) V_d - V (rad/s, m/s), world; V_d = 0 without feed-forward.
        stiffness: (6,) diagonal of K. damping: (6,) diagonal of D.
        tau_posture: (n,) joint-space posture torque, projected into the null space.
        tau_gravity: (n,) generalized gravity forces (Drake's
            CalcGravityGeneralizedForces, i.e. the force gravity applies; it is
            subtracted to compensate).
        torque_limits: (n,) symmetric limits, N m.

    Returns:
        (n,) joint torques, N m.
    """
    wrench = stiffness * pose_error + damping * velocity_error
    tau = J.T @ wrench + null_space_torque(J, tau_posture) - tau_gravity
    return np.clip(tau, -torque_limits, torque_limits)


def integrate_residual(offset: np.ndarray, rate_action: np.ndarray, step: float) -> np.ndarray:
    """One step of an incremental residual: ``clip(offset + step * clip(u, -1, 1), -1, 1)``.

    The policy's action ``u`` is a rate (in residual units per second, times ``step =
    rate_per_s * period_s``); the held offset it moves stays within the residual's range,
    so the composer sees a residual in [-1, 1] like any other.
    """
    return np.clip(offset + step * np.clip(rate_action, -1.0, 1.0), -1.0, 1.0)


def rate_toward_offset(target: np.ndarray, held: np.ndarray, step: float) -> np.ndarray:
    """The rate action that moves an incremental residual's ``held`` offset to ``target``
    in one policy step if it can, else as far as the rate allows: ``clip((target - held)
    / step, -1, 1)``, ``step = rate_per_s * residual_period_s`` (the offset one action of
    1 moves in one policy step; :func:`integrate_residual` over the step's ticks)."""
    if not (np.isfinite(step) and step > 0.0):
        raise ValueError(f"step must be a positive number, got {step}")
    target = np.asarray(target, dtype=float)
    held = np.asarray(held, dtype=float)
    return np.clip((target - held) / step, -1.0, 1.0)


def check_config_numbers(
    config: object,
    positive: tuple[str, ...] = (),
    non_negative: tuple[str, ...] = (),
    unit: str = "",
) -> None:
    """Raises ValueError naming the first of ``config``'s fields that is not a finite
    positive (or, for ``non_negative``, >= 0) number; ``unit`` ends the message's
    "a positive number" (e.g. " of seconds")."""
    for name in positive:
        value = getattr(config, name)
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive number{unit}, got {value}")
    for name in non_negative:
        value = getattr(config, name)
        if not (np.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name} must be a non-negative number, got {value}")
