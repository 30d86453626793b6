"""A learned residual on top of a hand-written rule (``rlfd train --base-correction``)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from rlfd_drake.base_correction import (
    BaseCorrectedAction,
    BaseCorrectedPolicy,
    RateTrackingRule,
    add_base_correction,
    make_base_correction,
)
from rlfd_drake.baselines.force_guided import ForceGuidedSearch
from rlfd_drake.control_math import integrate_residual, rate_toward_offset
from rlfd_drake.systems.observer import (
    OBSERVATION_RESIDUAL,
    OBSERVATION_SIZE,
    OBSERVATION_WRIST_FORCE,
    OBSERVATION_WRIST_TORQUE,
    ObserverConfig,
)
from rlfd_drake.train import TrainConfig

RANGE = ObserverConfig()


def _pressed_observation() -> np.ndarray:
    """The wrist pressed with 25 N, its centre of pressure 2 mm toward -x: the force
    search lifts fully and pushes +x."""
    obs = np.zeros(OBSERVATION_SIZE)
    force = np.array([0.0, 0.0, -25.0])
    obs[OBSERVATION_WRIST_FORCE] = force / RANGE.force_scale_N
    obs[OBSERVATION_WRIST_TORQUE] = np.cross([-0.002, 0.0, -0.05], force) / RANGE.torque_scale_Nm
    return obs


class _RecordingEnv(gym.Env):
    """Returns the pressed observation and records the actions it is given."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (6,), np.float32)

    def __init__(self):
        self.actions = []

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(OBSERVATION_SIZE), {}

    def step(self, action):
        self.actions.append(np.asarray(action, dtype=float))
        return _pressed_observation(), 0.0, False, False, {}


def test_the_applied_residual_is_the_sum_clipped_to_the_range():
    np.testing.assert_allclose(
        add_base_correction([1.0, 0.5, -0.2, 0, 0, 0], [0.5, -0.25, -0.9, 0, 0, 0.3]),
        [1.0, 0.25, -1.0, 0.0, 0.0, 0.3],
    )
    with pytest.raises(ValueError, match="base correction has 6 components and the learned"):
        add_base_correction(np.zeros(6), np.zeros(3))


def test_an_unknown_rule_is_refused_by_name():
    with pytest.raises(ValueError, match="base_correction must be one of .*'wiggle'"):
        make_base_correction("wiggle")
    with pytest.raises(ValueError, match="base_correction must be one of .*'wiggle'"):
        TrainConfig(base_correction="wiggle")
    with pytest.raises(ValueError, match="needs composition 'residual', got 'hybrid'"):
        TrainConfig(base_correction="force_search", composition="hybrid")


def test_the_search_with_the_slope_turns_by_the_tables_constant_tilt():
    """force_search_and_slope: the search's translation, the slope's constant turn."""
    from rlfd_drake.baselines.orientation_reference import slope_residual
    from rlfd_drake.tasks import load_task

    task = load_task("rj45")
    rule = make_base_correction("force_search_and_slope", task)
    pressed = _pressed_observation()
    slope = slope_residual(task)(pressed)
    assert np.linalg.norm(slope[3:6]) > 0.3  # 1 deg of the 3 deg range
    np.testing.assert_allclose(rule(pressed), np.r_[ForceGuidedSearch()(pressed)[0:3], slope[3:6]])
    np.testing.assert_allclose(rule(np.zeros(OBSERVATION_SIZE))[0:3], 0.0)  # free space
    with pytest.raises(ValueError, match="force_search_and_slope needs the task"):
        make_base_correction("force_search_and_slope")
    with pytest.raises(ValueError, match="force_search_and_slope needs the task"):
        BaseCorrectedAction(_RecordingEnv(), "force_search_and_slope")


def test_the_slope_rule_only_turns_by_the_tables_constant_tilt():
    """slope: no translation, the same turn on every observation, 1 deg of peg's 5."""
    from rlfd_drake.tasks import load_task

    rule = make_base_correction("slope", load_task("peg"))
    pressed, free = rule(_pressed_observation()), rule(np.zeros(OBSERVATION_SIZE))
    np.testing.assert_allclose(pressed, free)
    np.testing.assert_allclose(pressed[0:3], 0.0)
    assert np.degrees(np.linalg.norm(pressed[3:6]) * 0.087) == pytest.approx(1.0, rel=0.01)
    with pytest.raises(ValueError, match="slope needs the task"):
        make_base_correction("slope")


