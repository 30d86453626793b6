"""PoWER: Policy learning by Weighting Exploration with the Returns (Kober & Peters,
"Policy search for motor primitives in robotics", NIPS 2009; Machine Learning 84, 2011).

Table I's type-C baseline: Gaussian exploration in the parameter space of the DMP, i.e.
the forcing weights ``theta = rlfd_drake.dmp.get_weights(model)`` (apply a sample with
``rlfd_drake.dmp.with_weights``). Episodic, return-based variant with the exploration
held constant over an episode (so the paper's ``W_t = phi_t phi_t^T / (phi_t^T Sigma
phi_t)`` weighting reduces to the identity, as in Kober's reference code for episodic
exploration)::

    rollout k:   theta_k = theta + eps_k,   eps_k ~ N(0, diag(sigma^2))       (ask)
                 R_k = return of rollout k, R_k >= 0                          (tell)
    update:      B = the n_best rollouts with the highest returns so far (importance
                     sampling, Kober & Peters 2009)
                 eps_k = theta_k - theta            (relative to the CURRENT mean, as in
                                                     the reference implementation)
                 theta <- theta + sum_{k in B} R_k eps_k / sum_{k in B} R_k
    optional:    sigma_j^2 <- sum_{k in B} R_k eps_kj^2 / sum_{k in B} R_k  (same eps,
                 Kober & Peters 2011), floored at min_sigma

Variance adaptation starts once the memory holds ``n_best`` rollouts. It tends to
converge prematurely (measured on the tests' 8-D Gaussian bump: sigma falls to the
floor within a few hundred rollouts and the mean stalls 0.4-0.8 from the optimum,
against 0.1 with a fixed sigma), so it is off by default.

The update runs after every ``tell`` (one rollout per iteration, as in the reference
code). Since ``eps_k`` is taken from the current mean, the mean update equals the
return-weighted average of the best parameters seen so far. Returns must be >= 0 (the
returns act as an improper probability: PoWER is EM); the paper uses ``exp(-L1)``.
"""

from __future__ import annotations

import numpy as np

from rlfd_drake.baselines.checks import as_parameter_vector

__all__ = ["PoWER"]


class PoWER:
    """Episodic PoWER with an ask/tell interface.

    Args:
        theta0: initial parameters, shape (n,).
        sigma: exploration std, a scalar or per-parameter (n,); all > 0.
        n_best: how many of the best rollouts so far the update averages over.
        seed: seed of the exploration noise generator (numpy PCG64).
        adapt_variance: also update ``sigma`` from the best rollouts (see module doc).
        min_sigma: floor of the adapted ``sigma`` (keeps exploring).

    Attributes:
        theta: the current mean parameters (n,): evaluate these without noise.
        sigma: the current exploration std (n,).
        best_theta / best_return: the best rollout told so far (None / -inf at first).
        history: every told return, in order.
    """

    def __init__(
        self,
        theta0,
        sigma,
        n_best: int = 10,
        seed: int = 0,
        adapt_variance: bool = False,
        min_sigma: float = 1e-4,
    ):
        self.theta = as_parameter_vector("theta0", theta0)
        n = self.theta.size
        sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).copy()
        if not np.all(np.isfinite(sigma) & (sigma > 0.0)):
            raise ValueError(f"sigma must be > 0, got {sigma}")
        if isinstance(n_best, bool) or not isinstance(n_best, (int, np.integer)) or n_best < 1:
            raise ValueError(f"n_best must be a positive integer, got {n_best!r}")
        if not (np.isfinite(min_sigma) and min_sigma >= 0.0):
            raise ValueError(f"min_sigma must be >= 0, got {min_sigma!r}")
        self.sigma = sigma
        self.n_best = int(n_best)
        self.seed = seed
        self.adapt_variance = adapt_variance
        self.min_sigma = float(min_sigma)
        self._rng = np.random.default_rng(seed)
        # The importance-sampling memory: the n_best rollouts, best first.
        self._best_thetas = np.empty((0, n))
        self._best_returns = np.empty(0)
        self.best_theta: np.ndarray | None = None
        self.best_return = -np.inf
        self.history: list[float] = []

    @property
    def n_parameters(self) -> int:
        return self.theta.size

    def ask(self) -> np.ndarray:
        """Parameters to roll out next: ``theta + eps``, ``eps ~ N(0, diag(sigma^2))``."""
        return self.theta + self.sigma * self._rng.standard_normal(self.theta.size)

    def tell(self, theta_sampled, return_: float) -> None:
        """Report the return (>= 0) of a rollout of ``theta_sampled`` and update ``theta``."""
        theta_sampled = as_parameter_vector("theta_sampled", theta_sampled)
        if theta_sampled.shape != self.theta.shape:
            raise ValueError(
                f"theta_sampled must have shape {self.theta.shape}, got {theta_sampled.shape}"
            )
        return_ = float(return_)
        if not np.isfinite(return_) or return_ < 0.0:
            raise ValueError(f"return_ must be finite and >= 0 for PoWER, got {return_!r}")
        self.history.append(return_)
        if return_ > self.best_return:
            self.best_return, self.best_theta = return_, theta_sampled.copy()
        # Insert into the memory; a stable sort keeps the older of equal returns first.
        thetas = np.vstack([self._best_thetas, theta_sampled])
        returns = np.append(self._best_returns, return_)
        order = np.argsort(-returns, kind="stable")[: self.n_best]
        self._best_thetas, self._best_returns = thetas[order], returns[order]
        self._update()

    def _update(self) -> None:
        total = self._best_returns.sum()
        if total <= 0.0:  # all returns zero: nothing says where to go
            return
        weights = self._best_returns / total
        eps = self._best_thetas - self.theta
        # Adapt only once the memory is full: a variance estimated from fewer rollouts
        # than n_best collapses exploration after the first lucky sample.
        if self.adapt_variance and len(self._best_returns) == self.n_best:
            self.sigma = np.maximum(np.sqrt(weights @ eps**2), self.min_sigma)
        self.theta = self.theta + weights @ eps

    def __repr__(self) -> str:
        return (
            f"PoWER(n_parameters={self.n_parameters}, n_best={self.n_best}, seed={self.seed}, "
            f"adapt_variance={self.adapt_variance}, rollouts={len(self.history)})"
        )
