"""Update rules of the non-residual baselines (RLS / Linear, PoWER, FDG, eNAC) on
problems with known answers: exact least-squares identities, hand-computed updates,
and convergence to a known optimum (seeded, pure numpy, fast)."""

import numpy as np
import pytest

from rlfd_drake.baselines.enac import EpisodicNaturalActorCritic
from rlfd_drake.baselines.fdg import FiniteDifferenceGradient
from rlfd_drake.baselines.power import PoWER
from rlfd_drake.baselines.rls import (
    LinearPolicyConfig,
    LinearResidualPolicy,
    RecursiveLeastSquares,
)


def gaussian_bump(theta, theta_star, width=4.0):
    """R(theta) = exp(-|theta - theta*|^2 / width), maximum 1 at theta*."""
    return float(np.exp(-np.sum((theta - theta_star) ** 2) / width))


@pytest.fixture(scope="module")
def theta_star():
    """An 8-D optimum, |theta*| = 1.84."""
    return np.random.default_rng(0).uniform(-1.0, 1.0, 8)


# --------------------------------------------------------------------------------------
# Recursive least squares
# --------------------------------------------------------------------------------------
def test_rls_recovers_linear_map_exactly_from_noiseless_data():
    rng = np.random.default_rng(1)
    true_map = rng.normal(size=(4, 3))
    rls = RecursiveLeastSquares(4, 3, delta=1e-10)
    for _ in range(20):
        phi = rng.normal(size=4)
        rls.update(phi, true_map.T @ phi)
    np.testing.assert_allclose(rls.theta, true_map, atol=1e-6)
    phi = rng.normal(size=(5, 4))
    np.testing.assert_allclose(rls.predict(phi), phi @ true_map, atol=1e-6)
    assert rls.n_updates == 20


def test_rls_matches_lstsq_plain_weighted_and_forgetting():
    rng = np.random.default_rng(2)
    n_samples, n_features, n_outputs = 60, 5, 2
    features = rng.normal(size=(n_samples, n_features))
    targets = features @ rng.normal(size=(n_features, n_outputs)) + 0.3 * rng.normal(
        size=(n_samples, n_outputs)
    )
    weights = rng.uniform(0.1, 2.0, n_samples)
    lam = 0.97
    # Each RLS variant against the batch least squares it should equal.
    cases = {
        "plain": (1.0, np.ones(n_samples)),
        "weighted": (1.0, weights),
        "forgetting": (lam, weights * lam ** np.arange(n_samples - 1, -1, -1)),
    }
    for name, (forgetting, batch_weights) in cases.items():
        rls = RecursiveLeastSquares(n_features, n_outputs, forgetting_factor=forgetting, delta=1e-9)
        for i in range(n_samples):
            rls.update(features[i], targets[i], weight=1.0 if name == "plain" else weights[i])
        root = np.sqrt(batch_weights)[:, None]
        expected, *_ = np.linalg.lstsq(root * features, root * targets, rcond=None)
        np.testing.assert_allclose(rls.theta, expected, atol=1e-6, err_msg=name)


def test_rls_tracks_a_changed_map_only_with_forgetting():
    rng = np.random.default_rng(3)
    map_a, map_b = rng.normal(size=(3, 2)), rng.normal(size=(3, 2))
    forgetting, growing = (RecursiveLeastSquares(3, 2, forgetting_factor=f) for f in (0.9, 1.0))
    for true_map in (map_a, map_b):
        for _ in range(150):
            phi = rng.normal(size=3)
            forgetting.update(phi, true_map.T @ phi)
            growing.update(phi, true_map.T @ phi)
    # Old data weigh 0.9^150 ~ 1e-7 with forgetting; half the data without.
    np.testing.assert_allclose(forgetting.theta, map_b, atol=1e-4)
    assert np.abs(growing.theta - map_b).max() > 0.1


