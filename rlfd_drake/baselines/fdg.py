"""Finite-difference gradient (FDG) policy search (Peters & Schaal, "Reinforcement
learning of motor skills with policy gradients", Neural Networks 21(4), 2008, the
section on finite-difference methods).

Table I's second type-C baseline: it perturbs the DMP forcing weights ``theta``
(``rlfd_drake.dmp.get_weights`` / ``with_weights``). One iteration is ``1 +
n_perturbations`` rollouts::

    reference:      J_ref = J(theta)                                  (unperturbed)
    perturbations:  theta_i = theta + dtheta_i,  dtheta_i ~ N(0, sigma^2 I),
                    dJ_i = J(theta_i) - J_ref,          i = 1..n_perturbations
    gradient:       g = (dTheta^T dTheta)^-1 dTheta^T dJ    (least squares of dJ on
                    dTheta, rows dtheta_i; the minimum-norm solution when
                    n_perturbations < n, via numpy.linalg.lstsq)
    step:           theta <- theta + alpha g                (normalize_step=False)
                    theta <- theta + alpha g / |g|          (normalize_step=True)

Peters & Schaal write the step as ``theta + alpha g``; the normalised step is offered
because returns such as ``exp(-L1)`` make |g| vary by orders of magnitude.

``fit_reference=True`` (an option of ours, not the paper's default) estimates ``J_ref``
instead of measuring it: regress all returns of the iteration (the reference rollout
included, with ``dtheta = 0``) on ``[dTheta, 1]``, solving ``[dTheta, 1] [g; J_ref] =
J``, the same form as the eNAC critic's baseline. It absorbs the mean of the
second-order term ``1/2 dtheta^T H dtheta``, which the forward difference from a
single ``J(theta)`` turns into a gradient error of order ``sigma``; on the tests'
quadratic-exponential toy it halves the final error.

A unique least-squares gradient needs ``n_perturbations >= n``; with exactly ``n`` the
random square ``dTheta`` is often ill-conditioned and the step blows up (measured:
diverges on 8 parameters for some seeds), hence the default ``2 n``.
"""

from __future__ import annotations

import numpy as np

from rlfd_drake.baselines.checks import as_parameter_vector

__all__ = ["FiniteDifferenceGradient"]


