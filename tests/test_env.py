"""The Gym env: API checks, the DrakeGymEnv fixes, determinism, pickling, failures."""

from __future__ import annotations

import dataclasses
import pickle

import gymnasium as gym
import numpy as np
import pytest

from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.env import ENV_IDS, RlfdEnv
from rlfd_drake.tasks import load_task

# A short DMP-only phase keeps the tests fast; the env's logic is the same.
FAST = RlfdDiagramConfig(residual_activation_s=0.3)


def make_env(**kwargs) -> RlfdEnv:
    return RlfdEnv("peg_easy", diagram_config=FAST, **kwargs)


def test_all_ids_registered_and_make():
    for env_id, task in ENV_IDS.items():
        assert env_id in gym.registry
        assert gym.registry[env_id].kwargs["task"] == task
    env = gym.make("rlfd/PegInsertion-v0")
    assert env.unwrapped.task.name == "peg_easy"
    assert env.action_space.shape == (6,)
    assert env.observation_space.shape == (26,)


def test_gymnasium_and_sb3_check_env():
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make_env()
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=True)


def _rollout(env: RlfdEnv, seed: int, actions: np.ndarray):
    obs, info = env.reset(seed=seed)
    trace = [obs]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        trace.append(obs)
        if terminated or truncated:
            break
    return np.array(trace), info


def test_same_seed_same_episode_and_different_seed_differs():
    actions = np.random.default_rng(0).uniform(-1, 1, (4, 6)).astype(np.float32)
    a, info_a = _rollout(make_env(), 7, actions)
    b, info_b = _rollout(make_env(), 7, actions)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(info_a["fixture_dp"], info_b["fixture_dp"])
    c, info_c = _rollout(make_env(), 8, actions)
    assert not np.array_equal(info_a["start_dp"], info_c["start_dp"])


def test_resets_move_the_fixture_in_one_diagram():
    """The env builds its diagram once (pydrake never frees one holding a Python
    system) and moves the fixture at each reset: an episode after other episodes is
    the one a new env runs from the same start and fixture error."""
    actions = np.random.default_rng(1).uniform(-1, 1, (4, 6)).astype(np.float32)
    env = make_env()
    _rollout(env, 5, actions)
    diagram = env.rlfd.diagram
    used, info = _rollout(env, 6, actions)
    assert env.rlfd.diagram is diagram
    options = {k: info[k] for k in ("start_dp", "start_dq", "fixture_dp", "fixture_dq")}
    new_env = make_env()
    obs, _ = new_env.reset(seed=6, options=options)
    trace = [obs] + [new_env.step(action)[0] for action in actions[: len(used) - 1]]
    np.testing.assert_array_equal(used, np.array(trace))
    np.testing.assert_array_equal(
        env._true_goal().GetAsMatrix4(), new_env._true_goal().GetAsMatrix4()
    )


def test_info_handler_is_not_dropped():
    env = make_env(info_handler=lambda simulator: {"sim_time": simulator.get_context().get_time()})
    _, info = env.reset(seed=0)
    assert info["sim_time"] == pytest.approx(0.3)
    _, _, _, _, info = env.step(np.zeros(6, np.float32))
    assert info["sim_time"] == pytest.approx(0.4)


def test_reset_options_are_accepted_and_checked():
    env = make_env()
    dp = np.array([0.01, -0.02, 0.03])
    _, info = env.reset(seed=0, options={"start_dp": dp, "fixture_dp": np.zeros(3)})
    np.testing.assert_array_equal(info["start_dp"], dp)
    np.testing.assert_array_equal(info["fixture_dp"], np.zeros(3))
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=0, options={"start": 1})
    with pytest.raises(ValueError, match="start_dq must be a unit quaternion"):
        env.reset(seed=0, options={"start_dq": [1.0, 1.0, 0.0, 0.0]})


def test_perturbation_scale_zero_starts_at_the_demo_start():
    env = make_env(perturbation_scale=0.0)
    _, info = env.reset(seed=3)
    np.testing.assert_allclose(info["start_dp"], 0.0)
    with pytest.raises(ValueError, match="perturbation_scale"):
        env.set_perturbation_scale(1.5)


def test_render_modes_are_ansi_not_ascii():
    env = make_env(render_mode="ansi")
    assert env.metadata["render_modes"] == ["ansi", "human"]
    assert RlfdEnv.metadata["render_modes"] == ["ansi", "human"]
    env.reset(seed=0)
    assert "peg_easy" in env.render()
    with pytest.raises(ValueError, match="render_mode"):
        make_env(render_mode="ascii")


def test_bad_action_is_a_clear_error():
    env = make_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be 6 finite numbers"):
        env.step(np.array([np.nan, 0, 0, 0, 0, 0]))
    with pytest.raises(ValueError, match="action must be 6 finite numbers"):
        env.step(np.zeros(3))


def test_solver_failure_truncates_with_reason():
    env = make_env()
    env.reset(seed=0)

    class FailingSimulator:
        """The real simulator, except that AdvanceTo fails as SAP can."""

        def __init__(self, simulator):
            self._simulator = simulator

        def __getattr__(self, name):
            return getattr(self._simulator, name)

        def AdvanceTo(self, _time):
            raise RuntimeError("SAP did not converge (forced by the test)")

    env.simulator = FailingSimulator(env.simulator)
    obs, reward, terminated, truncated, info = env.step(np.zeros(6, np.float32))
    assert truncated and not terminated and reward == 0.0
    assert info["failure_reason"].startswith("solver: SAP did not converge")
    assert obs.shape == (26,)


