"""Self-imitation beside PPO: returns over rollouts, and the update rule on known answers."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv

from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.env import RlfdEnv
from rlfd_drake.self_imitation import EpisodeReturns, SelfImitation, discounted_returns
from rlfd_drake.train import TrainConfig, make_model


def fast_venv():
    config = RlfdDiagramConfig(residual_activation_s=0.3)
    return DummyVecEnv([lambda: RlfdEnv("peg_easy", diagram_config=config)])


def test_discounted_returns():
    np.testing.assert_allclose(discounted_returns([0, 0, 1], 0.5), [0.25, 0.5, 1.0])
    np.testing.assert_allclose(discounted_returns([1, 1], 1.0), [2.0, 1.0])


def test_episode_returns_follow_episodes_across_rollouts():
    """Env 0's episode spans both rollouts; env 1 finishes one in each and opens a third."""
    collector = EpisodeReturns(n_envs=2, gamma=0.5)
    steps = np.arange(6, dtype=float).reshape(3, 2)  # observation = step id
    rewards = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    starts = np.array([[1, 1], [0, 0], [0, 1]])  # env 1 starts again at step 2
    finished = collector.add_rollout(steps[..., None], steps[..., None], rewards, starts, [0, 0])
    assert len(finished) == 1  # env 1's first episode: steps 1 and 3
    observations, actions, returns = finished[0]
    np.testing.assert_array_equal(observations[:, 0], [1, 3])
    np.testing.assert_allclose(returns, [0.5, 1.0])
    more = steps + 6
    rewards = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    starts = np.array([[0, 0], [1, 0], [0, 0]])
    finished = collector.add_rollout(more[..., None], more[..., None], rewards, starts, [0, 1])
    observations, _, returns = finished[0]  # env 0: 0, 2, 4, then 6 with the reward
    np.testing.assert_array_equal(observations[:, 0], [0, 2, 4, 6])
    np.testing.assert_allclose(returns, [0.125, 0.25, 0.5, 1.0])
    observations, _, returns = finished[1]  # env 1: 5, 7, 9, 11, nothing earned
    np.testing.assert_array_equal(observations[:, 0], [5, 7, 9, 11])
    np.testing.assert_array_equal(returns, 0.0)
    with pytest.raises(ValueError, match="gamma must be in"):
        EpisodeReturns(n_envs=1, gamma=1.5)


def _filled(model, returns_above_value: float, action: np.ndarray) -> SelfImitation:
    """A SelfImitation on ``model`` storing 64 steps of ``action``, each returning the
    critic's value plus ``returns_above_value``."""
    callback = SelfImitation(batches=10, seed=0)
    callback.init_callback(model)
    observations = np.random.default_rng(1).normal(size=(64, 26)).astype(np.float32)
    with torch.no_grad():
        values = model.policy.predict_values(torch.as_tensor(observations)).flatten().numpy()
    actions = np.repeat(action[None], 64, axis=0).astype(np.float32)
    callback._store(observations, actions, values + returns_above_value)
    return callback


def _mean_actions(model, observations) -> np.ndarray:
    with torch.no_grad():
        tensor = torch.as_tensor(observations)
        return model.policy.get_distribution(tensor).distribution.mean.numpy()


def test_self_imitation_pulls_towards_actions_that_beat_the_critic():
    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, log_std_init=-2.0)
    model = make_model(config, fast_venv(), None)
    target = np.array([0.5, -0.3, 0.2, 0.0, 0.1, -0.1])
    callback = _filled(model, 1.0, target)
    before = np.abs(_mean_actions(model, callback.observations) - target).mean()
    distances = []
    for _ in range(20):
        callback.on_rollout_start()
        distances.append(np.abs(_mean_actions(model, callback.observations) - target).mean())
    # The critic's term raises the values towards the returns, so fewer steps beat them.
    assert callback.updates == 200 and 0.0 < callback.last_positive_fraction < 1.0
    assert distances[4] < before and distances[-1] < 0.5 * before  # the residual starts at 0
    # Returns the critic already expects (or exceeds) weigh nothing: no update at all.
    model = make_model(config, fast_venv(), None)
    callback = _filled(model, -0.5, target)
    parameters = [p.detach().clone() for p in model.policy.parameters()]
    callback.on_rollout_start()
    assert callback.updates == 0 and callback.last_positive_fraction == 0.0
    after = model.policy.parameters()
    assert all(torch.equal(a, b) for a, b in zip(parameters, after, strict=True))
    with pytest.raises(ValueError, match="batches must be an integer >= 1, got 0"):
        SelfImitation(batches=0)


def test_self_imitation_stores_the_episodes_ppo_rolled_out():
    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=32)
    model = make_model(config, fast_venv(), None)
    callback = SelfImitation(batches=2, seed=0)
    model.learn(total_timesteps=128, callback=callback)  # four rollouts
    assert callback.observations is not None and len(callback.returns) > 0
    assert len(callback.returns) == len(callback.actions) == len(callback.observations)
    assert len(callback.returns) <= 128 and np.all(callback.returns >= 0)  # sparse reward


def test_self_imitation_is_refused_where_it_cannot_run():
    with pytest.raises(ValueError, match="self_imitation_batches must be >= 0, got -1"):
        TrainConfig(self_imitation_batches=-1)
    for algo in ("sac", "recurrent_ppo"):
        with pytest.raises(
            ValueError, match=f"self_imitation_batches=4 cannot go with algo '{algo}'"
        ):
            TrainConfig(algo=algo, self_imitation_batches=4)
