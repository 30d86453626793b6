"""Episodic Natural Actor-Critic (eNAC) for a linear-Gaussian policy (Peters & Schaal,
"Natural Actor-Critic", Neurocomputing 71, 2008, the episodic natural actor-critic
algorithm; applied to motor primitives in Peters & Schaal, ESANN 2007, which the
paper cites).

Table I's type-B baseline: exploration in the DMP's phase-modulated coupling term
``C_t`` (``rlfd_drake.dmp.dmp_step(..., coupling=C_t)``), with ``phi_t`` e.g. the
normalised basis activations times the phase, ``psi_i(x) x / sum_j psi_j(x)``
(``rlfd_drake.dmp.basis_features``)::

    policy:      u_t = theta^T phi_t + eps_t,   eps_t ~ N(0, sigma^2 I),
                 theta (n_features, n_outputs)
    score:       grad_theta log pi(u_t | phi_t) = phi_t (u_t - theta^T phi_t)^T / sigma^2
    episode e:   psi_e = sum_t grad_theta log pi(u_t | phi_t)   (flattened, length d)
                 R_e   = the episode's return (undiscounted sum of rewards)
    critic:      solve the least-squares regression over the batch of episodes
                     [psi_e^T, 1] [w; J] = R_e
                 (w: natural gradient, J: baseline; numpy.linalg.lstsq, i.e. the
                 minimum-norm solution when the batch has fewer than d + 1 episodes)
    actor:       theta <- theta + alpha w               (normalize_step=False, default,
                                                         as in Peters & Schaal 2008)
                 theta <- theta + alpha w / |w|         (normalize_step=True)

For this policy the Fisher matrix is ``sum_t E[phi phi^T] / sigma^2 (x) I``, so ``w``
is ``sigma^2 (sum_t E[phi phi^T])^-1 grad J``: ``alpha`` of order ``1 / sigma^2``
gives steps of order one in theta (see the tests' linear-quadratic problem, where
``w = -2 sigma^2 (theta - K*)``).
"""

from __future__ import annotations

import numpy as np

from rlfd_drake.baselines.checks import check_positive_int

__all__ = ["EpisodicNaturalActorCritic"]


