"""The cost floor of Python LeafSystems at the rLfD diagram's rates.

The speed target of the control stack asks the four Python systems (DMP,
extrapolator, composer, impedance controller) plus the observer to cost at most 30 %
over the plant. This module measures what Python systems cost when they do *no*
work: each probe below has the ports, the rates and the pull pattern of the real
system it stands for (the controller's 500 Hz update pulls the composer's outputs,
which pull the extrapolator's; the observer's 500 Hz update reads the plant's contact
results) but its callbacks only copy a few numbers. Whatever the probes cost is the
price of Drake's Python dispatch (pybind11 calls, BasicVector views, event
collection), which no amount of tuning of the real systems' maths can remove.

The probes are added beside the plant replaying recorded torques (see
:mod:`rlfd_drake.bench.diagram`); their outputs drive nothing.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import Value
from pydrake.multibody.plant import ContactResults
from pydrake.systems.framework import BasicVector, Context, DiagramBuilder, LeafSystem

from rlfd_drake.scene import Scene

#: Periods of the real systems, s: DMP and extrapolator updates, controller and observer.
SLOW_PERIOD_S = 0.01
FAST_PERIOD_S = 0.002


class _PoseSourceProbe(LeafSystem):
    """Stands for the DMP: a 100 Hz update, pose (7) and twist (6) read from the state."""

    def __init__(self) -> None:
        super().__init__()
        index = self.DeclareDiscreteState(np.r_[1.0, np.zeros(12)])
        self.DeclarePeriodicDiscreteUpdateEvent(SLOW_PERIOD_S, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "X", 7, lambda c, o: o.SetFromVector(c.get_discrete_state(index).value()[:7])
        )
        self.DeclareVectorOutputPort(
            "V", 6, lambda c, o: o.SetFromVector(c.get_discrete_state(index).value()[7:])
        )

    def _update(self, context: Context, state) -> None:
        state.set_value(0, context.get_discrete_state(0).value())


class _HoldProbe(_PoseSourceProbe):
    """Stands for the extrapolator: a 100 Hz update reading (X, V), outputs computed on
    demand from the held samples (as the real one evaluates its polynomial)."""

    def __init__(self) -> None:
        super().__init__()
        self._X = self.DeclareVectorInputPort("X_in", 7)
        self._V = self.DeclareVectorInputPort("V_in", 6)

    def _update(self, context: Context, state) -> None:
        state.set_value(0, np.r_[self._X.Eval(context), self._V.Eval(context)])


class _PassThroughProbe(LeafSystem):
    """Stands for the composer: X, V and the residual in, X + residual and V out."""

    def __init__(self) -> None:
        super().__init__()
        self._X = self.DeclareVectorInputPort("X_in", 7)
        self._V = self.DeclareVectorInputPort("V_in", 6)
        self._residual = self.DeclareVectorInputPort("residual", 6)
        self.DeclareVectorOutputPort("X", 7, self._calc_X)
        self.DeclareVectorOutputPort("V", 6, lambda c, o: o.SetFromVector(self._V.Eval(c)))

    def _calc_X(self, context: Context, output: BasicVector) -> None:
        X = self._X.Eval(context).copy()
        X[:3] += self._residual.Eval(context)[:3]
        output.SetFromVector(X)


class _ControllerProbe(LeafSystem):
    """Stands for the impedance controller: a 500 Hz update reading the arm state and
    the set-point; its (zero) torque drives nothing."""

    def __init__(self) -> None:
        super().__init__()
        self._state = self.DeclareVectorInputPort("panda_state", 14)
        self._X = self.DeclareVectorInputPort("X", 7)
        self._V = self.DeclareVectorInputPort("V", 6)
        index = self.DeclareDiscreteState(7)
        self.DeclarePeriodicDiscreteUpdateEvent(FAST_PERIOD_S, 0.0, self._update)
        self.DeclareStateOutputPort("torque", index)

    def _update(self, context: Context, state) -> None:
        x, X, V = self._state.Eval(context), self._X.Eval(context), self._V.Eval(context)
        state.set_value(0, 0.0 * (x[:7] + X[0] + V[0]))


class _ObserverProbe(LeafSystem):
    """Stands for the observer: a 500 Hz update reading the contact results and the
    generalised contact forces (a peak kept in the state)."""

    def __init__(self, n_arm: int) -> None:
        super().__init__()
        self._contacts = self.DeclareAbstractInputPort("contact_results", Value(ContactResults()))
        self._tau = self.DeclareVectorInputPort("generalized_contact_forces", n_arm)
        self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(FAST_PERIOD_S, 0.0, self._update)

    def _update(self, context: Context, state) -> None:
        n = self._contacts.Eval(context).num_hydroelastic_contacts()
        peak = max(
            context.get_discrete_state(0).value()[0],
            float(n),
            float(np.max(np.abs(self._tau.Eval(context)))),
        )
        state.set_value(0, [peak])


def AddPythonFloorProbes(builder: DiagramBuilder, scene: Scene) -> list[LeafSystem]:
    """Adds the five probes wired like the rLfD diagram's Python systems; returns them."""
    plant = scene.plant
    source = builder.AddSystem(_PoseSourceProbe())
    hold = builder.AddSystem(_HoldProbe())
    composer = builder.AddSystem(_PassThroughProbe())
    controller = builder.AddSystem(_ControllerProbe())
    observer = builder.AddSystem(_ObserverProbe(plant.num_velocities(scene.panda)))
    builder.Connect(source.GetOutputPort("X"), hold.GetInputPort("X_in"))
    builder.Connect(source.GetOutputPort("V"), hold.GetInputPort("V_in"))
    builder.Connect(hold.GetOutputPort("X"), composer.GetInputPort("X_in"))
    builder.Connect(hold.GetOutputPort("V"), composer.GetInputPort("V_in"))
    builder.Connect(composer.GetOutputPort("X"), controller.GetInputPort("X"))
    builder.Connect(composer.GetOutputPort("V"), controller.GetInputPort("V"))
    builder.Connect(
        plant.get_state_output_port(scene.panda), controller.GetInputPort("panda_state")
    )
    builder.Connect(
        plant.get_contact_results_output_port(), observer.GetInputPort("contact_results")
    )
    builder.Connect(
        plant.get_generalized_contact_forces_output_port(scene.panda),
        observer.GetInputPort("generalized_contact_forces"),
    )
    builder.ExportInput(composer.GetInputPort("residual"), "residual")
    return [source, hold, composer, controller, observer]
