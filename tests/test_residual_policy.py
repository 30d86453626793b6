"""ResidualPolicy with a plain callable and a torch module."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink

from rlfd_drake.systems.residual_policy import ResidualPolicy, ResidualPolicyConfig

N_OBS = 4


class CountingPolicy:
    """Action = 0.1 * (number of calls since reset) in every entry; records resets."""

    def __init__(self):
        self.calls = 0
        self.resets = 0

    def reset(self):
        self.calls = 0
        self.resets += 1

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        assert obs.dtype == np.float32
        self.calls += 1
        return np.full(6, 0.1 * self.calls)


def _simulate(policy, duration: float, obs: np.ndarray | None = None, activation_s: float = 0.0):
    obs = np.arange(N_OBS, dtype=float) if obs is None else obs
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(obs))
    config = ResidualPolicyConfig(0.1, N_OBS, activation_time_s=activation_s)
    system = builder.AddSystem(ResidualPolicy(policy, config))
    builder.Connect(source.get_output_port(), system.GetInputPort("observation"))
    log = builder.AddSystem(VectorLogSink(6, 0.05))
    builder.Connect(system.GetOutputPort("residual"), log.get_input_port())
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    data = log.FindLog(simulator.get_context())
    return simulator, data.sample_times(), data.data().T


def test_callable_held_at_10_hz_and_reset_at_initialisation():
    policy = CountingPolicy()
    simulator, times, actions = _simulate(policy, 0.35)
    assert policy.resets == 1
    # Initialisation + updates at 0, 0.1, 0.2, 0.3 -> 5 calls; held in between.
    assert policy.calls == 5
    np.testing.assert_allclose(actions[np.isclose(times, 0.15)][0], 0.3)  # init, t=0, t=0.1
    # Actions beyond 1 are clipped.
    simulator.Initialize()
    assert policy.resets == 2
    simulator.AdvanceTo(1.5)
    assert np.all(simulator.get_context().get_discrete_state(0).get_value() == 1.0)


def test_policy_first_called_at_its_activation_time():
    """Before the activation time the residual holds zero and the policy is not
    called (its memory starts where a training episode's does); from it, as usual."""
    policy = CountingPolicy()
    simulator, times, actions = _simulate(policy, 0.55, activation_s=0.3)
    assert policy.resets == 1
    # Updates at 0.3, 0.4, 0.5 (0.3 is 3 x 0.1 s of float sums, a hair off 0.3).
    assert policy.calls == 3
    np.testing.assert_array_equal(actions[times < 0.3 - 1e-9], 0.0)
    np.testing.assert_allclose(actions[np.isclose(times, 0.35)][0], 0.1)
    np.testing.assert_allclose(actions[-1], 0.3)
    simulator.get_mutable_context().SetTime(0.0)
    simulator.Initialize()  # a new episode starts at zero again
    assert policy.resets == 2 and policy.calls == 0
    np.testing.assert_array_equal(simulator.get_context().get_discrete_state(0).get_value(), 0.0)
    with pytest.raises(ValueError, match="activation_time_s must be a number >= 0, got -1"):
        ResidualPolicy(policy, ResidualPolicyConfig(0.1, N_OBS, activation_time_s=-1.0))


def test_torch_module_policy():
    torch.manual_seed(0)
    module = torch.nn.Sequential(
        torch.nn.Linear(N_OBS, 16), torch.nn.Tanh(), torch.nn.Linear(16, 6), torch.nn.Tanh()
    )
    obs = np.array([0.1, -0.2, 0.3, 0.4])
    _, _, actions = _simulate(module, 0.2, obs)
    expected = module(torch.tensor(obs, dtype=torch.float32)).detach().numpy()
    np.testing.assert_allclose(actions[-1], expected, atol=1e-6)


def test_bad_action_raises():
    with pytest.raises(RuntimeError, match="need 6 finite"):
        _simulate(lambda obs: np.zeros(5), 0.1)
    with pytest.raises(RuntimeError, match="need 6 finite"):
        _simulate(lambda obs: np.full(6, np.nan), 0.1)
    with pytest.raises(TypeError, match="callable"):
        ResidualPolicy(42)


def test_a_released_policy_is_let_go_and_not_called():
    """A diagram kept for reuse drops its policy between episodes (ReleasePolicy): the
    policy is no longer referenced, an update says so, and SetPolicy brings one back."""
    import gc
    import weakref

    policy = CountingPolicy()
    simulator, _, _ = _simulate(policy, 0.15)
    system = next(s for s in simulator.get_system().GetSystems() if isinstance(s, ResidualPolicy))
    system.ReleasePolicy()
    released = weakref.ref(policy)
    del policy
    gc.collect()
    assert released() is None
    simulator.get_mutable_context().SetTime(0.0)
    with pytest.raises(RuntimeError, match="policy was released; call SetPolicy first"):
        simulator.Initialize()
    again = CountingPolicy()
    system.SetPolicy(again)
    simulator.Initialize()
    simulator.AdvanceTo(0.15)
    assert again.resets == 1 and again.calls == 3
