"""The mirror y -> -y: its signs follow the vectors' maths, the policy is exactly
symmetric, and it trains, saves, loads and runs in the diagram's wrapper as such."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RotationMatrix
from stable_baselines3.common.vec_env import DummyVecEnv

from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.env import RlfdEnv
from rlfd_drake.mirror_symmetry import (
    AXIAL_SIGNS,
    POLAR_SIGNS,
    MirrorSymmetricPolicy,
    action_mirror_signs,
    check_mirror_symmetric_task,
    observation_mirror_signs,
)
from rlfd_drake.policies import DeployedPolicy
from rlfd_drake.systems.observer import (
    OBSERVATION_RESIDUAL,
    OBSERVATION_WRIST_FORCE,
    OBSERVATION_WRIST_TORQUE,
)
from rlfd_drake.tasks import PoseSpec, load_task
from rlfd_drake.train import TrainConfig, load_model, make_model

MIRROR = np.diag([1.0, -1.0, 1.0])
FAST = RlfdDiagramConfig(residual_activation_s=0.3)


def fast_venv():
    return DummyVecEnv([lambda: RlfdEnv("peg_easy", diagram_config=FAST)])


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    angle_axis = RotationMatrix(R).ToAngleAxis()
    return angle_axis.angle() * angle_axis.axis()


def test_the_signs_are_the_mirror_of_polar_and_axial_vectors():
    """Positions and forces map by M; a torque r x f and a rotation's vector (the
    mirrored rotation is M R M) map by -M."""
    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(np.diag(MIRROR), POLAR_SIGNS)
    for _ in range(5):
        r, f = rng.normal(size=(2, 3))
        np.testing.assert_allclose(np.cross(MIRROR @ r, MIRROR @ f), AXIAL_SIGNS * np.cross(r, f))
        rotation_vector = rng.normal(size=3)
        angle = np.linalg.norm(rotation_vector)
        R = RotationMatrix(AngleAxis(angle, rotation_vector / angle)).matrix()
        np.testing.assert_allclose(
            _rotation_vector(MIRROR @ R @ MIRROR), AXIAL_SIGNS * rotation_vector, atol=1e-9
        )


def test_observation_and_action_signs_follow_their_layouts():
    signs = np.array(observation_mirror_signs())
    assert signs.shape == (26,)
    np.testing.assert_array_equal(signs[0:3], POLAR_SIGNS)  # position error
    np.testing.assert_array_equal(signs[3:6], AXIAL_SIGNS)  # rotation vector
    np.testing.assert_array_equal(signs[OBSERVATION_WRIST_TORQUE], AXIAL_SIGNS)
    np.testing.assert_array_equal(signs[OBSERVATION_WRIST_FORCE], POLAR_SIGNS)
    np.testing.assert_array_equal(signs[18:20], 1.0)  # phase, time
    np.testing.assert_array_equal(signs[OBSERVATION_RESIDUAL], action_mirror_signs("full"))
    assert observation_mirror_signs(3) == observation_mirror_signs() * 3
    assert action_mirror_signs("full") == POLAR_SIGNS + AXIAL_SIGNS
    assert action_mirror_signs("translation") == POLAR_SIGNS + AXIAL_SIGNS  # 6-D action
    assert action_mirror_signs("translation", applied_action_only=True) == POLAR_SIGNS
    assert action_mirror_signs("orientation", applied_action_only=True) == AXIAL_SIGNS
    with pytest.raises(ValueError, match="history must be an integer >= 1, got 0"):
        observation_mirror_signs(0)
    with pytest.raises(ValueError, match="residual_mode must be 'full' or one of"):
        action_mirror_signs("sideways")


def test_only_a_scene_symmetric_across_the_plane_is_accepted():
    peg = load_task("peg")
    check_mirror_symmetric_task(peg)  # fixture on the plane, slope about y
    moved = replace(peg, X_WFixture=PoseSpec((0.5, 0.02, 0.15), (0.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match=r"X_WFixture.position_m\[1\] must be 0, got 0.02"):
        check_mirror_symmetric_task(moved)
    turned = replace(peg, X_WFixture=PoseSpec((0.5, 0.0, 0.15), (0.0, 0.0, 30.0)))
    with pytest.raises(ValueError, match=r"X_WFixture.rpy_deg must be \[0, 0, 0\]"):
        check_mirror_symmetric_task(turned)
    tilted = replace(
        peg, fixture_error=replace(peg.fixture_error, table_slope_axis=(1.0, 0.0, 0.0))
    )
    with pytest.raises(ValueError, match="fixture_error.table_slope_axis must be"):
        check_mirror_symmetric_task(tilted)
    level = replace(tilted, fixture_error=replace(tilted.fixture_error, table_slope_deg=0.0))
    check_mirror_symmetric_task(level)  # no slope: its axis does not matter


def _randomise(model, seed: int = 0) -> None:
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in model.policy.parameters():
            if parameter.requires_grad:
                parameter.copy_(0.3 * torch.randn(parameter.shape, generator=generator))


def _mean_and_value(policy, obs: torch.Tensor):
    with torch.no_grad():
        return policy.get_distribution(obs).distribution.mean, policy.predict_values(obs)


def test_the_policy_is_exactly_symmetric_and_a_plain_one_is_not():
    obs = torch.as_tensor(np.random.default_rng(1).normal(size=(8, 26)), dtype=torch.float32)
    mirrored = obs * torch.tensor(observation_mirror_signs())
    action_signs = torch.tensor(action_mirror_signs("full"))
    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, scaled_observation=True)
    plain = make_model(config, fast_venv(), None)
    model = make_model(replace(config, mirror_symmetry=True), fast_venv(), None)
    assert isinstance(model.policy, MirrorSymmetricPolicy)
    np.testing.assert_array_equal(model.predict(obs.numpy(), deterministic=True)[0], 0.0)
    for candidate in (plain, model):
        _randomise(candidate)
    mean, value = _mean_and_value(model.policy, obs)
    mean_m, value_m = _mean_and_value(model.policy, mirrored)
    assert mean.abs().min() > 1e-4
    torch.testing.assert_close(mean_m, mean * action_signs)
    torch.testing.assert_close(value_m, value)
    # forward and evaluate_actions use the same symmetric distribution and value
    with torch.no_grad():
        actions, values, log_prob = model.policy(obs)
        values_e, log_prob_e, _ = model.policy.evaluate_actions(obs, actions)
        _, log_prob_m, _ = model.policy.evaluate_actions(mirrored, actions * action_signs)
    torch.testing.assert_close(values, value)
    torch.testing.assert_close(values_e, value)
    torch.testing.assert_close(log_prob_e, log_prob)
    torch.testing.assert_close(log_prob_m, log_prob)
    plain_mean, _ = _mean_and_value(plain.policy, obs)
    plain_mean_m, _ = _mean_and_value(plain.policy, mirrored)
    assert (plain_mean_m - plain_mean * action_signs).abs().max() > 1e-2


def test_a_symmetric_policy_trains_saves_loads_and_acts_symmetrically(tmp_path):
    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, mirror_symmetry=True)
    model = make_model(config, fast_venv(), None)
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=32)  # two updates
    assert any(
        not torch.equal(a, b) for a, b in zip(before, model.policy.parameters(), strict=True)
    )
    model.save(tmp_path / "policy.zip")
    loaded = load_model(tmp_path / "policy.zip")
    assert isinstance(loaded.policy, MirrorSymmetricPolicy)
    assert loaded.policy.action_signs == action_mirror_signs("full")
    _randomise(loaded, seed=3)  # two updates from zero move the mean by very little
    deployed = DeployedPolicy(loaded)
    obs = np.random.default_rng(2).normal(size=26).astype(np.float32) * 0.3
    action = deployed(obs)
    deployed.reset()
    action_m = deployed(obs * np.array(observation_mirror_signs(), dtype=np.float32))
    assert np.abs(action).max() > 1e-3
    np.testing.assert_allclose(action_m, action * np.array(action_mirror_signs("full")), atol=1e-6)


def test_symmetry_refuses_what_it_cannot_mirror(tmp_path):
    for kwargs, message in (
        (dict(algo="sac"), "mirror_symmetry cannot go with algo 'sac'"),
        (dict(algo="recurrent_ppo"), "mirror_symmetry cannot go with algo 'recurrent_ppo'"),
        (dict(privileged_critic=True), "mirror_symmetry cannot go with privileged_critic set"),
        (dict(ppo_sde_sample_steps=10), "mirror_symmetry cannot go with ppo_sde_sample_steps"),
        (dict(composition="pure"), "mirror_symmetry cannot go with composition 'pure'"),
    ):
        with pytest.raises(ValueError, match=message):
            TrainConfig(**{"algo": "ppo", "mirror_symmetry": True, **kwargs})
    variant = tmp_path / "peg_off_plane.yaml"
    variant.write_text(
        "based_on: peg\nname: peg_off_plane\n"
        "X_WFixture:\n  position_m: [0.5, 0.05, 0.15]\n  rpy_deg: [0.0, 0.0, 0.0]\n"
    )
    with pytest.raises(ValueError, match=r"X_WFixture.position_m\[1\] must be 0, got 0.05"):
        TrainConfig(task=str(variant), mirror_symmetry=True)
    space = fast_venv()
    with pytest.raises(ValueError, match="action_signs must be 6 signs"):
        MirrorSymmetricPolicy(
            space.observation_space,
            space.action_space,
            lambda _: 1e-3,
            observation_signs=observation_mirror_signs(),
            action_signs=(1.0, -1.0, 1.0),
        )
    with pytest.raises(ValueError, match="observation_signs must be 26 signs"):
        MirrorSymmetricPolicy(
            space.observation_space,
            space.action_space,
            lambda _: 1e-3,
            observation_signs=(0.5,) * 26,
            action_signs=action_mirror_signs("full"),
        )
