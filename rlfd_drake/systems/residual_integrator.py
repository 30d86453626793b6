"""An incremental residual: the policy commands how the residual moves, not where it is.

A residual that is an absolute offset must name the fixture error it corrects: a peg
resting on the entrance 2 mm from its hole feels a torque that says which way the hole
is but not how far, so a policy that maps that torque to an offset stops short. With
this integrator in front of the composer the policy's action is a rate; the held
offset keeps moving while the contact says "that way", as a human's search does, and
stays where the part went in. The offset it holds is what the composer adds to the
DMP and what the observer reports as the residual.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

from rlfd_drake.control_math import check_config_numbers, integrate_residual


@dataclass(frozen=True)
class ResidualIntegratorConfig:
    """Attributes:
    rate_per_s: how fast an action of 1 moves the offset, residual units per second
        (1 = the whole residual range, e.g. 1 cm, in a second).
    period_s: update period (the controller's 500 Hz), s.
    activation_time_s: the offset is held until this time (the composer ignores the
        residual before it).
    start_offset: the offset held until activation and integrated from (6, residual
        units in [-1, 1]); zeros = the paper's residual, which starts at nothing.
    """

    rate_per_s: float = 1.0
    period_s: float = 0.002
    activation_time_s: float = 5.0
    start_offset: tuple[float, ...] = (0.0,) * 6


class ResidualIntegrator(LeafSystem):
    """Integrates the policy's action into the residual offset the composer applies.

    .. pydrake_system::

        name: ResidualIntegrator
        input_ports:
        - residual_rate
        output_ports:
        - residual

    * ``residual_rate`` (6): the policy's action in [-1, 1] (clipped here), a rate.
    * ``residual`` (6): the offset, ``y <- clip(y + rate_per_s * period_s * u, -1, 1)``
      every period from ``activation_time_s`` on, ``start_offset`` before.

    A non-finite action raises RuntimeError; a start offset that is not 6 numbers in
    [-1, 1] raises ValueError.
    """

    def __init__(self, config: ResidualIntegratorConfig = ResidualIntegratorConfig()):  # noqa: B008
        super().__init__()
        check_config_numbers(
            config, positive=("rate_per_s", "period_s"), non_negative=("activation_time_s",)
        )
        start = np.asarray(config.start_offset, dtype=float)
        if start.shape != (6,) or not np.all(np.isfinite(start)) or np.any(np.abs(start) > 1):
            raise ValueError(
                f"start_offset must be 6 numbers in [-1, 1], got {config.start_offset!r}"
            )
        self.config = config
        self._step = config.rate_per_s * config.period_s
        self._rate_port = self.DeclareVectorInputPort("residual_rate", 6)
        state = self.DeclareDiscreteState(start)
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareStateOutputPort("residual", state)

    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        if context.get_time() < self.config.activation_time_s:
            return  # the offset stays where it starts
        rate = self._rate_port.Eval(context)
        if not np.all(np.isfinite(rate)):
            raise RuntimeError(
                f"ResidualIntegrator: non-finite value on port 'residual_rate': {rate}"
            )
        offset = context.get_discrete_state_vector().get_value()
        discrete_state.get_mutable_vector().SetFromVector(
            integrate_residual(offset, rate, self._step)
        )