class FiniteDifferenceGradient:
    """Finite-difference policy gradient with an ask/tell interface (like ``PoWER``).

    ``ask()`` hands out the iteration's rollouts in order (the reference first), and
    may be called several times before the ``tell``s (parallel rollouts);
    ``tell(theta_sampled, return_)`` matches ``theta_sampled`` to an outstanding
    rollout of the iteration. When all ``1 + n_perturbations`` returns are in,
    ``theta`` takes one gradient step and the next iteration's perturbations are drawn.

    Args:
        theta0: initial parameters, shape (n,).
        sigma: std of the perturbations, a scalar or per-parameter (n,); all > 0.
        n_perturbations: perturbed rollouts per iteration; default ``2 n`` (``n`` is the
            fewest that determine the gradient, but badly conditioned).
        learning_rate: ``alpha`` > 0.
        normalize_step: step ``alpha g / |g|`` instead of ``alpha g``.
        fit_reference: estimate ``J_ref`` jointly with ``g`` by regression (module doc)
            instead of taking the reference rollout's return.
        seed: seed of the perturbation generator (numpy PCG64).

    Attributes:
        theta: the current parameters (n,).
        gradient: the last gradient estimate (n,), None before the first iteration.
        iteration: completed iterations.
        best_theta / best_return: the best rollout told so far.
        history: every told return, in order.
    """

    def __init__(
        self,
        theta0,
        sigma,
        n_perturbations: int | None = None,
        learning_rate: float = 0.1,
        normalize_step: bool = False,
        fit_reference: bool = False,
        seed: int = 0,
    ):
        self.theta = as_parameter_vector("theta0", theta0)
        n = self.theta.size
        sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).copy()
        if not np.all(np.isfinite(sigma) & (sigma > 0.0)):
            raise ValueError(f"sigma must be > 0, got {sigma}")
        if n_perturbations is None:
            n_perturbations = 2 * n
        if (
            isinstance(n_perturbations, bool)
            or not isinstance(n_perturbations, (int, np.integer))
            or n_perturbations < 1
        ):
            raise ValueError(f"n_perturbations must be a positive integer, got {n_perturbations!r}")
        if not (np.isfinite(learning_rate) and learning_rate > 0.0):
            raise ValueError(f"learning_rate must be > 0, got {learning_rate!r}")
        self.sigma = sigma
        self.n_perturbations = int(n_perturbations)
        self.learning_rate = float(learning_rate)
        self.normalize_step = normalize_step
        self.fit_reference = fit_reference
        self.seed = seed
        self._rng = np.random.default_rng(seed)
        self.gradient: np.ndarray | None = None
        self.iteration = 0
        self.best_theta: np.ndarray | None = None
        self.best_return = -np.inf
        self.history: list[float] = []
        self._start_iteration()

    @property
    def n_parameters(self) -> int:
        return self.theta.size

    @property
    def rollouts_per_iteration(self) -> int:
        return 1 + self.n_perturbations

    @property
    def rollouts_left_to_ask(self) -> int:
        """Rollouts of the current iteration not handed out yet (a parallel batch must
        not ask for more before telling)."""
        return self.rollouts_per_iteration - self._n_asked

    def _start_iteration(self) -> None:
        perturbations = self.sigma * self._rng.standard_normal(
            (self.n_perturbations, self.theta.size)
        )
        # Row 0 is the reference (zero perturbation).
        self._perturbations = np.vstack([np.zeros(self.theta.size), perturbations])
        self._candidates = self.theta + self._perturbations
        self._returns = np.full(self.rollouts_per_iteration, np.nan)
        self._n_asked = 0

    def ask(self) -> np.ndarray:
        """The next parameters to roll out in this iteration (the reference first)."""
        if self._n_asked == self.rollouts_per_iteration:
            raise RuntimeError(
                "all rollouts of this iteration were handed out; tell their returns first"
            )
        candidate = self._candidates[self._n_asked].copy()
        self._n_asked += 1
        return candidate

    def tell(self, theta_sampled, return_: float) -> None:
        """Report the return of a rollout handed out by ``ask`` in this iteration."""
        theta_sampled = as_parameter_vector("theta_sampled", theta_sampled)
        if theta_sampled.shape != self.theta.shape:
            raise ValueError(
                f"theta_sampled must have shape {self.theta.shape}, got {theta_sampled.shape}"
            )
        return_ = float(return_)
        if not np.isfinite(return_):
            raise ValueError(f"return_ must be finite, got {return_!r}")
        outstanding = np.flatnonzero(np.isnan(self._returns[: self._n_asked]))
        matches = [i for i in outstanding if np.array_equal(self._candidates[i], theta_sampled)]
        if not matches:
            raise ValueError(
                "theta_sampled is not an outstanding rollout of this iteration "
                "(ask() for it first, and tell each return once)"
            )
        self._returns[matches[0]] = return_
        self.history.append(return_)
        if return_ > self.best_return:
            self.best_return, self.best_theta = return_, theta_sampled.copy()
        if not np.any(np.isnan(self._returns)):
            self._update()

    def _update(self) -> None:
        if self.fit_reference:
            # [dTheta, 1] [g; J_ref] = J over all rollouts, the reference included.
            design = np.hstack([self._perturbations, np.ones((len(self._returns), 1))])
            solution, *_ = np.linalg.lstsq(design, self._returns, rcond=None)
            self.gradient = solution[:-1]
        else:
            delta_theta = self._perturbations[1:]
            delta_return = self._returns[1:] - self._returns[0]
            self.gradient, *_ = np.linalg.lstsq(delta_theta, delta_return, rcond=None)
        step = self.gradient
        if self.normalize_step:
            norm = np.linalg.norm(step)
            step = step / norm if norm > 0.0 else step
        self.theta = self.theta + self.learning_rate * step
        self.iteration += 1
        self._start_iteration()

    def __repr__(self) -> str:
        return (
            f"FiniteDifferenceGradient(n_parameters={self.n_parameters}, "
            f"n_perturbations={self.n_perturbations}, learning_rate={self.learning_rate}, "
            f"normalize_step={self.normalize_step}, seed={self.seed}, "
            f"iteration={self.iteration})"
        )
