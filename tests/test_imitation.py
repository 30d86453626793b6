"""Behaviour cloning of a hand-written rule before RL (``rlfd train --imitate``)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv

from rlfd_drake.baselines.force_guided import ForceGuidedSearch
from rlfd_drake.imitation import collect_teacher_episodes, fit_policy_to_teacher
from rlfd_drake.systems.observer import (
    OBSERVATION_SIZE,
    OBSERVATION_WRIST_FORCE,
    OBSERVATION_WRIST_TORQUE,
    ObserverConfig,
)
from rlfd_drake.train import TrainConfig, load_model, make_model, train

RANGE = ObserverConfig()


class _WristEnv(gym.Env):
    """Observations of a wrist pressed down (25 N) with a random centre of pressure,
    or free, for ``length`` steps; the last step of every other episode is a success
    paying 1. The action does not matter."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)

    def __init__(self, length: int = 5):
        self.length = length
        self.episode = -1
        self.rng = np.random.default_rng(0)

    def _observation(self) -> np.ndarray:
        obs = self.rng.normal(scale=0.1, size=OBSERVATION_SIZE)
        if self.rng.random() < 0.7:
            force = np.array([0.0, 0.0, -25.0])
            centre = np.append(self.rng.normal(scale=0.004, size=2), -0.05)
            obs[OBSERVATION_WRIST_FORCE] = force / RANGE.force_scale_N
            obs[OBSERVATION_WRIST_TORQUE] = np.cross(centre, force) / RANGE.torque_scale_Nm
        else:
            obs[OBSERVATION_WRIST_FORCE] = 0.0
        return obs.astype(np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode += 1
        self.t = 0
        return self._observation(), {}

    def step(self, action):
        self.t += 1
        done = self.t == self.length
        success = done and self.episode % 2 == 0
        return self._observation(), float(success), done, False, {"success": success}


def test_teacher_episodes_hold_what_the_learner_saw_and_the_discounted_returns():
    venv = DummyVecEnv([lambda: _WristEnv(length=3), lambda: _WristEnv(length=4)])
    data = collect_teacher_episodes(venv, "force_search", episodes=3, gamma=0.5)
    assert data.episodes == 3
    # Both envs' first episodes (3 and 4 steps, successes) and env 0's second (3, not).
    assert data.successes.tolist() == [True, True, False]
    assert data.observations.shape == (10, OBSERVATION_SIZE)
    assert data.actions.shape == (10, 6)
    teacher = ForceGuidedSearch()
    np.testing.assert_allclose(
        data.actions, np.stack([teacher(o) for o in data.observations]), atol=1e-6
    )
    assert np.any(data.actions[:, 2] == 1.0)  # the rule lifted
    np.testing.assert_allclose(data.returns, [0.25, 0.5, 1.0, 0.125, 0.25, 0.5, 1.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="imitation_episodes must be >= 1, got 0"):
        collect_teacher_episodes(venv, "force_search", episodes=0, gamma=0.5)
    with pytest.raises(ValueError, match="base_correction must be one of"):
        collect_teacher_episodes(venv, "oracle", episodes=1, gamma=0.5)
    with pytest.raises(ValueError, match="force_search_and_slope needs the task"):
        collect_teacher_episodes(venv, "force_search_and_slope", episodes=1, gamma=0.5)


def test_the_fit_copies_the_rule_into_ppos_mean_and_leaves_its_noise():
    venv = DummyVecEnv([lambda: _WristEnv(length=10)])
    data = collect_teacher_episodes(venv, "force_search", episodes=60, gamma=0.99)
    # The networks read the wrist torque scaled to order one (0.05 N m per unit), as
    # the RJ-45 runs do: unscaled, the rule's input is ~0.01 beside noise of 0.1.
    config = TrainConfig(
        algo="ppo", envs=1, log_std_init=-2.0, scaled_observation=True, contact_torque_nm=0.05
    )
    model = make_model(config, venv, None)
    log_std = model.policy.log_std.detach().clone()
    report = fit_policy_to_teacher(model.policy, data, epochs=150, seed=0)
    assert report["samples"] == 600
    # The zero residual against lift 1 and a unit push: 2 / 6 per component, pressed.
    assert report["action_mse_before"] > 0.15
    assert report["action_mse_after"] < 0.1 * report["action_mse_before"]
    assert report["value_mse_after"] < report["value_mse_before"]
    assert torch.equal(model.policy.log_std, log_std)
    # What a deployed policy does: the mean action follows the rule on new observations.
    fresh = DummyVecEnv([lambda: _WristEnv(length=10)])
    fresh.envs[0].rng = np.random.default_rng(7)
    test = collect_teacher_episodes(fresh, "force_search", episodes=10, gamma=0.99)
    predicted, _ = model.predict(test.observations, deterministic=True)
    lifted = test.actions[:, 2] == 1.0
    assert np.mean(np.abs(predicted[lifted, 2] - 1.0)) < 0.2
    assert np.mean(np.sum(predicted[lifted, :2] * test.actions[lifted, :2], axis=1)) > 0.7
    with pytest.raises(ValueError, match="imitation_epochs must be >= 1, got 0"):
        fit_policy_to_teacher(model.policy, data, epochs=0, seed=0)


def test_imitation_settings_are_checked():
    with pytest.raises(ValueError, match="imitate must be one of"):
        TrainConfig(imitate="oracle")
    with pytest.raises(ValueError, match="cannot go with algo 'sac'"):
        TrainConfig(algo="sac", imitate="force_search")
    with pytest.raises(ValueError, match="cannot go with base_correction"):
        TrainConfig(imitate="force_search", base_correction="force_search")
    with pytest.raises(ValueError, match="imitation_episodes must be >= 1, got 0"):
        TrainConfig(imitate="force_search", imitation_episodes=0)


def test_a_run_starts_from_the_copied_rule_and_keeps_the_copy(tmp_path):
    """The real env: the rule's episodes, the fit, then PPO; the copy is the checkpoint
    at step 0 and the metrics say how the fit went."""
    config = TrainConfig(
        algo="ppo",
        episodes=1,
        envs=1,
        ppo_n_steps=8,
        imitate="force_search",
        imitation_episodes=2,
        imitation_epochs=3,
    )
    run = tmp_path / "run"
    metrics = train(config, run, progress_bar=False)
    imitation = metrics["imitation"]
    assert imitation["teacher"] == "force_search"
    assert imitation["teacher_episodes"] == 2
    assert imitation["samples"] > 2
    assert json.loads((run / "imitation.json").read_text()) == imitation
    copy = load_model(run / "checkpoints" / "policy_0_steps.zip")
    final = load_model(run / "policy.zip")
    changed = any(
        not torch.equal(a, b)
        for a, b in zip(copy.policy.parameters(), final.policy.parameters(), strict=True)
    )
    assert changed  # RL moved on from the copy
