"""The paper's "Linear" baseline: an adaptive linear residual policy in task space,
fitted by recursive least squares (Davchev et al. 2022, Tables II and IV; the paper
cites Kumar, Todorov & Levine 2016 for it and gives no update rule, so the rule below
is ours, built from two textbook parts).

1. ``RecursiveLeastSquares``: exponentially weighted RLS (Haykin, *Adaptive Filter
   Theory*, 5th ed., 2014, the chapter on the RLS algorithm), with vector targets. After ``n``
   samples ``(phi_i, y_i, weight w_i)`` it holds the minimiser of::

       sum_i lambda^(n-i) w_i |y_i - theta^T phi_i|^2 + lambda^n delta |theta - theta_0|^2

   by the per-sample recursion (``P`` is the inverse of the weighted Gram matrix)::

       phi, y  <- sqrt(w) phi, sqrt(w) y                 (sample weight)
       k       = P phi / (lambda + phi^T P phi)          (gain, (n_features,))
       e       = y - theta^T phi                          (a-priori error, (n_outputs,))
       theta  <- theta + k e^T                            ((n_features, n_outputs))
       P      <- (P - k phi^T P) / lambda,               P_0 = I / delta

2. ``LinearResidualPolicy``: reward-weighted regression (Peters & Schaal, "Reinforcement
   learning by reward-weighted regression for operational space control", ICML 2007)
   of a linear-Gaussian policy, solved by the RLS above::

       phi(obs) = [obs[observation_indices], 1]
       a_t      = clip(theta^T phi_t + eps_t, -1, 1) * mask,  eps_t ~ N(0, std^2 I)
       end of an episode with return R > 0:
           P <- P / lambda_episode                        (forget older episodes once)
           for each step t: RLS update with (phi_t, a_t) and weight w = R

   so ``theta`` is the return-weighted (and recency-weighted) least-squares fit of the
   explored actions: the EM / RWR policy update ``theta = argmin sum_k R_k |a_k -
   theta^T phi_k|^2``, computed incrementally. Episodes with ``R <= 0`` are left out
   (RWR needs non-negative weights; the paper's sparse reward gives 0 or positive).

   Weighting by the raw return is weak when returns vary smoothly: for a return
   ``exp(-|a - a*|^2 / c)`` and exploration std ``s`` an episode pulls the fit about
   ``(1 - lambda) 2 s^2 / (c + 2 s^2)`` of the way to ``a*`` while its noise pushes it
   about ``(1 - lambda) s`` at random, so the error settles where the two balance
   (measured, one-step episodes, s = 0.3, lambda = 0.8, start error 0.54: c = 1
   settles near 0.27; c = 0.1 reaches 0.08 after 100 episodes and 0.04 after 400).
   With the paper's sparse return (0, or positive on success) it reduces to
   regressing on the successful episodes.

Both are pure numpy (no Drake, no torch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rlfd_drake.baselines.checks import check_positive_int

__all__ = ["LinearPolicyConfig", "LinearResidualPolicy", "RecursiveLeastSquares"]

# The residual action: translation (0:3) and rotation vector (3:6), as
# rlfd_drake.diagram.RESIDUAL_SIZE; repeated here so this module never imports pydrake.
RESIDUAL_SIZE = 6


def _check_forgetting(name: str, value: float) -> float:
    if not (np.isfinite(value) and 0.0 < value <= 1.0):
        raise ValueError(f"{name} must be in (0, 1], got {value!r}")
    return float(value)


def _as_vector(name: str, value, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array}")
    return array


class RecursiveLeastSquares:
    """Exponentially weighted recursive least squares with vector targets.

    Model ``y = theta^T phi``, ``theta`` of shape (n_features, n_outputs); the
    recursion and the cost it minimises are in the module docstring (Haykin 2014).
    All outputs share ``P``: one RLS per output column with the same regressors, at
    the cost of one.

    Args:
        n_features: length of the regressor ``phi``.
        n_outputs: length of the target ``y``.
        forgetting_factor: ``lambda`` in (0, 1]; 1 is ordinary (growing-window) least
            squares, smaller values forget old samples (memory ~ 1 / (1 - lambda)).
        delta: ``P_0 = I / delta`` (> 0): the weight of the prior ``theta_0``; tiny
            values give plain least squares after ``n_features`` independent samples.
        theta0: initial parameters, shape (n_features, n_outputs); zeros if None.
        max_covariance_trace: if set, forgetting is reduced whenever it would push
            ``trace(P)`` above this bound, which prevents the blow-up of ``P`` in
            directions that the data do not excite ("covariance wind-up"; the
            bounded-trace remedy, e.g. Salgado, Goodwin & Middleton 1988).
    """

    def __init__(
        self,
        n_features: int,
        n_outputs: int,
        forgetting_factor: float = 1.0,
        delta: float = 1e-2,
        theta0: np.ndarray | None = None,
        max_covariance_trace: float | None = None,
    ):
        self.n_features = check_positive_int("n_features", n_features)
        self.n_outputs = check_positive_int("n_outputs", n_outputs)
        self.forgetting_factor = _check_forgetting("forgetting_factor", forgetting_factor)
        if not (np.isfinite(delta) and delta > 0.0):
            raise ValueError(f"delta must be > 0, got {delta!r}")
        if max_covariance_trace is not None and not max_covariance_trace > 0.0:
            raise ValueError(f"max_covariance_trace must be > 0, got {max_covariance_trace!r}")
        self.delta = float(delta)
        self.max_covariance_trace = max_covariance_trace
        shape = (self.n_features, self.n_outputs)
        if theta0 is None:
            self.theta = np.zeros(shape)
        else:
            self.theta = np.array(theta0, dtype=float)
            if self.theta.shape != shape:
                raise ValueError(f"theta0 must have shape {shape}, got {self.theta.shape}")
        self.covariance = np.eye(self.n_features) / self.delta  # P
        self.n_updates = 0

    def _divide_covariance(self, unforgotten: np.ndarray, factor: float) -> np.ndarray:
        """``unforgotten / factor``, with the forgetting limited by the trace bound."""
        if self.max_covariance_trace is not None and factor < 1.0:
            trace = float(np.trace(unforgotten))
            factor = min(1.0, max(factor, trace / self.max_covariance_trace))
        return unforgotten / factor

    def update(self, phi, y, weight: float = 1.0) -> np.ndarray:
        """One RLS step with regressor ``phi`` (n_features,) and target ``y`` (n_outputs,).

        ``weight`` >= 0 multiplies the sample's squared error in the cost (implemented
        by scaling ``phi`` and ``y`` by ``sqrt(weight)``). Returns the a-priori error
        ``y - theta^T phi`` (n_outputs,) before the update (unweighted).
        """
        phi = _as_vector("phi", phi, self.n_features)
        y = _as_vector("y", y, self.n_outputs)
        if not (np.isfinite(weight) and weight >= 0.0):
            raise ValueError(f"weight must be >= 0, got {weight!r}")
        error = y - self.theta.T @ phi
        root = np.sqrt(weight)
        phi_w, error_w = root * phi, root * error
        lam = self.forgetting_factor
        p_phi = self.covariance @ phi_w
        gain = p_phi / (lam + phi_w @ p_phi)
        self.theta = self.theta + np.outer(gain, error_w)
        # P - k phi^T P, written with the symmetric P so that P stays symmetric.
        unforgotten = self.covariance - np.outer(gain, p_phi)
        unforgotten = 0.5 * (unforgotten + unforgotten.T)
        self.covariance = self._divide_covariance(unforgotten, lam)
        self.n_updates += 1
        return error

    def discount(self, factor: float) -> None:
        """Age all past data by ``factor`` in (0, 1] without a new sample: ``P <- P / factor``.

        One forgetting step of the recursion on its own (the RLS step with
        ``lambda`` equals this followed by the step with ``lambda = 1``); used to
        forget per episode rather than per sample.
        """
        factor = _check_forgetting("factor", factor)
        self.covariance = self._divide_covariance(self.covariance, factor)

    def predict(self, phi) -> np.ndarray:
        """``theta^T phi``: (n_outputs,) for phi (n_features,), (n, n_outputs) for (n, ...)."""
        phi = np.asarray(phi, dtype=float)
        if phi.shape[-1:] != (self.n_features,) or phi.ndim > 2:
            raise ValueError(
                f"phi must have shape ({self.n_features},) or (n, {self.n_features}), "
                f"got {phi.shape}"
            )
        return phi @ self.theta

    def get_state(self) -> dict[str, np.ndarray]:
        """``theta``, ``covariance`` and ``n_updates`` as numpy arrays (np.savez-able)."""
        return {
            "theta": self.theta.copy(),
            "covariance": self.covariance.copy(),
            "n_updates": np.array(self.n_updates),
        }

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore what ``get_state`` returned (shapes are checked)."""
        theta = np.array(state["theta"], dtype=float)
        covariance = np.array(state["covariance"], dtype=float)
        if theta.shape != self.theta.shape:
            raise ValueError(f"theta must have shape {self.theta.shape}, got {theta.shape}")
        if covariance.shape != self.covariance.shape:
            raise ValueError(
                f"covariance must have shape {self.covariance.shape}, got {covariance.shape}"
            )
        self.theta, self.covariance = theta, covariance
        self.n_updates = int(state.get("n_updates", 0))

    def __repr__(self) -> str:
        return (
            f"RecursiveLeastSquares(n_features={self.n_features}, n_outputs={self.n_outputs}, "
            f"forgetting_factor={self.forgetting_factor}, delta={self.delta})"
        )