@pytest.mark.parametrize("rule", ["force_search", "force_search_and_slope", "slope"])
def test_an_offset_rule_is_refused_on_a_rate_residual(rule):
    """On peg_incremental the action is integrated: a constant turn would drift to the
    range's end. Each entry point names the rule, the task and the rate."""
    from rlfd_drake.evaluate import make_policy
    from rlfd_drake.tasks import load_task

    task = load_task("models/tasks/variants/peg_incremental.yaml")
    pattern = f"rule '{rule}' gives a residual offset.*peg_incremental.*residual_rate_per_s=2.0"
    with pytest.raises(ValueError, match=pattern):
        make_base_correction(rule, task)
    if rule != "force_search_and_slope":
        with pytest.raises(ValueError, match=pattern):
            make_policy(f"dmp|{rule}", "full", 0, task=task)


def test_rate_toward_offset_reaches_a_near_target_in_one_step_and_a_far_one_at_full_rate():
    held = np.zeros(6)
    target = np.array([0.1, -0.1, 0.0, 0.5, -1.0, 0.2])
    rate = rate_toward_offset(target, held, 0.2)
    np.testing.assert_allclose(rate, [0.5, -0.5, 0.0, 1.0, -1.0, 1.0])
    np.testing.assert_allclose(integrate_residual(held, rate, 0.2)[0:3], target[0:3])
    with pytest.raises(ValueError, match="step must be a positive number, got 0.0"):
        rate_toward_offset(target, held, 0.0)


@pytest.mark.parametrize("rule", ["force_search", "force_search_and_slope", "slope"])
def test_a_rule_taught_through_a_rate_brings_the_held_offset_to_the_rules_offset(rule):
    """On a rate task (rj45_phase_stop_incremental_nopush: 2 /s, 0.1 s steps) the tracked
    rule, closed around the integrator, holds the offset the rule names after
    ceil(1 / 0.2) = 5 steps at most, and stays there (a rate of zero)."""
    from rlfd_drake.tasks import load_task

    task = load_task("models/tasks/variants/rj45_phase_stop_incremental_nopush.yaml")
    tracked = make_base_correction(rule, task, through_rate=True)
    assert isinstance(tracked, RateTrackingRule) and tracked.step == pytest.approx(0.2)
    target = tracked.rule(_pressed_observation())
    obs = _pressed_observation()
    for _ in range(5):
        obs[OBSERVATION_RESIDUAL] = integrate_residual(obs[OBSERVATION_RESIDUAL], tracked(obs), 0.2)
    np.testing.assert_allclose(obs[OBSERVATION_RESIDUAL], target, atol=1e-12)
    np.testing.assert_allclose(tracked(obs), 0.0, atol=1e-9)
    with pytest.raises(ValueError, match="gives a residual offset"):
        make_base_correction(rule, task)  # not as a base under a learned rate


