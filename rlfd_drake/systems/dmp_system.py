"""DmpSystem: the Cartesian DMP base policy as a discrete Drake LeafSystem (100 Hz)."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import (
    BasicVector,
    Context,
    DiscreteValues,
    EventStatus,
    LeafSystem,
)

from rlfd_drake import dmp
from rlfd_drake.dmp import CartesianDmp

__all__ = ["DmpSystem"]


class DmpSystem(LeafSystem):
    """Runs :func:`rlfd_drake.dmp.dmp_step` at a fixed period and outputs the set-point.

    .. pydrake_system::

        name: DmpSystem
        input_ports:
        - coupling (optional)
        - X_WE_start (optional)
        output_ports:
        - X_WE_desired
        - V_WE_desired
        - phase

    Ports:
        - ``coupling`` (6): coupling term ``C_t`` ``[translation (3) m, orientation (3)
          rad]`` (the order of :mod:`rlfd_drake.dmp`, *not* Drake's ``[w; v]``), held over
          each step; zero when unconnected.
        - ``X_WE_start`` (7): start pose ``[p_WE (3) m, q_WE (4) wxyz]``, read only by the
          initialisation event (``Simulator.Initialize()``): the DMP starts at rest from the
          robot's current pose. When unconnected, the start stored in the state is kept
          (the demonstration's start in a default context, or the one given to
          :meth:`SetStartPose`).
        - ``X_WE_desired`` (7): ``[p_WE (3) m, q_WE (4) wxyz]`` of the DMP.
        - ``V_WE_desired`` (6): spatial velocity in Drake order ``[w_WE (3) rad/s;
          v_WE (3) m/s]``, both in the world frame.
        - ``phase`` (1): canonical-system phase ``x`` (1 at the start, decays to 0).

    State: one discrete group of size :data:`rlfd_drake.dmp.STATE_SIZE` (21) with the flat
    DMP state ``[y (3), z (3), q (4), eta (3), x (1), y0 (3), q0 (4)]``, updated by a
    periodic event (offset 0). Outputs read only that state (no direct feedthrough).

    Timing: the periodic update at ``t_k = k * period_s`` computes the sample at
    ``t_{k+1}`` (one-period preview, zero-order hold of the *next* sample). Right after
    ``Simulator.Initialize()`` the outputs are the start (rollout sample 0); after
    ``simulator.AdvanceTo(t_k)`` with ``k >= 1`` they equal :func:`rlfd_drake.dmp.rollout`
    sample ``k`` to round-off (the event at ``t_k`` is handled at the start of the next
    step), and during ``(t_k, t_{k+1})`` sample ``k + 1``.
    """

    def __init__(
        self,
        model: CartesianDmp,
        period_s: float = 0.01,
        goal_position: np.ndarray | None = None,
        goal_quat: np.ndarray | None = None,
        tau: float | None = None,
    ) -> None:
        """
        Args:
            model: the fitted DMP.
            period_s: update period (s); the paper runs the DMP at 100 Hz.
            goal_position: goal (m), shape (3,); default the demonstration's.
            goal_quat: goal [w, x, y, z], shape (4,); default the demonstration's.
            tau: temporal scaling (s); default the demonstration's duration.
        """
        super().__init__()
        if not (np.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f"period_s must be finite and > 0 s, got {period_s}")
        self._model = model
        self._period = float(period_s)
        g, qg = dmp._goal(model, goal_position, goal_quat)
        self._goal_position = g
        self._goal_quat = qg
        self._tau = model.tau if tau is None else float(tau)
        # Validates tau and the period once, at construction.
        dmp._step_constants(model.config, self._period, self._tau)

        self._state_index = self.DeclareDiscreteState(dmp.initial_state(model))
        self._coupling_port = self.DeclareVectorInputPort("coupling", 6)
        self._start_port = self.DeclareVectorInputPort("X_WE_start", 7)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
        state_ticket = {self.discrete_state_ticket(self._state_index)}
        self.DeclareVectorOutputPort(
            "X_WE_desired", 7, self._calc_pose, prerequisites_of_calc=state_ticket
        )
        self.DeclareVectorOutputPort(
            "V_WE_desired", 6, self._calc_velocity, prerequisites_of_calc=state_ticket
        )
        self.DeclareVectorOutputPort(
            "phase", 1, self._calc_phase, prerequisites_of_calc=state_ticket
        )

    @property
    def model(self) -> CartesianDmp:
        """The fitted DMP."""
        return self._model

    @property
    def period_s(self) -> float:
        """Update period (s)."""
        return self._period

    @property
    def tau(self) -> float:
        """Temporal scaling (s)."""
        return self._tau

    def SetStartPose(self, context: Context, position: np.ndarray, quat: np.ndarray) -> None:
        """Reset the DMP in ``context`` to rest at ``[position (3) m, quat (4) wxyz]``.

        The pose becomes the stored start, so a later ``Simulator.Initialize()`` keeps it
        unless ``X_WE_start`` is connected (the port wins).
        """
        state = dmp.initial_state(self._model, position, quat)
        context.SetDiscreteState(self._state_index, state)

    def _initialize(self, context: Context, discrete_state: DiscreteValues) -> EventStatus:
        if self._start_port.HasValue(context):
            x_we = self._start_port.Eval(context)
            state = dmp.initial_state(self._model, x_we[:3], x_we[3:])
        else:
            old = context.get_discrete_state(self._state_index).get_value()
            state = dmp.initial_state(self._model, old[dmp.START_POSITION], old[dmp.START_QUAT])
        discrete_state.set_value(self._state_index, state)
        return EventStatus.Succeeded()

    def _update(self, context: Context, discrete_state: DiscreteValues) -> EventStatus:
        coupling = (
            self._coupling_port.Eval(context) if self._coupling_port.HasValue(context) else None
        )
        state = context.get_discrete_state(self._state_index).get_value()
        new = dmp.dmp_step(
            state,
            self._model,
            self._period,
            self._goal_position,
            self._goal_quat,
            self._tau,
            coupling,
        )
        discrete_state.set_value(self._state_index, new)
        return EventStatus.Succeeded()

    def _state(self, context: Context) -> np.ndarray:
        return context.get_discrete_state(self._state_index).get_value()

    def _calc_pose(self, context: Context, output: BasicVector) -> None:
        s = self._state(context)
        output.SetFromVector(np.concatenate([s[dmp.POSITION], s[dmp.QUAT]]))

    def _calc_velocity(self, context: Context, output: BasicVector) -> None:
        s = self._state(context)
        output.SetFromVector(np.concatenate([s[dmp.ETA], s[dmp.VELOCITY]]) / self._tau)

    def _calc_phase(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, self._state(context)[dmp.PHASE])
