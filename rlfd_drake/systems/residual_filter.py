"""A first-order low-pass filter on the residual action, before the composer.

The 10 Hz residual is held between policy steps, so each new action steps the
set-point by up to the whole residual range. Against a 2000 N/m, 20 N m/rad wrist
that step throws the arm's mass at the fixture; franka_ros's Cartesian impedance
example low-passes its target pose for the same reason. This filter lets the
set-point move toward each new action with a time constant instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

from rlfd_drake.control_math import check_config_numbers, low_pass_gain


@dataclass(frozen=True)
class ResidualFilterConfig:
    """Attributes:
    time_constant_s: tau of the filter, s (the filtered residual covers 63 % of a
        step in tau).
    period_s: update period (the controller's 500 Hz), s.
    activation_time_s: the filter holds zero until this time (the composer ignores
        the residual before it), so the filtered residual starts from zero.
    """

    time_constant_s: float = 0.1
    period_s: float = 0.002
    activation_time_s: float = 5.0


class ResidualFilter(LeafSystem):
    """Low-passes the residual action: ``y += g (clip(u, -1, 1) - y)`` every period.

    .. pydrake_system::

        name: ResidualFilter
        input_ports:
        - residual
        output_ports:
        - filtered_residual

    * ``residual`` (6): the policy's action in [-1, 1] (clipped here as the composer
      clips it).
    * ``filtered_residual`` (6): the filter's state, zero before ``activation_time_s``.

    ``g = 1 - exp(-period / tau)`` is the exact discretisation of ``tau dy/dt = u - y``
    for an input held over the period. A non-finite residual raises RuntimeError.
    """

    def __init__(self, config: ResidualFilterConfig = ResidualFilterConfig()):  # noqa: B008
        super().__init__()
        check_config_numbers(
            config,
            positive=("time_constant_s", "period_s"),
            non_negative=("activation_time_s",),
            unit=" of seconds",
        )
        self.config = config
        self._gain = low_pass_gain(config.period_s, config.time_constant_s)
        self._residual_port = self.DeclareVectorInputPort("residual", 6)
        state = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareStateOutputPort("filtered_residual", state)

    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        if context.get_time() < self.config.activation_time_s:
            return  # the state stays zero
        residual = self._residual_port.Eval(context)
        if not np.all(np.isfinite(residual)):
            raise RuntimeError(f"ResidualFilter: non-finite value on port 'residual': {residual}")
        y = context.get_discrete_state_vector().get_value()
        discrete_state.get_mutable_vector().SetFromVector(
            y + self._gain * (np.clip(residual, -1.0, 1.0) - y)
        )