@dataclass(frozen=True)
class LinearPolicyConfig:
    """Settings of ``LinearResidualPolicy``.

    Attributes:
        observation_indices: entries of the observation used as features; None = all.
        translation: act on the translation part (0:3) of the residual; zeros otherwise.
        orientation: act on the rotation part (3:6); zeros otherwise. Table II uses
            translation only; Table IV's "Linear / Random" pairs a translation-only
            Linear policy with a RandomResidualPolicy on orientation.
        exploration_std: std of the Gaussian exploration noise, in action units
            (the action lives in [-1, 1]).
        forgetting_factor: ``lambda_episode`` in (0, 1], applied once per rewarded
            episode (not per step, so long episodes do not wash out the others).
        delta: ``P_0 = I / delta``: how strongly ``theta`` is held at zero (the zero
            residual, i.e. the DMP alone) before rewarded data arrive.
        max_covariance_trace: bound on ``trace(P)`` (see RecursiveLeastSquares).
    """

    observation_indices: tuple[int, ...] | None = None
    translation: bool = True
    orientation: bool = True
    exploration_std: float = 0.2
    forgetting_factor: float = 0.9
    delta: float = 1.0
    max_covariance_trace: float | None = 1e6

    def __post_init__(self) -> None:
        if not (np.isfinite(self.exploration_std) and self.exploration_std >= 0.0):
            raise ValueError(f"exploration_std must be >= 0, got {self.exploration_std!r}")
        _check_forgetting("forgetting_factor", self.forgetting_factor)
        if not (np.isfinite(self.delta) and self.delta > 0.0):
            raise ValueError(f"delta must be > 0, got {self.delta!r}")
        if self.observation_indices is not None and len(self.observation_indices) == 0:
            raise ValueError("observation_indices must be None or non-empty, got ()")


