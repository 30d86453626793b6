"""The fixed input layer that rescales the contact features for the networks."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack

from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.env import RlfdEnv
from rlfd_drake.observation_scaling import CONTACT_SCALES, ScaledObservation, contact_scales
from rlfd_drake.policies import DeployedPolicy, load_sb3_model
from rlfd_drake.systems.observer import OBSERVATION_SIZE, OBSERVATION_WRIST_TORQUE
from rlfd_drake.train import TrainConfig, make_model


def _box(size: int) -> gym.spaces.Box:
    return gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)


def test_each_stacked_frame_is_scaled_by_the_same_per_entry_scales():
    layer = ScaledObservation(_box(3 * OBSERVATION_SIZE))
    obs = torch.arange(3 * OBSERVATION_SIZE, dtype=torch.float32).reshape(1, -1) + 1.0
    out = layer(obs).reshape(3, OBSERVATION_SIZE)
    expected = obs.reshape(3, OBSERVATION_SIZE) * torch.tensor(CONTACT_SCALES)
    torch.testing.assert_close(out, expected)
    assert layer.features_dim == 3 * OBSERVATION_SIZE
    assert not list(layer.parameters())  # nothing to train


def test_the_contact_features_reach_order_one():
    scales = np.asarray(CONTACT_SCALES)
    # A part resting on the entrance 3 mm off, pressed with 80 N and a 1 N m torque,
    # in the Observer's units (2 cm, 5 N m and 50 N per unit).
    assert scales[0] * 0.003 / 0.02 == pytest.approx(0.75)
    assert scales[13] * 1.0 / 5.0 == pytest.approx(1.0)
    assert scales[17] * 80.0 / 50.0 == pytest.approx(4.0)


def test_a_small_part_gets_its_torque_scale_and_nothing_else_changes():
    scales = np.asarray(contact_scales(0.05))
    default = np.asarray(CONTACT_SCALES)
    torque = np.zeros(OBSERVATION_SIZE, bool)
    torque[OBSERVATION_WRIST_TORQUE] = True
    # The RJ-45 plug resting 2 mm off centre with 25 N: 0.05 N m, i.e. 0.01 in the
    # Observer's 5 N m units, one unit inside the network.
    assert scales[13] * 0.05 / 5.0 == pytest.approx(1.0)
    np.testing.assert_allclose(scales[torque], default[torque] * 20.0)
    np.testing.assert_array_equal(scales[~torque], default[~torque])
    assert contact_scales() == CONTACT_SCALES


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_torque_scales_are_named(value):
    with pytest.raises(ValueError, match="torque_per_unit_nm"):
        contact_scales(value)
    with pytest.raises(ValueError, match="contact_torque_nm"):
        TrainConfig(scaled_observation=True, contact_torque_nm=value)


def test_a_torque_scale_needs_the_scaled_observation():
    with pytest.raises(ValueError, match="contact_torque_nm=0.05 needs scaled_observation"):
        TrainConfig(contact_torque_nm=0.05)


@pytest.mark.parametrize(
    "space, scales, match",
    [
        (_box(30), CONTACT_SCALES, "dividing the observation size 30"),
        (_box(26), (1.0,) * 25, "must have 26 entries"),
        (_box(26), (0.0,) + (1.0,) * 25, "positive finite"),
        (gym.spaces.Box(-1, 1, (2, 13), np.float32), CONTACT_SCALES, "flat Box"),
    ],
)
def test_bad_spaces_and_scales_are_named(space, scales, match):
    with pytest.raises(ValueError, match=match):
        ScaledObservation(space, scales)


def test_scaled_sac_trains_saves_and_deploys_with_the_same_actions(tmp_path):
    fast = RlfdDiagramConfig(residual_activation_s=0.3)
    config = TrainConfig(
        algo="sac",
        envs=1,
        history=2,
        sac_learning_starts=4,
        scaled_observation=True,
        contact_torque_nm=0.05,
    )
    venv = VecFrameStack(DummyVecEnv([lambda: RlfdEnv("peg_easy", diagram_config=fast)]), n_stack=2)
    model = make_model(config, venv, None)
    assert isinstance(model.policy.actor.features_extractor, ScaledObservation)
    assert isinstance(model.policy.critic.features_extractor, ScaledObservation)
    model.learn(total_timesteps=8)
    model.save(tmp_path / "scaled.zip")
    loaded, _ = load_sb3_model(f"sac:{tmp_path / 'scaled.zip'}")
    assert isinstance(loaded.policy.actor.features_extractor, ScaledObservation)
    expected = torch.tensor(contact_scales(0.05)).repeat(2)
    for extractor in (
        loaded.policy.actor.features_extractor,
        model.policy.critic.features_extractor,
    ):
        torch.testing.assert_close(extractor.scales, expected)
    obs = np.random.default_rng(1).normal(size=(4, 2 * OBSERVATION_SIZE)).astype(np.float32)
    np.testing.assert_array_equal(
        model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0]
    )
    deployed = DeployedPolicy(loaded)
    assert deployed.history == 2 and np.all(np.isfinite(deployed(obs[0, -OBSERVATION_SIZE:])))


def test_unscaled_training_keeps_the_plain_input():
    fast = RlfdDiagramConfig(residual_activation_s=0.3)
    venv = DummyVecEnv([lambda: RlfdEnv("peg_easy", diagram_config=fast)])
    model = make_model(TrainConfig(algo="ppo", envs=1), venv, None)
    assert not isinstance(model.policy.features_extractor, ScaledObservation)


def test_hidden_entries_are_never_read_in_training_or_where_the_policy_runs(tmp_path):
    """Hidden entries are zeroed in every stacked frame; a trained, saved and deployed
    policy's action does not change with them, and bad entries are named."""
    layer = ScaledObservation(_box(2 * OBSERVATION_SIZE), hidden=(0, 20))
    scales = layer.scales.reshape(2, OBSERVATION_SIZE)
    assert torch.all(scales[:, [0, 20]] == 0.0) and torch.all(scales[:, 1] == CONTACT_SCALES[1])
    fast = RlfdDiagramConfig(residual_activation_s=0.3)
    venv = DummyVecEnv([lambda: RlfdEnv("peg_easy", diagram_config=fast)])
    config = TrainConfig(
        algo="ppo", envs=1, ppo_n_steps=16, scaled_observation=True, hidden_observation=[0, 1, 20]
    )
    assert config.hidden_observation == (0, 1, 20)
    model = make_model(config, venv, None)
    model.learn(total_timesteps=32)
    model.save(tmp_path / "hidden.zip")
    deployed = DeployedPolicy(load_sb3_model(str(tmp_path / "hidden.zip"))[0])
    with torch.no_grad():  # a trained policy whose output depends on what it reads
        for parameter in deployed.model.policy.action_net.parameters():
            parameter.normal_(0.0, 0.3)
    obs = np.random.default_rng(3).normal(size=OBSERVATION_SIZE).astype(np.float32)
    changed = obs.copy()
    changed[[0, 1, 20]] += 5.0
    np.testing.assert_array_equal(deployed(obs), deployed(changed))
    changed[2] += 5.0  # an entry it reads
    assert np.abs(deployed(obs) - deployed(changed)).max() > 1e-4
    # A bare index is one entry (it raised a TypeError from tuple(3) before).
    assert TrainConfig(scaled_observation=True, hidden_observation=3).hidden_observation == (3,)
    for bad in ((26,), (3, 3), (-1,), (1.5,), 26, "0"):
        with pytest.raises(ValueError, match="hidden observation entries must be distinct"):
            TrainConfig(scaled_observation=True, hidden_observation=bad)
    with pytest.raises(ValueError, match=r"hidden_observation=\(0,\) cannot go with"):
        TrainConfig(hidden_observation=(0,))
