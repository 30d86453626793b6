"""Quintic extrapolation of the 100 Hz DMP set-points to the 500 Hz controller.

At every tick of the source (``source_period_s``, 100 Hz) the extrapolator stores
the source's pose and twist and fits, per coordinate, the Hermite polynomial
through the last n <= 3 samples' values and first derivatives (degree 2n - 1: the
quintic once three samples exist, which reproduces any quintic trajectory exactly;
a cubic with two samples; linear extrapolation from the first sample alone).
Between source ticks the output is that polynomial evaluated at the current time,
i.e. extrapolated ahead of the newest sample by up to one source period.

Orientation is fitted on the manifold: each sample's quaternion becomes the
world-frame rotation vector ``r_j = Log(Q_j o conj(Q_ref))`` relative to the
newest sample Q_ref, its rate ``dr/dt = J_l^-1(r_j) w_j`` (left Jacobian of SO(3)),
the six rotation/position coordinates are fitted together, and the output is
``Q(t) = Exp(r(t)) o Q_ref`` with ``w(t) = J_l(r(t)) dr/dt``: always a unit
quaternion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from rlfd_drake.control_math import (
    hermite_matrix,
    quat_exp_rotation_vector,
    quat_multiply_scalar,
    rotation_vector_between,
    so3_left_jacobian_apply,
    so3_left_jacobian_inverse_apply,
)

_MAX_SAMPLES = 3
_SAMPLE_SIZE = 13  # p (3), Q (4), w (3), v (3)
# Discrete state layout.
_N = 0  # number of valid samples
_T_REF = 1  # time of the newest sample, s
_HISTORY = slice(2, 2 + _MAX_SAMPLES * _SAMPLE_SIZE)  # oldest first
_COEFFS = slice(_HISTORY.stop, _HISTORY.stop + 2 * _MAX_SAMPLES * 6)  # (6, 6) row-major
_STATE_SIZE = _COEFFS.stop
# The newest sample's quaternion, the reference of the rotation vectors.
_Q_REF = slice(_HISTORY.stop - _SAMPLE_SIZE + 3, _HISTORY.stop - _SAMPLE_SIZE + 7)


@dataclass(frozen=True)
class QuinticExtrapolatorConfig:
    """Attributes:
    source_period_s: period of the source (the DMP, 100 Hz), s; samples are taken at
        multiples of it.
    """

    source_period_s: float = 0.01


class QuinticExtrapolator(LeafSystem):
    """Up-samples a pose/twist set-point stream with a Hermite quintic.

    .. pydrake_system::

        name: QuinticExtrapolator
        input_ports:
        - X_WE_dmp
        - V_WE_dmp
        output_ports:
        - X_WE_desired
        - V_WE_desired

    * ``X_WE_dmp`` (7): source pose, position (m) then quaternion [w, x, y, z].
    * ``V_WE_dmp`` (6): source spatial velocity [w (rad/s); v (m/s)], world.
    * ``X_WE_desired`` (7), ``V_WE_desired`` (6): the polynomial at the current time.

    The discrete state (history and coefficients) is updated at the source rate;
    the outputs are evaluated from it at whatever time a consumer samples them (the
    500 Hz controller), so they are exact at any rate and cost one small polynomial
    evaluation per read. Before the first sample (a context that has not been
    initialised, which is what every other system's initialisation event sees,
    since Drake handles those events simultaneously) the outputs pass the source's
    inputs through: the controller's first torque then targets the DMP's start, not
    an arbitrary pose. A sample taken twice at the same time (initialisation
    followed by the periodic event at t = 0) replaces the newest one.
    """

    def __init__(
        self,
        config: QuinticExtrapolatorConfig = QuinticExtrapolatorConfig(),  # noqa: B008
    ):
        super().__init__()
        if config.source_period_s <= 0.0:
            raise ValueError(f"source_period_s must be > 0, got {config.source_period_s}")
        self.config = config
        h = config.source_period_s
        self._h = h
        # Inverse Hermite matrices for 1, 2, 3 samples at scaled times -(n-1), ..., 0.
        self._A_inv = {
            n: np.linalg.inv(hermite_matrix(np.arange(-(n - 1), 1, dtype=float)))
            for n in range(1, _MAX_SAMPLES + 1)
        }
        # Factors of the value and derivative rows of the basis B(s) = ([s^k],
        # [k s^(k-1) / h]) (derivative per second).
        k = np.arange(2 * _MAX_SAMPLES, dtype=float)
        self._factor = np.concatenate([np.ones_like(k), k / h])
        self._last_key: tuple[float, bytes] | None = None
        self._last_value = np.zeros((2, 6))
        self._X_port = self.DeclareVectorInputPort("X_WE_dmp", 7)
        self._V_port = self.DeclareVectorInputPort("V_WE_dmp", 6)
        self.DeclareDiscreteState(_STATE_SIZE)
        self.DeclarePeriodicDiscreteUpdateEvent(h, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        prerequisites = {
            self.all_state_ticket(),
            self.time_ticket(),
            self._X_port.ticket(),
            self._V_port.ticket(),
        }
        self.DeclareVectorOutputPort(
            "X_WE_desired", 7, self._calc_X, prerequisites_of_calc=prerequisites
        )
        self.DeclareVectorOutputPort(
            "V_WE_desired", 6, self._calc_V, prerequisites_of_calc=prerequisites
        )

    # -- update at the source rate ------------------------------------------------
    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        x = context.get_discrete_state(0).get_value()
        t = context.get_time()
        n = int(x[_N])
        history = x[_HISTORY].reshape(_MAX_SAMPLES, _SAMPLE_SIZE).copy()
        X = self._X_port.Eval(context)
        V = self._V_port.Eval(context)
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(V))):
            raise RuntimeError(f"QuinticExtrapolator: non-finite input X={X}, V={V}")
        sample = np.concatenate([X[:3], X[3:] / np.linalg.norm(X[3:]), V])
        if n > 0 and t - x[_T_REF] < 0.5 * self._h:
            history[-1] = sample  # same tick again: replace
        else:
            history[:-1] = history[1:]
            history[-1] = sample
            n = min(n + 1, _MAX_SAMPLES)
        new = np.zeros(_STATE_SIZE)
        new[_N] = n
        new[_T_REF] = t
        new[_HISTORY] = history.reshape(-1)
        new[_COEFFS] = self._fit(history[_MAX_SAMPLES - n :]).reshape(-1)
        discrete_state.set_value(0, new)

    def _fit(self, samples: np.ndarray) -> np.ndarray:
        """(6, 6) coefficients (rows: powers of scaled time, columns: [p, r])."""
        n = samples.shape[0]
        Q_ref = samples[-1, 3:7]
        conditions = np.empty((2 * n, 6))  # values then h * rates, one row per sample
        for j in range(n):
            r = rotation_vector_between(samples[j, 3:7], Q_ref)
            conditions[j, :3] = samples[j, :3]
            conditions[j, 3:] = r
            conditions[n + j, :3] = self._h * samples[j, 10:13]
            conditions[n + j, 3:] = self._h * so3_left_jacobian_inverse_apply(r, samples[j, 7:10])
        C = np.zeros((2 * _MAX_SAMPLES, 6))
        C[: 2 * n] = self._A_inv[n] @ conditions
        return C

    # -- outputs --------------------------------------------------------------------
    def _evaluate(self, x: np.ndarray, t: float) -> np.ndarray:
        """(2, 6): [value; rate per second] of [p, r] at time t from the state x.

        The controller reads both outputs at every tick, so the last evaluation is
        kept, keyed by the time and the state's bytes (a pure function of the two)."""
        key = (t, x.tobytes())
        if key == self._last_key:
            return self._last_value
        s = (t - x[_T_REF]) / self._h
        # Scalar powers (cheaper than numpy on 12 entries), then one (2, 6) @ (6, 6).
        s2 = s * s
        s3 = s2 * s
        s4 = s3 * s
        k = self._factor
        basis = np.array(
            [
                [1.0, s, s2, s3, s4, s4 * s],
                [0.0, k[7], k[8] * s, k[9] * s2, k[10] * s3, k[11] * s4],
            ]
        )
        value = basis @ x[_COEFFS].reshape(2 * _MAX_SAMPLES, 6)
        self._last_key, self._last_value = key, value
        return value

    def _calc_X(self, context: Context, output: BasicVector) -> None:
        x = context.get_discrete_state(0).get_value()
        if x[_N] == 0:
            output.SetFromVector(self._X_port.Eval(context))
            return
        value = self._evaluate(x, context.get_time())[0]
        out = output.get_mutable_value()
        out[:3] = value[:3]
        out[3:] = quat_multiply_scalar(quat_exp_rotation_vector(*value[3:]), x[_Q_REF])

    def _calc_V(self, context: Context, output: BasicVector) -> None:
        x = context.get_discrete_state(0).get_value()
        if x[_N] == 0:
            output.SetFromVector(self._V_port.Eval(context))
            return
        value, rate = self._evaluate(x, context.get_time())
        out = output.get_mutable_value()
        out[:3] = so3_left_jacobian_apply(value[3:], rate[3:])
        out[3:] = rate[:3]