def test_training_env_applies_the_rule_on_the_observation_the_agent_saw():
    env = _RecordingEnv()
    wrapped = BaseCorrectedAction(env, "force_search")
    wrapped.reset(seed=0)
    learned = np.array([0.25, 0.5, -0.5, 0.0, 0.0, 0.0], dtype=np.float32)
    wrapped.step(learned)  # free space at reset: the rule adds nothing
    np.testing.assert_allclose(env.actions[-1], learned)
    wrapped.step(learned)  # pressed: the rule lifts 1 and pushes +x by 1
    rule = ForceGuidedSearch()(_pressed_observation())
    np.testing.assert_allclose(rule, [1.0, 0.0, 1.0, 0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(env.actions[-1], [1.0, 0.5, 0.5, 0.0, 0.0, 0.0], atol=1e-7)
    with pytest.raises(RuntimeError, match="before reset"):
        BaseCorrectedAction(_RecordingEnv(), "force_search").step(learned)


def test_a_run_trained_on_the_rule_is_evaluated_on_it(tmp_path):
    import rlfd_drake.evaluate as evaluate_module
    from rlfd_drake.evaluate import diagram_residual_mode, make_policy
    from rlfd_drake.train import make_envs, make_model

    config = TrainConfig(
        algo="sac",
        envs=1,
        history=1,
        residual_mode="translation",
        base_correction="force_search",
        sac_learning_starts=4,
    )
    venv = make_envs(config, 1, seed=0)
    model = make_model(config, venv, None)
    model.learn(total_timesteps=6)
    venv.close()
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    model.save(run / "policy.zip")
    model.save(run / "checkpoints" / "policy_6_steps.zip")
    (run / "config.json").write_text(json.dumps({"config": {"base_correction": "force_search"}}))
    observation = _pressed_observation()
    for path in (run / "policy.zip", run / "checkpoints" / "policy_6_steps.zip"):
        policy = make_policy(str(path), "translation")
        assert isinstance(policy, BaseCorrectedPolicy)
        policy.reset()
        learned = policy.learned(observation)
        policy.reset()
        np.testing.assert_allclose(
            policy(observation),
            np.clip(ForceGuidedSearch()(observation) + learned * [1, 1, 1, 0, 0, 0], -1.0, 1.0),
            atol=1e-7,
        )
        # The rule acts on the whole residual: the diagram applies all of it.
        assert diagram_residual_mode(str(path), "translation") == "full"
    # Without the configuration the policy alone is run, as before (in a new process:
    # a process reads a policy's file and configuration once).
    (run / "config.json").unlink()
    evaluate_module._MODEL_CACHE.clear()
    assert not isinstance(make_policy(str(run / "policy.zip"), "translation"), BaseCorrectedPolicy)
    assert diagram_residual_mode(str(run / "policy.zip"), "translation") == "translation"


def test_the_cli_offers_exactly_the_known_rules():
    from rlfd_drake.base_correction import BASE_CORRECTIONS
    from rlfd_drake.cli import build_parser

    train_parser = build_parser()._subparsers._group_actions[0].choices["train"]
    option = next(a for a in train_parser._actions if a.dest == "base_correction")
    assert sorted(option.choices) == sorted(BASE_CORRECTIONS)
    assert option.default is None


def test_the_learner_corrects_only_its_part_on_top_of_the_rule():
    """--residual-mode orientation on the force search: the rule steers, the learner
    turns; the learner's translation outputs are not applied, the env applies all."""
    from rlfd_drake.train import _env_kwargs

    env = _RecordingEnv()
    wrapped = BaseCorrectedAction(env, "force_search", learned_mode="orientation")
    wrapped.reset(seed=0)
    wrapped.step(np.array([0.25, 0.5, -0.5, 0.1, -0.2, 0.3], dtype=np.float32))
    np.testing.assert_allclose(env.actions[-1], [0, 0, 0, 0.1, -0.2, 0.3], atol=1e-7)
    wrapped.step(np.array([0.25, 0.5, -0.5, 0.1, -0.2, 0.3], dtype=np.float32))
    np.testing.assert_allclose(env.actions[-1], [1.0, 0.0, 1.0, 0.1, -0.2, 0.3], atol=1e-7)
    policy = BaseCorrectedPolicy(ForceGuidedSearch(), lambda obs: np.full(6, 0.5), "orientation")
    np.testing.assert_allclose(policy(_pressed_observation()), [1, 0, 1, 0.5, 0.5, 0.5])
    config = TrainConfig(residual_mode="orientation", base_correction="force_search")
    assert _env_kwargs(config)["residual_mode"] == "full"
    assert _env_kwargs(TrainConfig(residual_mode="orientation"))["residual_mode"] == "orientation"
    with pytest.raises(ValueError, match="residual mode must be one of .*'sideways'"):
        BaseCorrectedAction(_RecordingEnv(), "force_search", learned_mode="sideways")
    with pytest.raises(ValueError, match="residual mode must be one of .*'sideways'"):
        BaseCorrectedPolicy(ForceGuidedSearch(), policy, "sideways")
