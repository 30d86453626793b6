"""DmpSystem: the Cartesian DMP base policy as a discrete Drake LeafSystem (100 Hz)."""

from __future__ import annotations

import dataclasses

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

#: The CartesianDmp fields ``SetForcingWeights`` replaces.
_FORCING_WEIGHTS = ("weights_translation", "weights_orientation")

__all__ = ["DmpSystem"]


class DmpSystem(LeafSystem):
    """Runs :func:`rlfd_drake.dmp.dmp_step` at a fixed period and outputs the set-point.

    .. pydrake_system::

        name: DmpSystem
        input_ports:
        - coupling (optional)
        - X_WE_start (optional)
        - tracking_error (optional)
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
        - ``tracking_error`` (3): the controller's set-point minus the measured position of
          E (m), read by each update when ``phase_stop_gain_per_m2 > 0``: the next step
          runs with ``tau (1 + gain max(0, |e| - deadband)^2)`` (phase stopping, see
          :func:`rlfd_drake.dmp.phase_stop_time_scale`); unconnected is no slowing.
        - ``X_WE_desired`` (7): ``[p_WE (3) m, q_WE (4) wxyz]`` of the DMP.
        - ``V_WE_desired`` (6): spatial velocity in Drake order ``[w_WE (3) rad/s;
          v_WE (3) m/s]``, both in the world frame.
        - ``phase`` (1): canonical-system phase ``x`` (1 at the start, decays to 0).

    State: one discrete group of size :data:`rlfd_drake.dmp.STATE_SIZE` (21) with the flat
    DMP state ``[y (3), z (3), q (4), eta (3), x (1), y0 (3), q0 (4)]``, and a second of
    size 1 with the time scale of the last step (1 without phase stopping), both updated
    by a periodic event (offset 0). Outputs read only that state (no direct feedthrough,
    so ``tracking_error`` may come from a controller downstream).

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
        phase_stop_gain_per_m2: float = 0.0,
        phase_stop_deadband_m: float = 0.0,
    ) -> None:
        """
        Args:
            model: the fitted DMP.
            period_s: update period (s); the paper runs the DMP at 100 Hz.
            goal_position: goal (m), shape (3,); default the demonstration's.
            goal_quat: goal [w, x, y, z], shape (4,); default the demonstration's.
            tau: temporal scaling (s); default the demonstration's duration.
            phase_stop_gain_per_m2: ``alpha_px`` of phase stopping (1/m^2); 0 (the
                paper's DMP) ignores ``tracking_error``.
            phase_stop_deadband_m: tracking error (m) below which the DMP is not slowed.
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
        # Validates the gain and the deadband once, at construction.
        dmp.phase_stop_time_scale(np.zeros(3), phase_stop_gain_per_m2, phase_stop_deadband_m)
        self._phase_stop_gain = float(phase_stop_gain_per_m2)
        self._phase_stop_deadband = float(phase_stop_deadband_m)

        self._state_index = self.DeclareDiscreteState(dmp.initial_state(model))
        self._coupling_port = self.DeclareVectorInputPort("coupling", 6)
        self._time_scale_index = self.DeclareDiscreteState(np.ones(1))
        self._start_port = self.DeclareVectorInputPort("X_WE_start", 7)
        self._tracking_error_port = self.DeclareVectorInputPort("tracking_error", 3)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
        state_ticket = {
            self.discrete_state_ticket(self._state_index),
            self.discrete_state_ticket(self._time_scale_index),
        }
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

    @property
    def phase_stop_gain_per_m2(self) -> float:
        """``alpha_px`` of phase stopping (1/m^2); 0 is off."""
        return self._phase_stop_gain

    def SetForcingWeights(self, model: CartesianDmp) -> None:
        """Takes the forcing-term weights of ``model``, which must be this system's DMP
        in every other field (the episodic baselines, Table I type C, search the
        weights: one diagram serves all their rollouts). Takes effect at the next
        update; call before ``Simulator.Initialize``.

        Raises:
            ValueError: ``model`` differs in a field other than the two weights.
        """
        # CartesianDmp checks the weights' shapes against its config, compared here.
        for f in dataclasses.fields(CartesianDmp):
            if f.name in _FORCING_WEIGHTS:
                continue
            mine, theirs = getattr(self._model, f.name), getattr(model, f.name)
            same = (
                np.array_equal(mine, theirs)
                if isinstance(mine, np.ndarray) or isinstance(theirs, np.ndarray)
                else mine == theirs
            )
            if not same:
                raise ValueError(
                    f"only the forcing weights may change: {f.name} = {theirs!r}, "
                    f"this DMP's is {mine!r}"
                )
        self._model = model

    def time_scale(self, context: Context) -> float:
        """The factor on ``tau`` of the last step in ``context`` (1 without slowing)."""
        return float(context.get_discrete_state(self._time_scale_index).get_value()[0])

    def SetStartPose(self, context: Context, position: np.ndarray, quat: np.ndarray) -> None:
        """Reset the DMP in ``context`` to rest at ``[position (3) m, quat (4) wxyz]``.

        The pose becomes the stored start, so a later ``Simulator.Initialize()`` keeps it
        unless ``X_WE_start`` is connected (the port wins).
        """
        state = dmp.initial_state(self._model, position, quat)
        context.SetDiscreteState(self._state_index, state)
        context.SetDiscreteState(self._time_scale_index, np.ones(1))

    def _initialize(self, context: Context, discrete_state: DiscreteValues) -> EventStatus:
        if self._start_port.HasValue(context):
            x_we = self._start_port.Eval(context)
            state = dmp.initial_state(self._model, x_we[:3], x_we[3:])
        else:
            old = context.get_discrete_state(self._state_index).get_value()
            state = dmp.initial_state(self._model, old[dmp.START_POSITION], old[dmp.START_QUAT])
        discrete_state.set_value(self._state_index, state)
        discrete_state.set_value(self._time_scale_index, np.ones(1))
        return EventStatus.Succeeded()

    def _update(self, context: Context, discrete_state: DiscreteValues) -> EventStatus:
        coupling = (
            self._coupling_port.Eval(context) if self._coupling_port.HasValue(context) else None
        )
        scale = 1.0
        if self._phase_stop_gain > 0.0 and self._tracking_error_port.HasValue(context):
            scale = dmp.phase_stop_time_scale(
                self._tracking_error_port.Eval(context),
                self._phase_stop_gain,
                self._phase_stop_deadband,
            )
        state = context.get_discrete_state(self._state_index).get_value()
        new = dmp.dmp_step(
            state,
            self._model,
            self._period,
            self._goal_position,
            self._goal_quat,
            self._tau * scale,
            coupling,
        )
        discrete_state.set_value(self._state_index, new)
        discrete_state.set_value(self._time_scale_index, np.array([scale]))
        return EventStatus.Succeeded()

    def _state(self, context: Context) -> np.ndarray:
        return context.get_discrete_state(self._state_index).get_value()

    def _calc_pose(self, context: Context, output: BasicVector) -> None:
        s = self._state(context)
        output.SetFromVector(np.concatenate([s[dmp.POSITION], s[dmp.QUAT]]))

    def _calc_velocity(self, context: Context, output: BasicVector) -> None:
        s = self._state(context)
        tau = self._tau * self.time_scale(context)
        output.SetFromVector(np.concatenate([s[dmp.ETA], s[dmp.VELOCITY]]) / tau)

    def _calc_phase(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, self._state(context)[dmp.PHASE])
