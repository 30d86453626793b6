"""The residual policy pi_theta inside the diagram, sampled at 10 Hz."""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import Context, DiscreteValues, LeafSystem

#: A policy maps an observation (n,) float32 to an action (6,) in [-1, 1].
Policy = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class ResidualPolicyConfig:
    """Attributes:
    period_s: policy period (10 Hz in the paper), s.
    observation_size: n, the size of the ``observation`` input.
    activation_time_s: the policy is first called at the first update at or after
        this time; before it the residual holds zero and the policy is not called, so
        its first observation and its memory (a frame stack, an LSTM) start where a
        training episode's do (``RlfdEnv`` runs the DMP alone up to the activation
        time, its action input held at zero). 0 = called from the start.
    """

    period_s: float = 0.1
    observation_size: int = 26
    activation_time_s: float = 0.0


def _as_callable(policy) -> Policy:
    """Wraps a torch ``nn.Module`` (no grad, float32 tensors); other callables as is."""
    torch = sys.modules.get("torch")
    if torch is not None and isinstance(policy, torch.nn.Module):
        module = policy.eval()

        def call(obs: np.ndarray) -> np.ndarray:
            with torch.no_grad():
                return module(torch.from_numpy(obs)).detach().cpu().numpy()

        return call
    if not callable(policy):
        raise TypeError(f"policy must be callable or a torch nn.Module, got {type(policy)}")
    return policy


class ResidualPolicy(LeafSystem):
    """Holds the residual action of a policy, updated at a fixed rate.

    .. pydrake_system::

        name: ResidualPolicy
        input_ports:
        - observation
        output_ports:
        - residual

    * ``observation`` (n): the Observer's observation.
    * ``residual`` (6): the last action, held between updates (zero-order hold),
      clipped to [-1, 1]; zero before ``activation_time_s``.

    ``policy`` is any callable ``obs (n,) float32 -> action (6,)``: a torch
    ``nn.Module`` (called under ``torch.no_grad``), a Stable-Baselines3 model via
    ``lambda obs: model.predict(obs, deterministic=True)[0]``, or a baseline. If the
    policy has a ``reset()`` method (recurrent state), it is called at every
    initialisation of the diagram (``Simulator.Initialize``), which also computes
    the first action from the initial observation when the policy acts from the start.
    A non-finite or wrongly shaped action raises RuntimeError.
    """

    def __init__(
        self,
        policy: Policy,
        config: ResidualPolicyConfig = ResidualPolicyConfig(),  # noqa: B008
    ):
        super().__init__()
        if config.period_s <= 0.0 or config.observation_size <= 0:
            raise ValueError(f"invalid ResidualPolicyConfig {config}")
        if not (np.isfinite(config.activation_time_s) and config.activation_time_s >= 0.0):
            raise ValueError(
                f"activation_time_s must be a number >= 0, got {config.activation_time_s}"
            )
        # Periodic event times are sums of floats: 50 x 0.1 s may land a hair before 5 s.
        self._first_call_s = config.activation_time_s - 1e-9
        self.config = config
        self.SetPolicy(policy)
        self._observation_port = self.DeclareVectorInputPort("observation", config.observation_size)
        state_index = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
        self.DeclareStateOutputPort("residual", state_index)

    def SetPolicy(self, policy: Policy) -> None:
        """Replaces the policy (a diagram is built once and serves many policies).
        Takes effect at the next update; call before ``Simulator.Initialize``."""
        self._policy = _as_callable(policy)
        self._policy_object = policy

    def ReleasePolicy(self) -> None:
        """Drops the policy, so that a diagram kept for reuse does not keep a model
        alive between its episodes; updates raise until ``SetPolicy`` gives another."""
        self._policy = None
        self._policy_object = None

    def ResetPolicy(self) -> None:
        """Calls the policy's ``reset()`` (recurrent state, observation stack), if it
        has one: done at every initialisation, and by ``ResumeFromSnapshot``, which
        skips the initialisation events."""
        reset = getattr(self._policy_object, "reset", None)
        if callable(reset):
            reset()

    def _initialize(self, context: Context, discrete_state: DiscreteValues) -> None:
        self.ResetPolicy()
        discrete_state.set_value(0, np.zeros(6))
        self._update(context, discrete_state)

    def _update(self, context: Context, discrete_state: DiscreteValues) -> None:
        if context.get_time() < self._first_call_s:
            return  # the held zero stays
        if self._policy is None:
            raise RuntimeError("ResidualPolicy: its policy was released; call SetPolicy first")
        obs = np.asarray(self._observation_port.Eval(context), dtype=np.float32)
        action = np.asarray(self._policy(obs), dtype=float).reshape(-1)
        if action.shape != (6,) or not np.all(np.isfinite(action)):
            raise RuntimeError(f"ResidualPolicy: the policy returned {action} (need 6 finite)")
        discrete_state.set_value(0, np.clip(action, -1.0, 1.0))