def test_rls_discount_equals_one_forgetting_step_and_trace_bound():
    rng = np.random.default_rng(4)
    phi, y = rng.normal(size=3), rng.normal(size=2)
    with_lambda = RecursiveLeastSquares(3, 2, forgetting_factor=0.8, delta=0.5)
    split = RecursiveLeastSquares(3, 2, forgetting_factor=1.0, delta=0.5)
    with_lambda.update(phi, y)
    split.discount(0.8)
    split.update(phi, y)
    # The lambda-step == P <- P / lambda, then the lambda = 1 step.
    np.testing.assert_allclose(split.theta, with_lambda.theta, atol=1e-12)
    np.testing.assert_allclose(split.covariance, with_lambda.covariance, atol=1e-12)
    bounded = RecursiveLeastSquares(3, 1, delta=1.0, max_covariance_trace=10.0)
    for _ in range(100):
        bounded.discount(0.5)  # no data: P would grow as 2^100 without the bound
    assert np.trace(bounded.covariance) == pytest.approx(10.0)


def test_rls_state_round_trip(tmp_path):
    rng = np.random.default_rng(5)
    rls = RecursiveLeastSquares(3, 2)
    for _ in range(5):
        rls.update(rng.normal(size=3), rng.normal(size=2))
    np.savez(tmp_path / "rls.npz", **rls.get_state())
    restored = RecursiveLeastSquares(3, 2)
    restored.set_state(dict(np.load(tmp_path / "rls.npz")))
    np.testing.assert_array_equal(restored.theta, rls.theta)
    np.testing.assert_array_equal(restored.covariance, rls.covariance)
    assert restored.n_updates == 5


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"forgetting_factor": 0.0}, "forgetting_factor must be in \\(0, 1\\], got 0.0"),
        ({"forgetting_factor": 1.5}, "forgetting_factor must be in \\(0, 1\\], got 1.5"),
        ({"delta": -1.0}, "delta must be > 0, got -1.0"),
        ({"n_features": 0}, "n_features must be a positive integer, got 0"),
        ({"theta0": np.zeros((2, 2))}, "theta0 must have shape \\(3, 2\\), got \\(2, 2\\)"),
    ],
)
def test_rls_rejects_bad_settings(kwargs, match):
    settings = {"n_features": 3, "n_outputs": 2} | kwargs
    with pytest.raises(ValueError, match=match):
        RecursiveLeastSquares(**settings)


def test_rls_rejects_bad_samples():
    rls = RecursiveLeastSquares(3, 2)
    with pytest.raises(ValueError, match="phi must have shape \\(3,\\), got \\(4,\\)"):
        rls.update(np.zeros(4), np.zeros(2))
    with pytest.raises(ValueError, match="y must have shape \\(2,\\), got \\(3,\\)"):
        rls.update(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="weight must be >= 0, got -1.0"):
        rls.update(np.zeros(3), np.zeros(2), weight=-1.0)
    with pytest.raises(ValueError, match="factor must be in"):
        rls.discount(0.0)


# --------------------------------------------------------------------------------------
# Linear residual policy (RLS + reward-weighted regression)
# --------------------------------------------------------------------------------------
OBS = np.array([0.1, -0.2, 0.3, 0.05])


def test_linear_policy_shape_range_and_masks():
    wild = LinearPolicyConfig(exploration_std=5.0)  # noise far beyond [-1, 1]
    policy = LinearResidualPolicy(4, wild, seed=0)
    actions = np.array([policy(OBS) for _ in range(50)])
    assert actions.shape == (50, 6)
    assert np.all(np.abs(actions) <= 1.0) and np.any(np.abs(actions) == 1.0)
    translation_only = LinearResidualPolicy(4, LinearPolicyConfig(orientation=False), seed=0)
    orientation_only = LinearResidualPolicy(4, LinearPolicyConfig(translation=False), seed=0)
    for _ in range(10):
        a = translation_only(OBS)
        assert np.all(a[3:6] == 0.0) and np.all(a[0:3] != 0.0)
        b = orientation_only(OBS)
        assert np.all(b[0:3] == 0.0) and np.all(b[3:6] != 0.0)