class EpisodicNaturalActorCritic:
    """eNAC for ``u = theta^T phi + N(0, sigma^2 I)``.

    Use: ``reset()`` at the start of an episode, ``act(phi)`` at every step,
    ``end_episode(return_)`` at the end (or, with rollouts in worker processes,
    ``episode_score()`` there and ``tell_episode(score, steps, return_)`` here); every
    ``episodes_per_update`` episodes the natural gradient is estimated and ``theta``
    updated. In ``deterministic`` mode
    ``act`` returns the mean and nothing is recorded (evaluation).

    Args:
        n_features: length of ``phi``.
        n_outputs: length of ``u`` (6 for the translation + orientation coupling term).
        sigma: exploration std (> 0), in the units of ``u``.
        learning_rate: ``alpha`` (> 0).
        seed: seed of the exploration noise generator (numpy PCG64).
        episodes_per_update: batch size of the critic regression; default ``2 (d + 1)``
            with ``d = n_features n_outputs`` (the regression has ``d + 1`` unknowns).
        normalize_step: step ``alpha w / |w|`` instead of ``alpha w``.
        theta0: initial parameters (n_features, n_outputs); zeros (no coupling) if None.
        deterministic: start in evaluation mode (attribute, may be switched later).

    Attributes:
        theta: the policy mean parameters (n_features, n_outputs).
        natural_gradient: the last ``w`` (n_features, n_outputs), None before.
        baseline: the last ``J`` of the regression, None before.
        n_updates: number of actor updates so far.
        history: every told return, in order.
    """

    def __init__(
        self,
        n_features: int,
        n_outputs: int,
        sigma: float,
        learning_rate: float,
        seed: int = 0,
        episodes_per_update: int | None = None,
        normalize_step: bool = False,
        theta0: np.ndarray | None = None,
        deterministic: bool = False,
    ):
        self.n_features = check_positive_int("n_features", n_features)
        self.n_outputs = check_positive_int("n_outputs", n_outputs)
        if not (np.isfinite(sigma) and sigma > 0.0):
            raise ValueError(f"sigma must be > 0, got {sigma!r}")
        if not (np.isfinite(learning_rate) and learning_rate > 0.0):
            raise ValueError(f"learning_rate must be > 0, got {learning_rate!r}")
        n_parameters = self.n_features * self.n_outputs
        if episodes_per_update is None:
            episodes_per_update = 2 * (n_parameters + 1)
        self.episodes_per_update = check_positive_int("episodes_per_update", episodes_per_update)
        self.sigma = float(sigma)
        self.learning_rate = float(learning_rate)
        self.normalize_step = normalize_step
        self.seed = seed
        self.deterministic = deterministic
        shape = (self.n_features, self.n_outputs)
        if theta0 is None:
            self.theta = np.zeros(shape)
        else:
            self.theta = np.array(theta0, dtype=float)
            if self.theta.shape != shape:
                raise ValueError(f"theta0 must have shape {shape}, got {self.theta.shape}")
        self._rng = np.random.default_rng(seed)
        self._episode_score = np.zeros(shape)  # running sum of grad log pi
        self._episode_steps = 0
        self._batch_scores: list[np.ndarray] = []
        self._batch_returns: list[float] = []
        self.natural_gradient: np.ndarray | None = None
        self.baseline: float | None = None
        self.n_updates = 0
        self.history: list[float] = []

    def reset(self) -> None:
        """Start of an episode: drop what an unfinished episode accumulated."""
        self._episode_score = np.zeros_like(self.theta)
        self._episode_steps = 0

    def act(self, phi) -> tuple[np.ndarray, np.ndarray]:
        """Sample ``u`` for features ``phi`` (n_features,).

        Returns ``(u, grad log pi(u | phi))`` with shapes (n_outputs,) and
        (n_features, n_outputs); in deterministic mode ``(theta^T phi, zeros)``.
        """
        phi = np.asarray(phi, dtype=float)
        if phi.shape != (self.n_features,):
            raise ValueError(f"phi must have shape ({self.n_features},), got {phi.shape}")
        if not np.all(np.isfinite(phi)):
            raise ValueError(f"phi must be finite, got {phi}")
        mean = self.theta.T @ phi
        if self.deterministic:
            return mean, np.zeros_like(self.theta)
        noise = self.sigma * self._rng.standard_normal(self.n_outputs)
        score = np.outer(phi, noise) / self.sigma**2
        self._episode_score += score
        self._episode_steps += 1
        return mean + noise, score

    def episode_score(self) -> tuple[np.ndarray, int]:
        """The current episode's ``sum_t grad log pi`` (n_features, n_outputs) (a copy) and
        its number of stochastic steps, e.g. to send from a rollout worker to the learner."""
        return self._episode_score.copy(), self._episode_steps

    def end_episode(self, return_: float) -> np.ndarray | None:
        """Store the episode's ``(psi, R)``; update ``theta`` when the batch is full.

        Returns the natural gradient ``w`` (n_features, n_outputs) if this episode
        completed a batch, else None. Episodes without stochastic steps (deterministic
        mode, or no ``act`` call) are not stored.
        """
        score, steps = self.episode_score()
        self.reset()
        return self.tell_episode(score, steps, return_)

    def tell_episode(self, score, steps: int, return_: float) -> np.ndarray | None:
        """``end_episode`` for an episode run elsewhere (``episode_score`` of a copy of
        this learner with the same ``theta`` in a worker)."""
        if not np.isfinite(return_):
            raise ValueError(f"return_ must be finite, got {return_!r}")
        score = np.asarray(score, dtype=float)
        if score.shape != self.theta.shape:
            raise ValueError(f"score must have shape {self.theta.shape}, got {score.shape}")
        if steps == 0:
            return None
        self.history.append(float(return_))
        self._batch_scores.append(score.ravel().copy())
        self._batch_returns.append(float(return_))
        if len(self._batch_returns) < self.episodes_per_update:
            return None
        return self._update()

    def _update(self) -> np.ndarray:
        scores = np.asarray(self._batch_scores)
        design = np.hstack([scores, np.ones((len(scores), 1))])
        solution, *_ = np.linalg.lstsq(design, np.asarray(self._batch_returns), rcond=None)
        w = solution[:-1].reshape(self.theta.shape)
        self.natural_gradient, self.baseline = w, float(solution[-1])
        step = w
        if self.normalize_step:
            norm = np.linalg.norm(w)
            step = w / norm if norm > 0.0 else w
        self.theta = self.theta + self.learning_rate * step
        self.n_updates += 1
        self._batch_scores.clear()
        self._batch_returns.clear()
        return w

    def __repr__(self) -> str:
        return (
            f"EpisodicNaturalActorCritic(n_features={self.n_features}, "
            f"n_outputs={self.n_outputs}, sigma={self.sigma}, "
            f"learning_rate={self.learning_rate}, episodes_per_update="
            f"{self.episodes_per_update}, seed={self.seed})"
        )
