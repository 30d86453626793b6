"""Speed of our Cartesian DMP against movement_primitives' CartesianDMP (same demo, same run).

``run()`` returns medians over ``repeats`` of: fitting one 10 s demonstration sampled at
100 Hz, and an open-loop rollout of 10 s at 100 Hz (1000 steps). It writes nothing; the
``rlfd bench dmp`` command stores the result.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from rlfd_drake.dmp import DmpConfig, fit_cartesian_dmp, rollout
from rlfd_drake.geometry import quat_from_rotation_vector, quat_multiply

__all__ = ["synthetic_demonstration", "run"]


def synthetic_demonstration(
    duration_s: float = 10.0, rate_hz: float = 100.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth approach-and-insert-like motion that starts and ends at rest.

    Minimum-jerk progress ``m(s)`` drives a 25 cm reach with a lateral S-curve, a descent,
    and a rotation of about 55 degrees about a changing axis.

    Returns:
        ``(times (N,) s, positions (N, 3) m, quats (N, 4) wxyz)`` with
        ``N = duration_s * rate_hz + 1``.
    """
    n = int(round(duration_s * rate_hz)) + 1
    times = np.linspace(0.0, duration_s, n)
    s = times / duration_s
    m = 10.0 * s**3 - 15.0 * s**4 + 6.0 * s**5
    positions = np.stack(
        [
            0.45 + 0.20 * m + 0.03 * np.sin(2.0 * np.pi * m),
            -0.10 * m + 0.08 * np.sin(np.pi * m),
            0.45 - 0.25 * m + 0.02 * np.sin(3.0 * np.pi * m) ** 2,
        ],
        axis=1,
    )
    rotvec = np.stack([0.3 * m, -0.5 * m + 0.1 * np.sin(np.pi * m), 0.8 * m], axis=1)
    # Start from a gripper pointing down (180 degrees about x).
    quats = quat_multiply(quat_from_rotation_vector(rotvec), np.array([0.0, 1.0, 0.0, 0.0]))
    return times, positions, quats


def _median_time(fn, repeats: int) -> float:
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def run(repeats: int = 5) -> dict:
    """Time fit + 10 s rollout at 100 Hz of our DMP and of movement_primitives' one.

    Both use the paper's 40 translation / 70 orientation basis functions where possible
    (movement_primitives has one count for both: 70 is used). One warm-up call each is
    not timed.

    Returns:
        ``{"fit_s", "rollout_s", "mp_fit_s", "mp_rollout_s", "fit_speedup",
        "rollout_speedup", "repeats", "n_basis", "n_samples", "rollout_steps",
        "max_position_difference_m"}`` with median wall times (s) and the largest position
        difference between the two rollouts (m).
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    from movement_primitives.dmp import CartesianDMP

    times, positions, quats = synthetic_demonstration()
    duration = float(times[-1])
    config = DmpConfig()
    model = fit_cartesian_dmp(times, positions, quats, config)
    ours = rollout(model, dt=0.01)

    n_mp = max(config.n_basis_translation, config.n_basis_orientation)
    y = np.hstack([positions, quats])

    def mp_fit():
        mp = CartesianDMP(execution_time=duration, dt=0.01, n_weights_per_dim=n_mp)
        mp.imitate(times, y)
        mp.configure(start_y=y[0], goal_y=y[-1])
        return mp

    mp_model = mp_fit()
    _, mp_y = mp_model.open_loop()

    fit_s = _median_time(lambda: fit_cartesian_dmp(times, positions, quats, config), repeats)
    rollout_s = _median_time(lambda: rollout(model, dt=0.01), repeats)
    mp_fit_s = _median_time(mp_fit, repeats)
    mp_rollout_s = _median_time(mp_model.open_loop, repeats)
    n = min(len(mp_y), len(ours[1]))
    return {
        "fit_s": fit_s,
        "rollout_s": rollout_s,
        "mp_fit_s": mp_fit_s,
        "mp_rollout_s": mp_rollout_s,
        "fit_speedup": mp_fit_s / fit_s,
        "rollout_speedup": mp_rollout_s / rollout_s,
        "repeats": repeats,
        "n_basis": {
            "translation": config.n_basis_translation,
            "orientation": config.n_basis_orientation,
            "movement_primitives": n_mp,
        },
        "n_samples": len(times),
        "rollout_steps": len(ours[0]) - 1,
        "max_position_difference_m": float(np.abs(mp_y[:n, :3] - ours[1][:n]).max()),
    }