class LinearResidualPolicy:
    """Adaptive linear residual policy in task space (the paper's "Linear" baseline).

    ``action = clip(theta^T [obs_sel, 1] + eps, -1, 1) * mask`` with ``theta`` of shape
    (n_selected + 1, 6), adapted after each episode by reward-weighted regression
    solved with recursive least squares (module docstring). ``theta`` starts at zero,
    so an untrained policy is the zero residual plus exploration noise.

    Use: ``reset()`` at the start of each episode, ``policy(obs)`` at every residual
    step (10 Hz), ``end_episode(return_)`` at the end (or, with rollouts in worker
    processes, ``episode_samples()`` there and ``tell_episode(features, actions,
    return_)`` here). With ``deterministic=True`` no noise is added and nothing is
    recorded (evaluation).

    Args:
        observation_size: length of the observations the policy will be given.
        config: LinearPolicyConfig; the defaults if None.
        seed: seed of the exploration noise generator (numpy PCG64).
        deterministic: start in evaluation mode (attribute, may be switched later).
    """

    def __init__(
        self,
        observation_size: int,
        config: LinearPolicyConfig | None = None,
        seed: int = 0,
        deterministic: bool = False,
    ):
        self.observation_size = check_positive_int("observation_size", observation_size)
        self.config = LinearPolicyConfig() if config is None else config
        indices = self.config.observation_indices
        if indices is None:
            self._indices = np.arange(self.observation_size)
        else:
            self._indices = np.asarray(indices, dtype=int)
            bad = [i for i in indices if not 0 <= i < self.observation_size]
            if bad:
                raise ValueError(
                    f"observation_indices must lie in [0, {self.observation_size}), got {bad}"
                )
        self.seed = seed
        self.deterministic = deterministic
        self._rng = np.random.default_rng(seed)
        self._mask = np.zeros(RESIDUAL_SIZE)
        self._mask[0:3] = 1.0 if self.config.translation else 0.0
        self._mask[3:6] = 1.0 if self.config.orientation else 0.0
        # The RLS itself does not forget per sample; end_episode forgets per episode.
        self.rls = RecursiveLeastSquares(
            n_features=len(self._indices) + 1,
            n_outputs=RESIDUAL_SIZE,
            forgetting_factor=1.0,
            delta=self.config.delta,
            max_covariance_trace=self.config.max_covariance_trace,
        )
        self._episode_features: list[np.ndarray] = []
        self._episode_actions: list[np.ndarray] = []
        self.n_episodes = 0
        self.n_rewarded_episodes = 0

    @property
    def theta(self) -> np.ndarray:
        """The policy's parameters, shape (n_selected + 1, 6) (last row: the bias)."""
        return self.rls.theta

    def features(self, observation) -> np.ndarray:
        """``phi(obs) = [obs[observation_indices], 1]``, shape (n_selected + 1,)."""
        observation = _as_vector("observation", observation, self.observation_size)
        return np.append(observation[self._indices], 1.0)

    def reset(self) -> None:
        """Start of an episode: forget the (unfinished) episode buffer."""
        self._episode_features.clear()
        self._episode_actions.clear()

    def __call__(self, observation) -> np.ndarray:
        """The action (6,) in [-1, 1] for ``observation``; explores unless deterministic."""
        phi = self.features(observation)
        action = self.rls.predict(phi)
        if not self.deterministic:
            # Draw all 6 entries whatever the mask, so the stream does not depend on it.
            action = action + self.config.exploration_std * self._rng.standard_normal(RESIDUAL_SIZE)
        action = np.clip(action, -1.0, 1.0) * self._mask
        if not self.deterministic:
            self._episode_features.append(phi)
            self._episode_actions.append(action)
        return action

    def episode_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The current episode's explored samples: features (T, n_selected + 1) and
        actions (T, 6) (copies), e.g. to send from a rollout worker to the learner."""
        n_features = self.rls.n_features
        features = np.array(self._episode_features).reshape(-1, n_features)
        actions = np.array(self._episode_actions).reshape(-1, RESIDUAL_SIZE)
        return features, actions

    def end_episode(self, return_: float) -> int:
        """Adapt ``theta`` toward this episode's explored actions, weighted by ``return_``.

        Only ``return_ > 0`` contributes (reward-weighted regression needs
        non-negative weights and zero weight teaches nothing). Clears the buffer.
        Returns the number of samples regressed on.
        """
        features, actions = self.episode_samples()
        self.reset()
        return self.tell_episode(features, actions, return_)

    def tell_episode(self, features, actions, return_: float) -> int:
        """``end_episode`` for samples explored elsewhere (``episode_samples`` of a copy
        of this policy in a worker): features (T, n_selected + 1), actions (T, 6)."""
        if not np.isfinite(return_):
            raise ValueError(f"return_ must be finite, got {return_!r}")
        features = np.asarray(features, dtype=float)
        actions = np.asarray(actions, dtype=float)
        n_features = self.rls.n_features
        if features.ndim != 2 or features.shape[1] != n_features:
            raise ValueError(f"features must have shape (T, {n_features}), got {features.shape}")
        if actions.shape != (len(features), RESIDUAL_SIZE):
            raise ValueError(
                f"actions must have shape ({len(features)}, {RESIDUAL_SIZE}), got {actions.shape}"
            )
        n_samples = 0
        if return_ > 0.0 and len(features):
            self.rls.discount(self.config.forgetting_factor)
            for phi, action in zip(features, actions, strict=True):
                self.rls.update(phi, action, weight=float(return_))
            n_samples = len(features)
            self.n_rewarded_episodes += 1
        self.n_episodes += 1
        return n_samples

    def get_state(self) -> dict[str, np.ndarray]:
        """The learnt state as numpy arrays (np.savez-able); the noise stream is not saved."""
        state = self.rls.get_state()
        state["n_episodes"] = np.array(self.n_episodes)
        state["n_rewarded_episodes"] = np.array(self.n_rewarded_episodes)
        return state

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore what ``get_state`` returned (e.g. ``dict(np.load(path))``)."""
        self.rls.set_state(state)
        self.n_episodes = int(state.get("n_episodes", 0))
        self.n_rewarded_episodes = int(state.get("n_rewarded_episodes", 0))

    def __repr__(self) -> str:
        return (
            f"LinearResidualPolicy(observation_size={self.observation_size}, "
            f"config={self.config}, seed={self.seed}, deterministic={self.deterministic})"
        )
