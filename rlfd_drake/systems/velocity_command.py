"""The set-point of the paper's pure-RL and hybrid baselines (Table III): the policy's
action is a task-space velocity command that moves the set-point, instead of a
residual added to the DMP's."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import BasicVector, Context, DiscreteValues, LeafSystem

from rlfd_drake.control_math import (
    RESIDUAL_MODES,
    quat_exp_rotation_vector,
    quat_multiply_scalar,
    scale_residual,
)

# Discrete state layout: position (3), quaternion wxyz (4), latched flag (1).
_STATE_SIZE = 8
_LATCHED = 7


@dataclass(frozen=True)
class VelocityCommandConfig:
    """Attributes:
    max_speed_m_s: linear speed per unit of action, m/s.
    max_angular_speed_rad_s: angular-velocity component per unit of action, rad/s
        (its norm is bounded to pi / period, i.e. at most half a turn per tick).
    mode: "full", "translation", "orientation" or "off" (which parts the policy
        commands; the others stay where they were latched).
    activation_time_s: before it the base (DMP) set-point is passed through; at it
        the set-point is latched and from then on moves only with the commands. 0 =
        pure RL (the DMP never moves the set-point); the task's activation time =
        the hybrid that switches from the DMP to the policy.
    period_s: integration period (the controller's 500 Hz), s.
    """

    max_speed_m_s: float = 0.05
    max_angular_speed_rad_s: float = 0.35
    mode: str = "full"
    activation_time_s: float = 0.0
    period_s: float = 0.002


class VelocityCommandSetpoint(LeafSystem):
    """Integrates the policy's velocity command into the set-point.

    .. pydrake_system::

        name: VelocityCommandSetpoint
        input_ports:
        - X_WE_base
        - V_WE_base
        - residual
        output_ports:
        - X_WE_desired
        - V_WE_desired

    * ``X_WE_base`` (7), ``V_WE_base`` (6): the DMP's set-point and twist [w; v],
      passed through before ``activation_time_s``; the pose is latched at it.
    * ``residual`` (6): the action in [-1, 1] (clipped), read here as a velocity
      command ``[v / max_speed_m_s; w / max_angular_speed_rad_s]`` (world frame).
    * ``X_WE_desired`` (7): from the activation on, the latched pose moved by the
      commands: ``p += v dt``, ``Q = exp(w dt) o Q`` every ``period_s``.
    * ``V_WE_desired`` (6): the commanded twist [w; v] once active (the controller's
      feed-forward), else the base twist.

    The same ports as ``ResidualComposer``, so either can sit between the
    extrapolator and the controller. A non-finite command raises RuntimeError.
    """

    def __init__(
        self,
        config: VelocityCommandConfig = VelocityCommandConfig(),  # noqa: B008
    ):
        super().__init__()
        if config.mode not in RESIDUAL_MODES:
            raise ValueError(f"mode must be one of {RESIDUAL_MODES}, got {config.mode!r}")
        for name in ("max_speed_m_s", "max_angular_speed_rad_s", "activation_time_s"):
            value = getattr(config, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        if not (math.isfinite(config.period_s) and config.period_s > 0.0):
            raise ValueError(
                f"period_s must be a positive number of seconds, got {config.period_s}"
            )
        self.config = config
        # The command is held for 50 ticks (10 Hz against 500 Hz): scale it once.
        self._cached_key: bytes | None = None
        self._cached_command: tuple[np.ndarray, np.ndarray] = (np.zeros(3), np.zeros(3))
        self._X_port = self.DeclareVectorInputPort("X_WE_base", 7)
        self._V_port = self.DeclareVectorInputPort("V_WE_base", 6)
        self._command_port = self.DeclareVectorInputPort("residual", 6)
        initial = np.zeros(_STATE_SIZE)
        initial[3] = 1.0
        self._state_index = self.DeclareDiscreteState(initial)
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "X_WE_desired",
            7,
            self._calc_X,
            prerequisites_of_calc={
                self.time_ticket(),
                self._X_port.ticket(),
                self.xd_ticket(),
            },
        )
        self.DeclareVectorOutputPort(
            "V_WE_desired",
            6,
            self._calc_V,
            prerequisites_of_calc={
                self.time_ticket(),
                self._V_port.ticket(),
                self._command_port.ticket(),
                self.xd_ticket(),
            },
        )

    def Command(self, command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(v (3,) m/s, w (3,) rad/s) of a normalised command (6,)."""
        key = np.asarray(command).tobytes()
        if key == self._cached_key:
            return self._cached_command
        if not np.all(np.isfinite(command)):
            raise RuntimeError(
                f"VelocityCommandSetpoint: non-finite value on port 'residual': {command}"
            )
        # An angle of pi per tick is the most a rotation vector can say unambiguously.
        max_angle = math.pi / self.config.period_s
        config = self.config
        v, w = scale_residual(
            command, config.max_speed_m_s, config.max_angular_speed_rad_s, config.mode
        )
        norm = float(np.linalg.norm(w))
        if norm > max_angle:
            w = w * (max_angle / norm)
        self._cached_key, self._cached_command = key, (v, w)
        return v, w

    def _active(self, context: Context) -> bool:
        state = context.get_discrete_state(self._state_index).get_value()
        return state[_LATCHED] > 0.5 and context.get_time() >= self.config.activation_time_s

    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        if context.get_time() < self.config.activation_time_s:
            return
        state = context.get_discrete_state(self._state_index).get_value()
        if state[_LATCHED] > 0.5:
            p, q = state[:3], state[3:7]
        else:  # the switch: start from where the base set-point is now
            X = self._X_port.Eval(context)
            p, q = X[:3], X[3:]
        v, w = self.Command(self._command_port.Eval(context))
        dt = self.config.period_s
        new = np.empty(_STATE_SIZE)
        new[:3] = p + v * dt
        dq = quat_exp_rotation_vector(w[0] * dt, w[1] * dt, w[2] * dt)
        q_new = np.array(quat_multiply_scalar(dq, q))
        new[3:7] = q_new / np.linalg.norm(q_new)
        new[_LATCHED] = 1.0
        discrete_state.set_value(self._state_index, new)

    def _calc_X(self, context: Context, output: BasicVector) -> None:
        if self._active(context):
            output.SetFromVector(context.get_discrete_state(self._state_index).get_value()[:7])
        else:
            output.SetFromVector(self._X_port.Eval(context))

    def _calc_V(self, context: Context, output: BasicVector) -> None:
        if self._active(context):
            v, w = self.Command(self._command_port.Eval(context))
            output.SetFromVector(np.concatenate([w, v]))
        else:
            output.SetFromVector(self._V_port.Eval(context))