def test_episode_ends_by_time_limit():
    env = RlfdEnv("peg_easy", diagram_config=RlfdDiagramConfig(residual_activation_s=9.5))
    # Start far off so the DMP cannot have inserted by 10 s; push up with the residual.
    env.reset(seed=0, options={"fixture_dp": np.array([0.01, 0.0, 0.0])})
    done = False
    steps = 0
    while not done:
        _, _, terminated, truncated, info = env.step(np.array([0, 0, 1, 0, 0, 0], np.float32))
        steps += 1
        done = terminated or truncated
    assert truncated and not info["success"]
    assert steps == 5
    assert info["time_s"] == pytest.approx(10.0)


def test_the_step_is_the_tasks_residual_period_unless_the_config_sets_one():
    """A task's residual_period_s sets the env's step (the residual's rate); an explicit
    diagram config period wins; the last half-second is 10 steps at 20 Hz, 5 at 10 Hz."""
    fast_task = dataclasses.replace(load_task("peg_easy"), residual_period_s=0.05)
    late = RlfdDiagramConfig(residual_activation_s=9.5)
    for config, period in ((late, 0.05), (dataclasses.replace(late, residual_period_s=0.1), 0.1)):
        env = RlfdEnv(fast_task, diagram_config=config)
        assert env.time_step == period and env.diagram_config.residual_period_s == period
        env.reset(seed=0, options={"fixture_dp": np.array([0.01, 0.0, 0.0])})
        steps, done = 0, False
        while not done:
            _, _, terminated, truncated, info = env.step(np.zeros(6, np.float32))
            steps += 1
            done = terminated or truncated
        assert steps == round(0.5 / period)
        assert info["time_s"] == pytest.approx(10.0)


def test_pickles_and_runs_in_subproc_vec_env():
    from stable_baselines3.common.vec_env import SubprocVecEnv

    env = make_env()
    clone = pickle.loads(pickle.dumps(env))
    assert clone.task.name == "peg_easy"
    venv = SubprocVecEnv([make_env, make_env], start_method="spawn")
    try:
        venv.seed(0)
        obs = venv.reset()
        assert obs.shape == (2, 26)
        obs, rewards, dones, infos = venv.step(np.zeros((2, 6), np.float32))
        assert obs.shape == (2, 26) and len(infos) == 2
    finally:
        venv.close()


def test_success_needs_orientation_when_the_task_says_so(monkeypatch):
    env = RlfdEnv("rj45", diagram_config=FAST)
    assert env.task.kappa_deg is not None
    monkeypatch.setattr(env, "_part_error", lambda: (np.zeros(3), env.task.kappa_deg + 1.0))
    assert not env._inserted()
    monkeypatch.setattr(env, "_part_error", lambda: (np.zeros(3), 0.5 * env.task.kappa_deg))
    assert env._inserted()
    monkeypatch.setattr(env, "_part_error", lambda: (np.full(3, env.task.kappa_m), 0.0))
    assert not env._inserted()  # |(k, k, k)| > k


def test_sparse_reward_is_one_exactly_on_the_successful_step():
    env = make_env()
    env.reset(seed=0, options={"start_dp": np.zeros(3), "fixture_dp": np.zeros(3)})
    rewards = []
    done = False
    while not done:
        _, reward, terminated, truncated, info = env.step(np.zeros(6, np.float32))
        rewards.append(reward)
        done = terminated or truncated
    assert terminated and info["success"]
    assert rewards[-1] == 1.0 and set(rewards[:-1]) <= {0.0}


def test_pure_composition_acts_from_the_start_and_moves_the_setpoint():
    """The pure-RL baseline (Table III): no DMP phase in reset, the action is a velocity
    command, and the dense reward rises as the part approaches the goal."""
    env = RlfdEnv("peg_easy", composition="pure", reward="dense")
    _, info = env.reset(seed=0)
    assert info["time_s"] == 0.0
    X0 = env._port("X_WE_desired").copy()
    _, reward_still, *_ = env.step(np.zeros(6, np.float32))
    np.testing.assert_array_equal(env._port("X_WE_desired"), X0)  # no DMP motion
    _, _, _, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], np.float32))
    moved = env._port("X_WE_desired")[:3] - X0[:3]
    # One 0.1 s step at the full 5 cm/s along x.
    np.testing.assert_allclose(moved, [0.005, 0.0, 0.0], atol=1e-9)
    assert np.isfinite(reward_still) and reward_still < 0.0
    with pytest.raises(ValueError, match="composition"):
        RlfdEnv("peg_easy", composition="mixed")


def test_applied_residual_action_pads_the_3d_action_into_its_part():
    from rlfd_drake.env import AppliedResidualAction

    class Recorder(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)

        def step(self, action):
            self.last = action
            return np.zeros(1, np.float32), 0.0, False, False, {}

    for mode, part in (("translation", slice(0, 3)), ("orientation", slice(3, 6))):
        env = AppliedResidualAction(Recorder(), mode)
        assert env.action_space.shape == (3,)
        env.step(np.array([0.1, -0.2, 0.3], np.float32))
        np.testing.assert_allclose(env.unwrapped.last[part], [0.1, -0.2, 0.3], atol=1e-7)
        assert np.count_nonzero(env.unwrapped.last) == 3
    with pytest.raises(ValueError, match="residual mode must be one of"):
        AppliedResidualAction(Recorder(), "full")
    with pytest.raises(ValueError, match="action must be 3 numbers"):
        AppliedResidualAction(Recorder(), "translation").step(np.zeros(6, np.float32))