def test_linear_policy_deterministic_is_noise_free_and_records_nothing():
    policy = LinearResidualPolicy(4, seed=0)
    policy.rls.theta = np.random.default_rng(0).normal(scale=0.1, size=(5, 6))
    policy.deterministic = True
    expected = np.clip(policy.theta.T @ np.append(OBS, 1.0), -1.0, 1.0)
    for _ in range(3):
        np.testing.assert_array_equal(policy(OBS), expected)
    theta = policy.theta.copy()
    assert policy.end_episode(1.0) == 0
    np.testing.assert_array_equal(policy.theta, theta)


def test_linear_policy_same_seed_same_actions():
    runs = []
    for seed in (7, 7, 8):
        policy = LinearResidualPolicy(4, seed=seed)
        runs.append(np.array([policy(OBS) for _ in range(5)]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.allclose(runs[0], runs[2])


def test_linear_policy_one_rewarded_episode_has_the_closed_form_answer():
    # One sample (phi, a), weight R, prior P0 = I / delta aged once by lambda: the ridge
    # solution predicts R |phi|^2 / (lambda delta + R |phi|^2) * a at phi.
    delta, forgetting, reward = 1.0, 0.9, 2.0
    config = LinearPolicyConfig(delta=delta, forgetting_factor=forgetting)
    policy = LinearResidualPolicy(4, config, seed=0)
    policy.reset()
    explored = policy(OBS)
    assert policy.end_episode(0.0) == 0  # zero return: nothing learnt
    np.testing.assert_array_equal(policy.theta, 0.0)
    policy.reset()
    explored = policy(OBS)
    assert policy.end_episode(reward) == 1
    norm2 = np.sum(np.append(OBS, 1.0) ** 2)
    policy.deterministic = True
    np.testing.assert_allclose(
        policy(OBS), reward * norm2 / (forgetting * delta + reward * norm2) * explored, atol=1e-12
    )


def test_linear_policy_learns_the_rewarded_action():
    # One-step episodes at a fixed observation, return exp(-|a - a*|^2 / 0.1) > 0.
    # Measured over 30 seeds after 100 episodes: median 0.08, max 0.13 (start: 0.54).
    a_star = np.array([0.4, -0.3, 0.2, 0.0, 0.0, 0.0])
    config = LinearPolicyConfig(orientation=False, exploration_std=0.3, forgetting_factor=0.8)
    for seed in range(3):
        policy = LinearResidualPolicy(4, config, seed=seed)
        for _ in range(100):
            policy.reset()
            action = policy(OBS)
            policy.end_episode(np.exp(-np.sum((action - a_star) ** 2) / 0.1))
        policy.deterministic = True
        assert np.linalg.norm(policy(OBS) - a_star) < 0.15
        assert policy.n_rewarded_episodes == 100


def test_linear_policy_state_round_trip(tmp_path):
    policy = LinearResidualPolicy(4, LinearPolicyConfig(observation_indices=(0, 2)), seed=0)
    for _ in range(3):
        policy.reset()
        policy(OBS)
        policy.end_episode(1.0)
    np.savez(tmp_path / "linear.npz", **policy.get_state())
    restored = LinearResidualPolicy(4, LinearPolicyConfig(observation_indices=(0, 2)), seed=1)
    restored.set_state(dict(np.load(tmp_path / "linear.npz")))
    policy.deterministic = restored.deterministic = True
    np.testing.assert_array_equal(restored(OBS), policy(OBS))
    assert restored.theta.shape == (3, 6) and restored.n_rewarded_episodes == 3


def test_linear_policy_worker_samples_teach_like_end_episode():
    learner, local = LinearResidualPolicy(4, seed=0), LinearResidualPolicy(4, seed=0)
    worker = LinearResidualPolicy(4, seed=0)
    for policy in (local, worker):
        policy.reset()
        for _ in range(3):
            policy(OBS)
    features, actions = worker.episode_samples()
    assert features.shape == (3, 5) and actions.shape == (3, 6)
    assert learner.tell_episode(features, actions, 0.7) == local.end_episode(0.7) == 3
    np.testing.assert_array_equal(learner.theta, local.theta)
    with pytest.raises(ValueError, match="actions must have shape \\(3, 6\\), got \\(3, 5\\)"):
        learner.tell_episode(features, features, 1.0)


def test_linear_policy_rejects_bad_input():
    with pytest.raises(ValueError, match="exploration_std must be >= 0, got -0.1"):
        LinearPolicyConfig(exploration_std=-0.1)
    with pytest.raises(ValueError, match="forgetting_factor must be in \\(0, 1\\], got 1.2"):
        LinearPolicyConfig(forgetting_factor=1.2)
    with pytest.raises(ValueError, match="observation_indices must lie in \\[0, 4\\), got \\[4\\]"):
        LinearResidualPolicy(4, LinearPolicyConfig(observation_indices=(0, 4)))
    policy = LinearResidualPolicy(4)
    with pytest.raises(ValueError, match="observation must have shape \\(4,\\), got \\(3,\\)"):
        policy(np.zeros(3))
    with pytest.raises(ValueError, match="return_ must be finite, got nan"):
        policy.end_episode(float("nan"))


# --------------------------------------------------------------------------------------
# PoWER
# --------------------------------------------------------------------------------------
def test_power_update_by_hand():
    power = PoWER(np.zeros(2), sigma=0.5, n_best=2, seed=0)
    power.tell([1.0, 0.0], 1.0)
    np.testing.assert_allclose(power.theta, [1.0, 0.0])  # one rollout: its parameters
    power.tell([0.0, 1.0], 3.0)
    # theta + sum R_k eps_k / sum R_k, eps from the current mean [1, 0]:
    # [1, 0] + (1 * [0, 0] + 3 * [-1, 1]) / 4 = [0.25, 0.75].
    np.testing.assert_allclose(power.theta, [0.25, 0.75])
    power.tell([5.0, 5.0], 2.0)  # replaces the return-1 rollout in the best two
    # [0.25, 0.75] + (3 [-0.25, 0.25] + 2 [4.75, 4.25]) / 5: the weighted mean of the two.
    np.testing.assert_allclose(
        power.theta, (3 * np.array([0.0, 1.0]) + 2 * np.array([5.0, 5.0])) / 5
    )
    np.testing.assert_array_equal(power.best_theta, [0.0, 1.0])
    assert power.best_return == 3.0 and power.history == [1.0, 3.0, 2.0]


def test_power_variance_adaptation_by_hand():
    power = PoWER(np.zeros(2), sigma=0.5, n_best=2, seed=0, adapt_variance=True, min_sigma=0.0)
    power.tell([1.0, 0.0], 1.0)
    np.testing.assert_allclose(power.sigma, 0.5)  # memory not full yet: unchanged
    power.tell([0.0, 1.0], 3.0)
    # sigma^2 = (1 * [0, 0]^2 + 3 * [-1, 1]^2) / 4 with eps from the mean [1, 0].
    np.testing.assert_allclose(power.sigma, np.sqrt([0.75, 0.75]))


def test_power_zero_returns_do_not_move_theta():
    power = PoWER(np.ones(3), sigma=0.1, seed=0)
    for _ in range(5):
        power.tell(power.ask(), 0.0)
    np.testing.assert_array_equal(power.theta, np.ones(3))


def test_power_converges_on_a_gaussian_bump(theta_star):
    # Measured over 20 seeds after 1000 rollouts: median 0.085, max 0.127 (start 1.84).
    for seed in range(2):
        power = PoWER(np.zeros(8), sigma=0.2, n_best=10, seed=seed)
        for _ in range(1000):
            theta = power.ask()
            power.tell(theta, gaussian_bump(theta, theta_star))
        assert np.linalg.norm(power.theta - theta_star) < 0.15
        assert len(power.history) == 1000
        assert power.best_return == pytest.approx(max(power.history))


def test_power_same_seed_same_samples():
    a, b = PoWER(np.zeros(4), 0.3, seed=3), PoWER(np.zeros(4), 0.3, seed=3)
    np.testing.assert_array_equal(a.ask(), b.ask())


def test_power_rejects_bad_input():
    with pytest.raises(ValueError, match="sigma must be > 0, got \\[-0.1 -0.1\\]"):
        PoWER(np.zeros(2), sigma=-0.1)
    with pytest.raises(ValueError, match="n_best must be a positive integer, got 0"):
        PoWER(np.zeros(2), sigma=0.1, n_best=0)
    power = PoWER(np.zeros(2), sigma=0.1)
    with pytest.raises(ValueError, match="return_ must be finite and >= 0 for PoWER, got -0.5"):
        power.tell(np.zeros(2), -0.5)
    with pytest.raises(ValueError, match="theta_sampled must have shape \\(2,\\), got \\(3,\\)"):
        power.tell(np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="theta0 must be a non-empty 1-D array"):
        PoWER(np.zeros((2, 2)), sigma=0.1)


# --------------------------------------------------------------------------------------
# Finite-difference gradient
# --------------------------------------------------------------------------------------
def run_fdg_iteration(fdg, objective):
    for _ in range(fdg.rollouts_per_iteration):
        theta = fdg.ask()
        fdg.tell(theta, objective(theta))


@pytest.mark.parametrize("fit_reference", [False, True])
def test_fdg_gradient_is_exact_for_a_linear_return(fit_reference):
    slope = np.array([1.0, -2.0, 0.5])
    fdg = FiniteDifferenceGradient(
        np.zeros(3), sigma=0.1, learning_rate=0.2, fit_reference=fit_reference, seed=0
    )
    assert fdg.n_perturbations == 6 and fdg.rollouts_per_iteration == 7
    run_fdg_iteration(fdg, lambda theta: slope @ theta + 4.0)
    np.testing.assert_allclose(fdg.gradient, slope, atol=1e-10)
    np.testing.assert_allclose(fdg.theta, 0.2 * slope, atol=1e-10)
    assert fdg.iteration == 1
    normalised = FiniteDifferenceGradient(np.zeros(3), 0.1, learning_rate=0.2, normalize_step=True)
    run_fdg_iteration(normalised, lambda theta: slope @ theta)
    np.testing.assert_allclose(normalised.theta, 0.2 * slope / np.linalg.norm(slope), atol=1e-10)


@pytest.mark.parametrize(("fit_reference", "tolerance"), [(False, 0.1), (True, 0.05)])
def test_fdg_converges_on_a_gaussian_bump(theta_star, fit_reference, tolerance):
    # 20 iterations of 1 + 16 rollouts. Measured over 20 seeds: median 0.053 / max 0.086
    # (reference rollout), median 0.023 / max 0.035 (fitted reference); start 1.84.
    for seed in range(2):
        fdg = FiniteDifferenceGradient(
            np.zeros(8), sigma=0.02, learning_rate=1.0, fit_reference=fit_reference, seed=seed
        )
        for _ in range(20):
            run_fdg_iteration(fdg, lambda theta: gaussian_bump(theta, theta_star))
        assert np.linalg.norm(fdg.theta - theta_star) < tolerance
        assert len(fdg.history) == 20 * 17


def test_fdg_ask_tell_protocol():
    fdg = FiniteDifferenceGradient(np.ones(2), sigma=0.1, n_perturbations=3, seed=0)
    asked = [fdg.ask() for _ in range(4)]
    np.testing.assert_array_equal(asked[0], np.ones(2))  # the reference comes first
    with pytest.raises(RuntimeError, match="tell their returns first"):
        fdg.ask()
    with pytest.raises(ValueError, match="not an outstanding rollout"):
        fdg.tell(np.zeros(2), 1.0)
    for theta in reversed(asked):  # any order, e.g. from parallel workers
        fdg.tell(theta, float(theta.sum()))
    assert fdg.iteration == 1
    np.testing.assert_allclose(fdg.gradient, [1.0, 1.0], atol=1e-10)
    with pytest.raises(ValueError, match="not an outstanding rollout"):
        fdg.tell(asked[0], 1.0)  # belongs to the finished iteration


def test_fdg_rejects_bad_input():
    with pytest.raises(ValueError, match="sigma must be > 0, got \\[0. 0.\\]"):
        FiniteDifferenceGradient(np.zeros(2), sigma=0.0)
    with pytest.raises(ValueError, match="n_perturbations must be a positive integer, got 0"):
        FiniteDifferenceGradient(np.zeros(2), sigma=0.1, n_perturbations=0)
    with pytest.raises(ValueError, match="learning_rate must be > 0, got -1.0"):
        FiniteDifferenceGradient(np.zeros(2), sigma=0.1, learning_rate=-1.0)
    fdg = FiniteDifferenceGradient(np.zeros(2), sigma=0.1)
    with pytest.raises(ValueError, match="return_ must be finite, got inf"):
        fdg.tell(fdg.ask(), float("inf"))


# --------------------------------------------------------------------------------------
# Episodic natural actor-critic
# --------------------------------------------------------------------------------------
def lq_episode(enac, features, gain):
    """One episode of u_t = policy(phi_t), return -sum_t |u_t - gain^T phi_t|^2."""
    enac.reset()
    total = 0.0
    for phi in features:
        u, _ = enac.act(phi)
        total -= float(np.sum((u - gain.T @ phi) ** 2))
    return enac.end_episode(total)


@pytest.fixture(scope="module")
def lq_problem():
    """Features phi_t (8 steps, 4 features) fixed across episodes and the optimum K* (4, 3).

    The features are orthogonal (sum_t phi_t phi_t^T = 2 I) so that the estimation noise
    is the same in every direction of theta; |K*| = 1.74.
    """
    rng = np.random.default_rng(10)
    orthonormal, _ = np.linalg.qr(rng.normal(size=(8, 4)))
    return np.sqrt(2.0) * orthonormal, rng.uniform(-1.0, 1.0, size=(4, 3))


def test_enac_natural_gradient_matches_the_lq_closed_form(lq_problem):
    # For u = theta^T phi + N(0, sigma^2 I) and R = -sum_t |u_t - K*^T phi_t|^2 the
    # natural gradient is w = -2 sigma^2 (theta - K*), whatever the features. Measured
    # over 10 seeds with 1000 episodes: relative error median 1.4 %, max 2.3 %.
    features, gain = lq_problem
    sigma = 0.1
    enac = EpisodicNaturalActorCritic(4, 3, sigma, learning_rate=1.0, episodes_per_update=1000)
    w = None
    for _ in range(1000):
        w = lq_episode(enac, features, gain)
    assert w is not None and enac.n_updates == 1
    expected = 2 * sigma**2 * gain  # theta = 0
    assert np.linalg.norm(w - expected) < 0.05 * np.linalg.norm(expected)
    np.testing.assert_allclose(enac.theta, w)  # alpha = 1 from theta = 0
    expected_baseline = -sum(np.sum((gain.T @ phi) ** 2) for phi in features) - 8 * 3 * sigma**2
    assert enac.baseline == pytest.approx(expected_baseline, rel=0.01)


def test_enac_converges_to_the_lq_optimum(lq_problem):
    # alpha = 0.1 / sigma^2 contracts theta - K* by 0.8 per update in expectation.
    # Measured over 20 seeds after 30 updates of 30 episodes: median 0.034, max 0.043
    # (start |K*| = 1.74).
    features, gain = lq_problem
    sigma = 0.05
    enac = EpisodicNaturalActorCritic(4, 3, sigma, 0.1 / sigma**2, seed=0, episodes_per_update=30)
    for _ in range(30 * 30):
        lq_episode(enac, features, gain)
    assert enac.n_updates == 30
    assert np.linalg.norm(enac.theta - gain) < 0.08


def test_enac_score_deterministic_mode_and_normalised_step():
    sigma = 0.5
    enac = EpisodicNaturalActorCritic(2, 3, sigma, learning_rate=0.3, seed=0, normalize_step=True)
    enac.theta = np.arange(6.0).reshape(2, 3)
    phi = np.array([0.5, -1.0])
    u, score = enac.act(phi)
    np.testing.assert_allclose(score, np.outer(phi, u - enac.theta.T @ phi) / sigma**2)
    enac.deterministic = True
    u, score = enac.act(phi)
    np.testing.assert_array_equal(u, enac.theta.T @ phi)
    np.testing.assert_array_equal(score, 0.0)
    assert enac.end_episode(1.0) is None  # counts the stochastic step taken above
    enac.deterministic = False
    theta = enac.theta.copy()
    for episode in range(enac.episodes_per_update - 1):
        enac.reset()
        enac.act(phi)
        enac.end_episode(float(episode))
    assert enac.episodes_per_update == 14  # 2 (d + 1), d = 6
    assert np.linalg.norm(enac.theta - theta) == pytest.approx(0.3)
    enac.deterministic = True
    enac.reset()
    enac.act(phi)
    assert enac.end_episode(5.0) is None and len(enac.history) == 14


def test_enac_worker_scores_teach_like_end_episode(lq_problem):
    features, gain = lq_problem
    local = EpisodicNaturalActorCritic(4, 3, 0.1, 1.0, seed=0, episodes_per_update=20)
    learner = EpisodicNaturalActorCritic(4, 3, 0.1, 1.0, seed=99, episodes_per_update=20)
    worker = EpisodicNaturalActorCritic(4, 3, 0.1, 1.0, seed=0, episodes_per_update=20)
    for _ in range(20):
        lq_episode(local, features, gain)
        worker.reset()
        total = 0.0
        for phi in features:
            u, _ = worker.act(phi)
            total -= float(np.sum((u - gain.T @ phi) ** 2))
        score, steps = worker.episode_score()
        assert steps == 8
        learner.tell_episode(score, steps, total)
    assert learner.n_updates == local.n_updates == 1
    np.testing.assert_allclose(learner.theta, local.theta, atol=1e-12)
    with pytest.raises(ValueError, match="score must have shape \\(4, 3\\), got \\(3, 4\\)"):
        learner.tell_episode(np.zeros((3, 4)), 1, 0.0)


def test_enac_rejects_bad_input():
    with pytest.raises(ValueError, match="sigma must be > 0, got -1.0"):
        EpisodicNaturalActorCritic(2, 3, sigma=-1.0, learning_rate=0.1)
    with pytest.raises(ValueError, match="learning_rate must be > 0, got 0.0"):
        EpisodicNaturalActorCritic(2, 3, sigma=1.0, learning_rate=0.0)
    with pytest.raises(ValueError, match="theta0 must have shape \\(2, 3\\), got \\(3, 2\\)"):
        EpisodicNaturalActorCritic(2, 3, 1.0, 0.1, theta0=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="episodes_per_update must be a positive integer, got 0"):
        EpisodicNaturalActorCritic(2, 3, 1.0, 0.1, episodes_per_update=0)
    enac = EpisodicNaturalActorCritic(2, 3, 1.0, 0.1)
    with pytest.raises(ValueError, match="phi must have shape \\(2,\\), got \\(3,\\)"):
        enac.act(np.zeros(3))
    with pytest.raises(ValueError, match="return_ must be finite, got nan"):
        enac.end_episode(float("nan"))
