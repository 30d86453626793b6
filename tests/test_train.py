"""Training smoke runs: real SB3 updates on the real env, tiny budgets."""

from __future__ import annotations

import json
import re
import tempfile
from dataclasses import replace

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.utils import set_random_seed
from stable_baselines3.common.vec_env import DummyVecEnv

from rlfd_drake.diagram import RlfdDiagramConfig
from rlfd_drake.env import SHAPING_AXES, RlfdEnv
from rlfd_drake.train import (
    EpisodeProgress,
    EveryNEpisodes,
    ExplorationNoiseSchedule,
    LinearDecayOverEpisodes,
    ResidualSAC,
    TrainConfig,
    load_model,
    make_model,
    resumed_model,
    train,
)

FAST = RlfdDiagramConfig(residual_activation_s=0.3)


def fast_venv():
    return DummyVecEnv([lambda: RlfdEnv("peg_easy", diagram_config=FAST)])


def _parameters(model):
    return [p.detach().clone() for p in model.policy.parameters()]


def _changed(before, model) -> bool:
    return any(
        not torch.equal(a, b) for a, b in zip(before, model.policy.parameters(), strict=True)
    )


def test_untrained_residual_is_zero():
    for algo in ("ppo", "sac"):
        model = make_model(TrainConfig(algo=algo, envs=1, history=1), fast_venv(), None)
        obs = np.random.default_rng(0).normal(size=(5, 26)).astype(np.float32)
        actions, _ = model.predict(obs, deterministic=True)
        np.testing.assert_array_equal(actions, 0.0)


def test_ppo_two_updates_change_the_policy():
    for epochs in (10, 3):
        config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, ppo_epochs=epochs)
        model = make_model(config, fast_venv(), None)
        before = _parameters(model)
        model.learn(total_timesteps=32)  # two rollouts of 16 steps -> two updates
        assert model._n_updates == 2 * epochs  # SB3 counts passes
        assert _changed(before, model)


def _hidden_widths(network) -> list[int]:
    return [layer.out_features for layer in network if isinstance(layer, torch.nn.Linear)]


def test_ppo_hidden_layers_shape_actor_and_critic(tmp_path):
    """The widths reach both networks, for PPO and recurrent PPO; the residual still
    starts at zero, and a saved policy loads back with its widths."""
    obs = np.random.default_rng(0).normal(size=(3, 26)).astype(np.float32)
    for algo, layers in (("ppo", (32, 16, 8)), ("recurrent_ppo", (24,))):
        config = TrainConfig(algo=algo, envs=1, ppo_n_steps=16, ppo_hidden_layers=list(layers))
        assert config.ppo_hidden_layers == layers  # a list is taken as the tuple it means
        model = make_model(config, fast_venv(), None)
        extractor = model.policy.mlp_extractor
        assert _hidden_widths(extractor.policy_net) == list(layers)
        assert _hidden_widths(extractor.value_net) == list(layers)
        actions, _ = model.predict(obs, deterministic=True)
        np.testing.assert_array_equal(actions, 0.0)
    model.save(tmp_path / "policy.zip")
    loaded = load_model(tmp_path / "policy.zip")
    assert _hidden_widths(loaded.policy.mlp_extractor.policy_net) == [24]
    for bad in ((), (64, 0), (64, 2.5), "64", 64, (True,)):
        with pytest.raises(ValueError, match="ppo_hidden_layers must be"):
            TrainConfig(algo="ppo", ppo_hidden_layers=bad)
    with pytest.raises(ValueError, match=r"ppo_hidden_layers=\(8,\) needs algo 'ppo'"):
        TrainConfig(algo="sac", ppo_hidden_layers=(8,))


def test_ppo_actor_layers_shape_the_actor_alone(tmp_path):
    """The actor's own widths leave the critic at ppo_hidden_layers'; no widths is a
    linear actor: its mean action is an affine function of the scaled observation,
    zero at the start, and it trains, saves and loads as a linear actor."""
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(3, 26)).astype(np.float32)
    for algo, actor in (("ppo", (16,)), ("recurrent_ppo", ())):
        config = TrainConfig(algo=algo, envs=1, ppo_n_steps=16, ppo_actor_layers=list(actor))
        assert config.ppo_actor_layers == actor
        model = make_model(config, fast_venv(), None)
        extractor = model.policy.mlp_extractor
        assert _hidden_widths(extractor.policy_net) == list(actor)
        assert _hidden_widths(extractor.value_net) == [64, 64]
        np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], 0.0)
    linear = make_model(
        TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, ppo_actor_layers=()), fast_venv(), None
    )
    before = _parameters(linear)
    linear.learn(total_timesteps=32)
    assert _changed(before, linear)
    linear.save(tmp_path / "linear.zip")
    loaded = load_model(tmp_path / "linear.zip")
    assert _hidden_widths(loaded.policy.mlp_extractor.policy_net) == []
    # affine in the observation (no hidden layer): f(a) + f(b) = f(a + b) + f(0)
    a, b = rng.normal(size=(2, 1, 26)).astype(np.float32) * 0.1
    zero = np.zeros_like(a)
    mean = [loaded.predict(x, deterministic=True)[0] for x in (a, b, a + b, zero)]
    np.testing.assert_allclose(mean[0] + mean[1], mean[2] + mean[3], atol=1e-5)
    assert np.abs(mean[0] - mean[3]).max() > 1e-4  # it did learn something
    for bad in ((64, 0), (2.5,), "64", 64, (False,)):
        with pytest.raises(ValueError, match="ppo_actor_layers must be"):
            TrainConfig(algo="ppo", ppo_actor_layers=bad)
    with pytest.raises(ValueError, match=r"ppo_actor_layers=\(\) needs algo 'ppo'"):
        TrainConfig(algo="sac", ppo_actor_layers=())


def _monte_carlo_gap(model) -> float:
    """Largest gap from R_t = r_t + gamma R_(t+1) (within an episode) in the last rollout:
    the recursion GAE's returns obey at lambda = 1 and not below it (they mix in V)."""
    buffer = model.rollout_buffer
    returns, rewards = buffer.returns[:, 0], buffer.rewards[:, 0]
    continues = 1.0 - buffer.episode_starts[1:, 0]
    expected = rewards[:-1] + model.gamma * continues * returns[1:]
    return float(np.max(np.abs(returns[:-1] - expected)))


def test_ppo_gae_lambda_reaches_the_advantages():
    gaps = {}
    for gae_lambda in (1.0, 0.5):
        config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, ppo_gae_lambda=gae_lambda)
        model = make_model(config, fast_venv(), None)
        assert model.gae_lambda == gae_lambda
        model.learn(total_timesteps=16)
        gaps[gae_lambda] = _monte_carlo_gap(model)
    assert gaps[1.0] < 1e-5
    assert gaps[0.5] > 1e-3  # the untrained critic's values are not zero


def test_exploration_noise_schedule_holds_the_log_std_through_updates():
    """The scheduled log std is what every rollout samples with, the optimiser leaves it
    alone, and it reaches the final value when the episodes run out."""
    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, log_std_init=-2.0)
    model = make_model(config, fast_venv(), None)
    progress = EpisodeProgress(done=5, total=20)
    schedule = ExplorationNoiseSchedule(-2.0, -3.0, progress)
    seen = []

    class Record(BaseCallback):
        def _on_rollout_start(self):
            seen.append(self.model.policy.log_std.detach().clone())

        def _on_step(self):
            return True

    before = _parameters(model)
    model.learn(total_timesteps=32, callback=CallbackList([schedule, Record()]))
    assert model._n_updates == 2 * model.n_epochs and _changed(before, model)
    assert not model.policy.log_std.requires_grad
    assert len(seen) == 2 and all(torch.allclose(v, torch.tensor(-2.25)) for v in seen)
    assert torch.allclose(model.policy.log_std, torch.tensor(-2.25))  # not moved by the updates
    progress.done = 30  # past the budget: held at the final value
    schedule.on_rollout_start()
    assert torch.allclose(model.policy.log_std, torch.tensor(-3.0))


def test_sac_updates_change_the_policy():
    config = TrainConfig(algo="sac", envs=1, history=1, sac_learning_starts=8)
    model = make_model(config, fast_venv(), None)
    before = _parameters(model)
    model.learn(total_timesteps=12)
    assert model._n_updates >= 2
    assert _changed(before, model)


def test_save_load_round_trip_gives_identical_actions(tmp_path):
    model = make_model(TrainConfig(algo="ppo", envs=1, ppo_n_steps=16), fast_venv(), None)
    model.learn(total_timesteps=16)
    model.save(tmp_path / "policy.zip")
    loaded = load_model(tmp_path / "policy.zip")
    obs = np.random.default_rng(1).normal(size=(8, 26)).astype(np.float32)
    np.testing.assert_array_equal(
        model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0]
    )
    with pytest.raises(ValueError, match="does not exist"):
        load_model(tmp_path / "missing.zip")


def test_train_writes_a_run_folder_and_refuses_to_overwrite(tmp_path):
    config = TrainConfig(
        algo="ppo",
        episodes=1,
        envs=1,
        ppo_n_steps=8,
        checkpoint_every_episodes=1,
        eval_every_episodes=1,
        eval_episodes=1,
    )
    run = tmp_path / "run"
    metrics = train(config, run, progress_bar=False)
    assert metrics["episodes"] == 1
    assert metrics["gradient_updates"] > 0  # an 8-step rollout fits in one episode
    assert metrics["date"].startswith("20")
    assert len(list((run / "checkpoints").glob("policy_*_steps.zip"))) == 1
    evaluations = np.load(run / "eval" / "evaluations.npz")
    assert evaluations["results"].shape == (1, 1)  # one evaluation of one episode
    for name in ("config.json", "episodes.csv", "policy.zip", "metrics.json"):
        assert (run / name).exists(), name
    assert json.loads((run / "config.json").read_text())["config"]["algo"] == "ppo"
    with pytest.raises(FileExistsError, match="already holds a run"):
        train(config, run, progress_bar=False)
    # Resuming compares the configuration as saved (JSON: tuple fields come back lists).
    resumed = train(config, run, resume=True, progress_bar=False)
    assert resumed["episodes"] == 1
    # Its metrics say that the wall time is the resumed part's, and rate the whole log.
    assert resumed["resumed_at_episode"] == 1
    assert resumed["resumed_from_checkpoint"].startswith("policy_")
    logged = (run / "episodes.csv").read_text().splitlines()[1:]
    assert resumed["success_rate_all"] == np.mean([int(line.split(",")[2]) for line in logged])
    with pytest.raises(ValueError, match="--resume with a different configuration"):
        train(replace(config, ppo_n_steps=16), run, resume=True, progress_bar=False)


def test_the_same_seed_trains_the_same_policy_on_one_machine(tmp_path):
    """Two runs of one configuration, two env processes each, log the same episodes and
    save the same networks. (Across machines they need not: another CPU's floating point
    moves a contact and the runs part after a few episodes.)"""
    config = TrainConfig(algo="ppo", episodes=4, envs=2, ppo_n_steps=16, seed=3)
    first, second = tmp_path / "first", tmp_path / "second"
    for run in (first, second):
        train(config, run, progress_bar=False)
    assert (first / "episodes.csv").read_text() == (second / "episodes.csv").read_text()
    weights = [load_model(run / "policy.zip").policy.state_dict() for run in (first, second)]
    assert weights[0].keys() == weights[1].keys()
    assert all(torch.equal(weights[0][key], weights[1][key]) for key in weights[0])
    assert json.loads((first / "metrics.json").read_text())["gradient_updates"] > 0


class _CountCalls(BaseCallback):
    def _on_step(self) -> bool:
        return True


def _triggers(n_episodes, dones_per_step, episodes_done=0):
    """Steps at which EveryNEpisodes fires, for the given per-step ``dones``."""
    child = _CountCalls()
    trigger = EveryNEpisodes(n_episodes, child, episodes_done)
    trigger.init_callback(make_model(TrainConfig(algo="ppo", envs=1), fast_venv(), None))
    fired = []
    for step, dones in enumerate(dones_per_step):
        calls = child.n_calls
        trigger.update_locals({"dones": np.array(dones, dtype=bool)})
        assert trigger.on_step()
        if child.n_calls > calls:
            fired.append(step)
    return fired


def test_checkpoints_and_evaluations_fire_on_finished_episodes_not_steps():
    # Two envs; finished episodes after each step: 1, 2, 4, 4, 5, 7, 7, 9.
    dones = [[1, 0], [0, 1], [1, 1], [0, 0], [1, 0], [1, 1], [0, 0], [1, 1]]
    assert _triggers(3, dones) == [2, 5, 7]  # on reaching 3, 6 and 9 episodes
    assert _triggers(1, dones) == [0, 1, 2, 4, 5, 7]
    # A resumed run with 5 episodes done counts on from 5: 6, 7, 9, 9, 10, 12, 12, 14.
    assert _triggers(3, dones, episodes_done=5) == [0, 2, 5]
    with pytest.raises(ValueError, match="n_episodes"):
        EveryNEpisodes(0, _CountCalls())


def test_exported_policy_acts_the_same_and_is_smaller(tmp_path):
    from rlfd_drake.policies import export_policy

    config = TrainConfig(algo="sac", envs=1, history=1, sac_learning_starts=4)
    model = make_model(config, fast_venv(), None)
    model.learn(total_timesteps=8)  # the optimizers now hold moment estimates
    model.save(tmp_path / "policy.zip")
    exported = export_policy(tmp_path / "policy.zip", tmp_path / "deploy.zip")
    assert exported.stat().st_size < 0.8 * (tmp_path / "policy.zip").stat().st_size
    obs = np.random.default_rng(2).normal(size=(8, 26)).astype(np.float32)
    np.testing.assert_array_equal(
        model.predict(obs, deterministic=True)[0],
        load_model(exported).predict(obs, deterministic=True)[0],
    )
    with pytest.raises(FileExistsError, match="deploy.zip exists"):
        export_policy(tmp_path / "policy.zip", exported)


def test_export_carries_the_training_configuration(tmp_path):
    from rlfd_drake.policies import export_policy, trained_residual_mode

    run = tmp_path / "run"
    run.mkdir()
    model = make_model(TrainConfig(algo="sac", envs=1, history=1), fast_venv(), None)
    model.save(run / "policy.zip")
    config = {"config": {"residual_mode": "translation"}, "command": "rlfd train ..."}
    (run / "config.json").write_text(json.dumps(config))
    assert trained_residual_mode(run / "policy.zip") == "translation"
    exported = export_policy(run / "policy.zip", tmp_path / "shipped.zip")
    assert json.loads((tmp_path / "shipped.json").read_text()) == config
    assert trained_residual_mode(exported) == "translation"
    # A config.json beside another policy file is not that policy's.
    (run / "other.zip").write_bytes(b"")
    assert trained_residual_mode(run / "other.zip") is None


def test_sac_target_entropy_reaches_the_model():
    default = make_model(TrainConfig(algo="sac", envs=1, history=1), fast_venv(), None)
    assert default.target_entropy == -6.0  # SB3's -dim(A)
    wide = make_model(
        TrainConfig(algo="sac", envs=1, history=1, sac_target_entropy=1.0), fast_venv(), None
    )
    assert wide.target_entropy == 1.0
    gentle = make_model(
        TrainConfig(algo="sac", envs=1, history=1, sac_initial_ent_coef=1e-4), fast_venv(), None
    )
    assert float(gentle.log_ent_coef.detach().exp()) == pytest.approx(1e-4)


def test_sac_gradient_steps_set_the_updates_per_step():
    config = TrainConfig(algo="sac", envs=1, history=1, sac_learning_starts=4, sac_gradient_steps=3)
    model = make_model(config, fast_venv(), None)
    assert model.gradient_steps == 3
    model.learn(total_timesteps=6)
    assert model._n_updates == 3 * 2  # steps 5 and 6, three updates each


def test_sac_critic_burn_in_holds_the_actor_while_the_critic_learns(tmp_path):
    """In the burn-in only the critic's parameters move; after it the actor's do too."""
    config = TrainConfig(algo="sac", envs=1, history=1, sac_learning_starts=4, sac_critic_burn_in=6)
    model = make_model(config, fast_venv(), None)
    assert model.critic_burn_in == 6

    def snapshot(module):
        return [p.detach().clone() for p in module.parameters()]

    def moved(before, module) -> bool:
        return any(not torch.equal(a, b) for a, b in zip(before, module.parameters(), strict=True))

    actor, critic, alpha = snapshot(model.actor), snapshot(model.critic), model.log_ent_coef.item()
    model.learn(total_timesteps=10)  # updates after steps 5-10: 6, all in the burn-in
    assert model._n_updates == 6
    assert not moved(actor, model.actor) and model.log_ent_coef.item() == alpha
    assert moved(critic, model.critic)
    model.learn(total_timesteps=2, reset_num_timesteps=False)  # past it
    assert moved(actor, model.actor) and model.log_ent_coef.item() != alpha
    model.save(tmp_path / "checkpoint.zip")
    resumed = resumed_model(config, tmp_path / "checkpoint.zip", fast_venv())
    assert type(resumed) is ResidualSAC and resumed.critic_burn_in == 6
    assert resumed._n_updates == model._n_updates  # the burn-in counts on
    for bad in (-1, 2.5):
        with pytest.raises(ValueError, match="sac_critic_burn_in must be an integer >= 0"):
            TrainConfig(algo="sac", sac_critic_burn_in=bad)
    with pytest.raises(ValueError, match="sac_critic_burn_in=10 needs algo 'sac', got 'ppo'"):
        TrainConfig(algo="ppo", sac_critic_burn_in=10)


def test_a_task_variant_trains_from_its_yaml():
    """A task YAML path (a variant of a shipped task) reaches the envs as that task."""
    from rlfd_drake.train import _env_kwargs

    config = TrainConfig(task="models/tasks/variants/gear_rot2deg.yaml")
    env = RlfdEnv(**_env_kwargs(config))
    assert env.task.name == "gear_rot2deg"
    assert env.task.residual_max_rotation_rad == pytest.approx(0.035)


def test_bad_config_names_the_field():
    with pytest.raises(ValueError, match="sac_target_entropy"):
        TrainConfig(sac_target_entropy=float("nan"))
    with pytest.raises(ValueError, match="algo must be one of"):
        TrainConfig(algo="dqn")
    with pytest.raises(ValueError, match="episodes must be >= 1"):
        TrainConfig(episodes=0)
    with pytest.raises(ValueError, match="task must be one of"):
        TrainConfig(task="peg_huge")
    with pytest.raises(ValueError, match="no_such_task.yaml"):
        TrainConfig(task="models/tasks/variants/no_such_task.yaml")
    with pytest.raises(ValueError, match="force_limit_n must be a positive number, got 0"):
        TrainConfig(force_limit_n=0.0)
    with pytest.raises(ValueError, match="sac_gradient_steps must be >= 1, got 0"):
        TrainConfig(sac_gradient_steps=0)
    with pytest.raises(ValueError, match="sac_initial_ent_coef must be a positive number"):
        TrainConfig(sac_initial_ent_coef=0.0)
    with pytest.raises(ValueError, match="force_limit_penalty must be a number >= 0, got -1"):
        TrainConfig(force_limit_penalty=-1.0)
    with pytest.raises(ValueError, match="force_limit_penalty must be a number >= 0, got nan"):
        RlfdEnv("peg_easy", force_limit_penalty=float("nan"))


@pytest.mark.parametrize("penalty", [0.0, 0.5])
def test_training_force_limit_ends_episodes_that_push_harder(penalty):
    """A training-only force limit reaches the envs and ends an episode as a failure
    once the low-passed contact force exceeds it (the DMP alone from the demo start,
    with the hole 2 mm off, lands on the chamfer with more than 1 N); that step's
    reward is minus the penalty."""
    from rlfd_drake.train import _env_kwargs

    config = TrainConfig(task="peg_easy", force_limit_n=1.0, force_limit_penalty=penalty)
    kwargs = _env_kwargs(config)
    assert kwargs["task"].name == "peg_easy" and kwargs["task"].force_limit_n == 1.0
    assert _env_kwargs(TrainConfig(task="peg_easy"))["task"] == "peg_easy"
    env = RlfdEnv(**kwargs)
    zero = {"start_dp": np.zeros(3), "start_dq": np.array([1.0, 0.0, 0.0, 0.0])}
    env.reset(seed=0, options={**zero, "fixture_dp": np.array([0.002, 0.0, 0.0])})
    for _ in range(50):
        _, reward, terminated, truncated, info = env.step(np.zeros(6, np.float32))
        if terminated or truncated:
            break
    assert terminated and info["force_limit_broken"] and not info["success"]
    assert reward == -penalty


@pytest.mark.parametrize("signal, index", [("low_passed", 3), ("one_step", 0)])
def test_peak_force_cost_charges_the_peak_force_the_residual_steps_add(signal, index):
    """--peak-force-cost C --peak-force-threshold-n F: the rewards of an episode sum to
    the paper's minus C (e_end - e_activation), e = max(0, peak force / F - 1), the
    force being the low-passed one or the 2 ms one (--peak-force-signal); the episode
    goes on past the threshold."""
    from rlfd_drake.train import _env_kwargs

    options = {
        "start_dp": np.zeros(3),
        "start_dq": np.array([1.0, 0.0, 0.0, 0.0]),
        "fixture_dp": np.array([0.002, 0.0, 0.0]),
    }

    def episode(**cost) -> tuple[list[float], float, float]:
        env = RlfdEnv(**_env_kwargs(TrainConfig(task="peg_easy", **cost)))
        env.reset(seed=0, options=options)
        at_activation = float(env._port("force_metrics")[index])
        rewards = []
        for _ in range(10):  # the peg slides in at about step 15
            _, reward, terminated, truncated, _ = env.step(np.zeros(6, np.float32))
            rewards.append(reward)
            if terminated or truncated:
                break
        return rewards, at_activation, float(env._port("force_metrics")[index])

    paper, _, _ = episode()
    charged, start, end = episode(
        peak_force_cost=0.5, peak_force_threshold_n=1.0, peak_force_signal=signal
    )
    assert len(charged) == len(paper) == 10  # no termination at the threshold
    assert end > start  # the chamfer contact raises the peak after the activation
    expected = 0.5 * (max(0.0, end - 1.0) - max(0.0, start - 1.0))
    assert sum(paper) - sum(charged) == pytest.approx(expected, rel=1e-9)
    assert all(c <= p for c, p in zip(charged, paper, strict=True))


def test_peak_force_cost_is_validated():
    for cost, threshold, message in (
        (-1.0, 50.0, "peak_force_cost must be a number >= 0, got -1.0"),
        (0.5, None, "peak_force_cost 0.5 needs peak_force_threshold_n"),
        (0.0, 50.0, "peak_force_threshold_n 50.0 needs peak_force_cost > 0"),
        (0.5, 0.0, "peak_force_threshold_n must be a number > 0, got 0.0"),
        (0.5, float("inf"), "peak_force_threshold_n must be a number > 0, got inf"),
    ):
        with pytest.raises(ValueError, match=re.escape(message)):
            TrainConfig(peak_force_cost=cost, peak_force_threshold_n=threshold)
    with pytest.raises(ValueError, match="peak_force_cost must be a number >= 0, got nan"):
        RlfdEnv("peg_easy", peak_force_cost=float("nan"))
    message = "peak_force_signal must be one of ('low_passed', 'one_step'), got 'raw'"
    with pytest.raises(ValueError, match=re.escape(message)):
        TrainConfig(peak_force_cost=0.5, peak_force_threshold_n=50.0, peak_force_signal="raw")
    with pytest.raises(ValueError, match=re.escape(message)):
        RlfdEnv("peg_easy", peak_force_signal="raw")


def test_action_cost_charges_each_step_its_mean_square_action():
    """--action-cost C: a step's reward is the paper's minus C times the mean square of
    the clipped action (an action of 2 costs as 1); the simulation is the same."""
    from rlfd_drake.train import _env_kwargs

    options = {"start_dp": np.zeros(3), "start_dq": np.array([1.0, 0.0, 0.0, 0.0])}
    action = np.array([0.5, -2.0, 0.0, 0.0, 0.0, 0.0], np.float32)

    def first_steps(**cost) -> tuple[list[float], np.ndarray]:
        env = RlfdEnv(**_env_kwargs(TrainConfig(task="peg_easy", **cost)))
        env.reset(seed=0, options=options)
        steps = [env.step(action) for _ in range(3)]
        return [step[1] for step in steps], steps[-1][0]

    paper, paper_observation = first_steps()
    charged, charged_observation = first_steps(action_cost=0.3)
    np.testing.assert_array_equal(charged_observation, paper_observation)
    mean_square = (0.5**2 + 1.0**2) / 6
    for p, c in zip(paper, charged, strict=True):
        assert p - c == pytest.approx(0.3 * mean_square, rel=1e-9)
    for bad in (-0.1, float("nan")):
        with pytest.raises(
            ValueError, match=re.escape(f"action_cost must be a number >= 0, got {bad}")
        ):
            TrainConfig(action_cost=bad)


def test_distance_shaping_pays_the_discounted_change_of_the_distance_potential():
    """--distance-shaping C: a step's reward is the paper's plus gamma * phi(s') - phi(s),
    phi = -C * L1(part position error) / 1 cm, from the true goal; the simulation is the
    same. Summed over an episode it telescopes (gamma = 1): the reward for a path is
    C per cm of L1 distance it closed, whatever the path."""
    from rlfd_drake.train import DISCOUNT, _env_kwargs

    options = {"start_dp": np.zeros(3), "start_dq": np.array([1.0, 0.0, 0.0, 0.0])}
    options["fixture_dp"] = np.array([0.002, -0.001, 0.0])
    action = np.array([0.3, -0.2, 0.5, 0.0, 0.0, 0.0], np.float32)

    def l1_cm(env: RlfdEnv) -> float:
        error, _ = env._part_error()
        return float(np.sum(np.abs(error))) / 0.01

    def steps(**shaping) -> tuple[list[float], list[float], np.ndarray]:
        env = RlfdEnv(**{**_env_kwargs(TrainConfig(task="peg_easy")), **shaping})
        env.reset(seed=0, options=options)
        distances, rewards = [l1_cm(env)], []
        for _ in range(4):
            observation, reward, *_ = env.step(action)
            rewards.append(reward)
            distances.append(l1_cm(env))
        return rewards, distances, observation

    paper, distances, paper_observation = steps()
    shaped, _, shaped_observation = steps(distance_shaping=2.0, discount=DISCOUNT)
    np.testing.assert_array_equal(shaped_observation, paper_observation)
    assert distances[-1] < distances[0] - 0.5  # the DMP closes the distance
    for k, (p, s) in enumerate(zip(paper, shaped, strict=True)):
        expected = -2.0 * DISCOUNT * distances[k + 1] + 2.0 * distances[k]
        assert s - p == pytest.approx(expected, rel=1e-9)
    undiscounted, _, _ = steps(distance_shaping=2.0, discount=1.0)
    closed = sum(u - p for u, p in zip(undiscounted, paper, strict=True))
    assert closed == pytest.approx(2.0 * (distances[0] - distances[-1]), rel=1e-9)
    # "lateral": only the errors across the insertion axis (the true goal frame's x, y).
    lateral_config = TrainConfig(
        task="peg_easy", distance_shaping=2.0, distance_shaping_axes="lateral"
    )
    lateral_env = RlfdEnv(**{**_env_kwargs(lateral_config), "discount": 1.0})
    lateral_env.reset(seed=0, options=options)
    R_GoalW = lateral_env._true_goal().rotation().inverse().matrix()
    error, _ = lateral_env._part_error()
    lateral_cm = float(np.sum(np.abs((R_GoalW @ error)[:2]))) / 0.01
    assert lateral_env._potential == pytest.approx(-2.0 * lateral_cm, rel=1e-12)
    assert 0.0 < lateral_cm < 0.5 * distances[0]  # the height is most of the distance
    # "lateral_depth": and the axial error capped at the fixture's depth (the part is
    # still above the hole here: the whole depth counts, not the height above it).
    depth_config = replace(lateral_config, distance_shaping_axes="lateral_depth")
    depth_env = RlfdEnv(**{**_env_kwargs(depth_config), "discount": 1.0})
    depth_env.reset(seed=0, options=options)
    depth_cm = depth_env.task.fixture.depth_m / 0.01
    assert abs((R_GoalW @ error)[2]) / 0.01 > depth_cm
    assert depth_env._potential == pytest.approx(-2.0 * (lateral_cm + depth_cm), rel=1e-12)
    from rlfd_drake.cli import build_parser

    train_parser = build_parser()._subparsers._group_actions[0].choices["train"]
    axes = next(a for a in train_parser._actions if a.dest == "distance_shaping_axes")
    assert tuple(axes.choices) == SHAPING_AXES
    with pytest.raises(ValueError, match="distance_shaping_axes 'lateral' needs distance_sha"):
        TrainConfig(distance_shaping_axes="lateral")
    with pytest.raises(ValueError, match="distance_shaping_axes must be one of"):
        RlfdEnv("peg_easy", distance_shaping=1.0, distance_shaping_axes="z")
    for field, bad, message in (
        ("distance_shaping", -1.0, "distance_shaping must be a number >= 0, got -1.0"),
        ("distance_shaping", float("nan"), "distance_shaping must be a number >= 0, got nan"),
        ("discount", 0.0, "discount must be a number in (0, 1], got 0.0"),
        ("discount", 1.5, "discount must be a number in (0, 1], got 1.5"),
    ):
        with pytest.raises(ValueError, match=re.escape(message)):
            RlfdEnv("peg_easy", **{field: bad})
    with pytest.raises(ValueError, match="distance_shaping must be a number >= 0, got -0.5"):
        TrainConfig(distance_shaping=-0.5)


def test_deployed_policy_matches_the_frame_stacked_training_view():
    from stable_baselines3.common.vec_env import VecFrameStack

    config = TrainConfig(algo="sac", envs=1, history=3, sac_learning_starts=4)
    venv = VecFrameStack(fast_venv(), n_stack=3)
    model = make_model(config, venv, None)
    model.learn(total_timesteps=8)  # non-zero actions after updates
    deployed = _assert_deployed_acts_as_on_the_stack(model, venv, history=3)
    deployed.reset()
    np.testing.assert_array_equal(deployed._stack, 0.0)


def _assert_deployed_acts_as_on_the_stack(model, venv, history: int):
    """The model deployed (one observation per call) gives, step by step, the action
    it gives on ``venv``'s frame-stacked view; returns the deployed policy."""
    from rlfd_drake.policies import DeployedPolicy

    deployed = DeployedPolicy(model)
    assert deployed.history == history
    venv.seed(5)
    stacked = venv.reset()
    rng = np.random.default_rng(0)
    for _ in range(4):
        expected, _ = model.predict(stacked, deterministic=True)
        np.testing.assert_allclose(deployed(stacked[0, -26:]), expected[0], rtol=0, atol=1e-7)
        stacked, _, _, _ = venv.step(rng.uniform(-1, 1, (1, 6)).astype(np.float32))
    return deployed


def test_init_from_starts_from_the_source_networks(tmp_path):
    from rlfd_drake.train import copy_policy_parameters

    source = make_model(TrainConfig(algo="sac", envs=1, history=1), fast_venv(), None)
    with torch.no_grad():
        for p in source.policy.parameters():
            p.add_(torch.randn_like(p))
        source.log_ent_coef.fill_(-1.0)
    path = tmp_path / "source.zip"
    source.save(path)
    config = TrainConfig(algo="sac", envs=1, history=1, init_from=str(path))
    target = make_model(config, fast_venv(), None)
    copy_policy_parameters(load_model(config.init_from), target)
    for a, b in zip(source.policy.parameters(), target.policy.parameters(), strict=True):
        assert torch.equal(a, b)
    assert float(target.log_ent_coef.detach()) == -1.0
    obs = np.random.default_rng(1).normal(size=(4, 26)).astype(np.float32)
    np.testing.assert_array_equal(
        source.predict(obs, deterministic=True)[0], target.predict(obs, deterministic=True)[0]
    )
    ppo = make_model(TrainConfig(algo="ppo", envs=1), fast_venv(), None)
    with pytest.raises(ValueError, match="SAC policy, this run trains PPO"):
        copy_policy_parameters(source, ppo)
    deeper = make_model(
        TrainConfig(algo="ppo", envs=1, ppo_actor_layers=(64, 64, 64)), fast_venv(), None
    )
    for first, second in ((deeper, ppo), (ppo, deeper)):  # a layer more, a layer fewer
        with pytest.raises(ValueError, match="init_from's networks do not match this run's"):
            copy_policy_parameters(first, second)
    with pytest.raises(ValueError, match="init_from"):
        TrainConfig(init_from=str(tmp_path / "missing.zip"))
    with pytest.raises(ValueError, match="composition"):
        TrainConfig(composition="mixed")


def test_a_run_that_ends_before_its_first_update_says_so(tmp_path):
    """A fine-tune's 60 RJ-45 episodes can end before SAC's learning starts: the saved
    policy is then the copied one, and the run says so instead of passing it off."""
    config = TrainConfig(algo="sac", episodes=1, envs=1, sac_learning_starts=10_000)
    with pytest.warns(UserWarning, match="no gradient update"):
        metrics = train(config, tmp_path / "run", progress_bar=False)
    assert metrics["gradient_updates"] == 0


def test_sac_warm_up_explores_with_its_policy_not_uniform_samples():
    """During learning_starts the residual is the zero-mean policy's jiggle (the DMP),
    not SB3's uniform full-range actions."""
    config = TrainConfig(algo="sac", envs=1, history=1, sac_learning_starts=1000, log_std_init=-3)
    model = make_model(config, fast_venv(), None)
    model._last_obs = np.zeros((1, 26), np.float32)
    actions = np.array([model._sample_action(1000)[0] for _ in range(200)])
    assert np.max(np.abs(actions)) < 0.3  # std 0.05; uniform would reach ~1
    assert np.std(actions) > 0.01


def test_applied_action_only_trains_a_3d_policy_that_deploys_padded(tmp_path):
    from rlfd_drake.policies import DeployedPolicy
    from rlfd_drake.train import make_envs

    config = TrainConfig(
        algo="sac",
        envs=1,
        history=1,
        residual_mode="translation",
        applied_action_only=True,
        sac_learning_starts=4,
    )
    venv = make_envs(config, 1, seed=0)
    assert venv.action_space.shape == (3,)
    model = make_model(config, venv, None)
    before = _parameters(model)
    model.learn(total_timesteps=8)
    assert _changed(before, model)
    model.save(tmp_path / "policy.zip")
    loaded = load_model(tmp_path / "policy.zip")
    deployed = DeployedPolicy(loaded, residual_mode="translation")
    observation = venv.reset()
    expected, _ = loaded.predict(observation, deterministic=True)
    action = deployed(observation[0])
    assert action.shape == (6,)
    np.testing.assert_allclose(action[:3], expected[0], rtol=0, atol=1e-7)
    np.testing.assert_array_equal(action[3:], 0.0)
    venv.close()


def test_applied_action_only_needs_a_partial_residual_mode():
    with pytest.raises(ValueError, match="applied_action_only needs residual_mode"):
        TrainConfig(residual_mode="full", applied_action_only=True)


def test_correlated_noise_has_its_stationary_std_and_correlation_time():
    from rlfd_drake.train import exploration_noise

    assert exploration_noise(0.0, 2.0, 6, 0.1) is None
    noise = exploration_noise(0.4, 2.0, 3, 0.1)
    set_random_seed(0)  # SB3's noise draws from numpy's global generator, seeded by SB3
    samples = np.array([noise() for _ in range(40_000)])
    assert np.std(samples[2000:]) == pytest.approx(0.4, rel=0.1)
    lag1 = np.corrcoef(samples[2000:-1, 0], samples[2001:, 0])[0, 1]
    assert lag1 == pytest.approx(np.exp(-0.1 / 2.0), abs=0.01)
    noise.reset()  # each episode starts from a zero offset
    np.testing.assert_array_equal(noise.noise_prev, 0.0)


def test_sac_explores_with_the_correlated_noise_from_its_warm_up():
    """The explored actions are the policy's (tiny) jiggle plus a slowly drifting offset;
    without the option they are the jiggle alone."""
    kwargs = dict(algo="sac", envs=1, history=1, sac_learning_starts=1000, log_std_init=-5)

    def explored(config):
        model = make_model(config, fast_venv(), None)
        model._last_obs = np.zeros((1, 26), np.float32)
        set_random_seed(0)
        return np.array([model._sample_action(1000, model.action_noise)[0][0] for _ in range(400)])

    plain = explored(TrainConfig(**kwargs))
    drifting = explored(TrainConfig(**kwargs, sac_correlated_noise=0.4))  # all components
    lateral = explored(TrainConfig(**kwargs, sac_correlated_noise=(0.4, 0.4, 0, 0, 0, 0)))
    assert np.max(np.abs(plain)) < 0.05
    assert np.all(np.std(drifting, axis=0) > 0.1)
    assert np.corrcoef(drifting[:-1, 0], drifting[1:, 0])[0, 1] > 0.8
    assert np.all(np.std(lateral[:, :2], axis=0) > 0.1)
    assert np.max(np.abs(lateral[:, 2:])) < 0.05  # the other components: the jiggle only
    with pytest.raises(ValueError, match="sac_correlated_noise must have 1 or 6"):
        make_model(TrainConfig(**kwargs, sac_correlated_noise=(0.4, 0.4)), fast_venv(), None)


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"algo": "sac", "sac_correlated_noise": (0.4, -0.1)}, "sac_correlated_noise must be one"),
        ({"algo": "sac", "sac_correlated_noise": (float("nan"),)}, "sac_correlated_noise must"),
        ({"algo": "sac", "sac_correlated_noise": ()}, "sac_correlated_noise must be one or more"),
        ({"algo": "ppo", "sac_correlated_noise": (0.3,)}, r"sac_correlated_noise=\(0.3,\) needs"),
        ({"algo": "sac", "sac_correlated_noise_time_s": 0.0}, "sac_correlated_noise_time_s must"),
    ],
)
def test_correlated_noise_is_validated(fields, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**fields)


@pytest.mark.parametrize("timeout_terminal", [False, True])
def test_timeout_terminal_makes_the_learner_treat_the_time_limit_as_terminal(timeout_terminal):
    from stable_baselines3 import SAC

    from rlfd_drake.env import TimeLimitAsTerminal
    from rlfd_drake.tasks import load_task
    from rlfd_drake.train import wrap_training_env

    # The residual acts from 0.3 s (FAST): 4 residual steps of 0.1 s.
    short = replace(load_task("peg_easy"), episode_time_s=0.7)

    def make():
        env = RlfdEnv(short, diagram_config=FAST)
        return wrap_training_env(env, "full", False, None, timeout_terminal)

    env = make()
    assert isinstance(env, TimeLimitAsTerminal) == timeout_terminal
    env.reset(seed=0)
    ends = [env.step(np.zeros(6, dtype=np.float32))[2:4] for _ in range(4)]
    assert ends[:3] == [(False, False)] * 3
    assert ends[3] == ((True, False) if timeout_terminal else (False, True))
    model = SAC("MlpPolicy", DummyVecEnv([make]), learning_starts=100, seed=0)
    model.set_logger(Logger(folder=None, output_formats=[]))  # no tmp/SB3-<time> folder
    model.learn(total_timesteps=4)
    buffer = model.replay_buffer
    # SB3 bootstraps a step whose timeout flag is set; a terminal one scores 0 after.
    assert buffer.dones[3, 0] == 1.0
    assert buffer.timeouts[3, 0] == (0.0 if timeout_terminal else 1.0)
    assert not buffer.dones[:3].any()
    assert TrainConfig(timeout_terminal=True).timeout_terminal


def test_ppo_state_dependent_exploration_holds_its_noise_until_redrawn():
    """With ppo_sde_sample_steps the untrained residual is still zero, the noise is a
    fixed function of the observation until SB3 redraws it (every N steps), and two
    PPO updates train it; without it, one observation gets a new sample every time."""
    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, ppo_sde_sample_steps=4)
    model = make_model(config, fast_venv(), None)
    assert model.use_sde and model.sde_sample_freq == 4
    obs = np.random.default_rng(0).normal(size=(1, 26)).astype(np.float32)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], 0.0)
    first, second = (model.predict(obs, deterministic=False)[0] for _ in range(2))
    np.testing.assert_array_equal(first, second)
    assert np.all(np.abs(first) > 0.0)
    model.policy.reset_noise()
    assert not np.allclose(model.predict(obs, deterministic=False)[0], first)
    before = _parameters(model)
    model.learn(total_timesteps=32)
    assert model._n_updates == 2 * model.n_epochs and _changed(before, model)
    independent = make_model(TrainConfig(algo="ppo", envs=1), fast_venv(), None)
    assert not independent.use_sde
    samples = [independent.predict(obs, deterministic=False)[0] for _ in range(2)]
    assert not np.allclose(*samples)


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"ppo_sde_sample_steps": -1}, "ppo_sde_sample_steps must be an integer >= 0, got -1"),
        ({"ppo_sde_sample_steps": 2.5}, "ppo_sde_sample_steps must be an integer >= 0, got 2.5"),
        (
            {"ppo_sde_sample_steps": 8, "algo": "sac"},
            "ppo_sde_sample_steps=8 needs algo 'ppo', got 'sac'",
        ),
    ],
)
def test_ppo_sde_sample_steps_is_validated(fields, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        TrainConfig(**fields)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_init_from_refuses_a_source_that_reads_the_observation_differently(algo):
    """The fixed input scales are part of a network's state: a fine-tune from a policy
    with other scales would silently run with the source's, not its own flags'. It is
    refused with both readings named; equal scales copy, networks and scales alike."""
    from rlfd_drake.train import copy_policy_parameters

    def model(**fields):
        return make_model(TrainConfig(algo=algo, envs=1, history=1, **fields), fast_venv(), None)

    rj45_reading = model(scaled_observation=True, contact_torque_nm=0.05)
    peg_reading = model(scaled_observation=True)
    with pytest.raises(
        ValueError,
        match=re.escape(
            "init_from reads its observation scaled, wrist torque 0.05 N m per unit, this run "
            "scaled, wrist torque 1 N m per unit"
        ),
    ):
        copy_policy_parameters(rj45_reading, peg_reading)
    with pytest.raises(ValueError, match="reads its observation unscaled, this run scaled"):
        copy_policy_parameters(model(), peg_reading)
    with pytest.raises(ValueError, match="this run unscaled"):
        copy_policy_parameters(peg_reading, model())
    same = model(scaled_observation=True, contact_torque_nm=0.05)
    copy_policy_parameters(rj45_reading, same)
    for (name, a), b in zip(
        rj45_reading.policy.state_dict().items(), same.policy.state_dict().values(), strict=True
    ):
        assert torch.equal(a, b), name


def test_linear_learning_rate_falls_to_zero_over_the_run_episodes():
    progress = EpisodeProgress(done=0, total=4)
    schedule = LinearDecayOverEpisodes(1e-3, progress)
    assert schedule(0.9) == pytest.approx(1e-3)  # SB3's own progress is ignored
    progress.done = 3
    assert schedule(0.9) == pytest.approx(2.5e-4)
    progress.done = 5  # the last rollout may run past the budget
    assert schedule(0.9) == 0.0
    with pytest.raises(ValueError, match="learning_rate_schedule must be one of"):
        TrainConfig(learning_rate_schedule="cosine")


def test_a_linear_schedule_run_ends_with_a_smaller_step_than_it_started(tmp_path):
    config = TrainConfig(
        algo="ppo", episodes=2, envs=1, ppo_n_steps=8, learning_rate_schedule="linear"
    )
    train(config, tmp_path / "run", progress_bar=False)
    model = load_model(tmp_path / "run" / "policy.zip")
    # The optimiser keeps the step of the last update, taken after the first episode.
    last_step = model.policy.optimizer.param_groups[0]["lr"]
    assert 0.0 <= last_step <= 0.5 * config.learning_rate
    constant = replace(config, learning_rate_schedule="constant")
    train(constant, tmp_path / "constant", progress_bar=False)
    steady = load_model(tmp_path / "constant" / "policy.zip")
    assert steady.policy.optimizer.param_groups[0]["lr"] == pytest.approx(config.learning_rate)


def test_a_shipped_policy_named_from_the_checkout_starts_a_run_from_any_folder(
    tmp_path, monkeypatch
):
    """rlfd reproduce's transfer runs start from --init-from models/policies/<file>.zip:
    from a folder without models/ that is the installed file, with its sidecar."""
    from rlfd_drake.paths import SHIPPED_GEAR_POLICY, models_dir
    from rlfd_drake.policies import policy_file, training_config_file

    monkeypatch.chdir(tmp_path)
    shipped = f"models/{SHIPPED_GEAR_POLICY}"
    assert policy_file(shipped) == models_dir() / SHIPPED_GEAR_POLICY
    assert policy_file(f"ppo:{shipped}") == models_dir() / SHIPPED_GEAR_POLICY
    assert training_config_file(shipped) == (models_dir() / SHIPPED_GEAR_POLICY).with_suffix(
        ".json"
    )
    assert TrainConfig(algo="ppo", init_from=shipped).init_from == shipped
    with pytest.raises(ValueError, match="init_from must be a saved policy file"):
        TrainConfig(algo="ppo", init_from="models/policies/nope.zip")


def test_learning_without_tensorboard_leaves_no_folder_behind(tmp_path, monkeypatch):
    # SB3's default logger makes tmp/SB3-<time> at every learn(), even writing nothing.
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    for config in (
        TrainConfig(algo="ppo", envs=1, ppo_n_steps=16),
        TrainConfig(algo="sac", envs=1, history=1, sac_learning_starts=8),
    ):
        model = make_model(config, fast_venv(), None)
        model.learn(total_timesteps=16)
        assert model._n_updates > 0
    assert list(tmp_path.iterdir()) == []


def test_privileged_critic_trains_a_critic_that_reads_what_the_actor_cannot(tmp_path):
    from rlfd_drake.env import PRIVILEGED_SIZE
    from rlfd_drake.policies import DeployedPolicy
    from rlfd_drake.privileged_critic import PrivilegedCriticPolicy
    from rlfd_drake.train import make_envs

    config = TrainConfig(
        algo="ppo", envs=1, ppo_n_steps=16, scaled_observation=True, privileged_critic=True
    )
    venv = make_envs(config, 1, seed=0)
    assert venv.observation_space.shape == (26 + PRIVILEGED_SIZE,)
    observation = venv.reset()
    # The appended entries are the episode's: its fixture error, in 1 mm units.
    fixture_dp = venv.get_attr("setup")[0].fixture_dp
    np.testing.assert_allclose(observation[0, 32:35], fixture_dp / 0.001, rtol=1e-5, atol=1e-5)
    model = make_model(config, venv, None)
    assert isinstance(model.policy, PrivilegedCriticPolicy)
    before = _parameters(model)
    model.learn(total_timesteps=32)  # two updates
    assert _changed(before, model)
    # The actor ignores the privileged entries, the critic does not.
    rng = np.random.default_rng(2)
    obs = rng.normal(size=(4, 26 + PRIVILEGED_SIZE)).astype(np.float32)
    other = obs.copy()
    other[:, 26:] = rng.normal(size=(4, PRIVILEGED_SIZE))
    policy = model.policy
    with torch.no_grad():
        means = [
            policy.get_distribution(policy.obs_to_tensor(o)[0]).distribution.mean
            for o in (obs, other)
        ]
        values = [policy.predict_values(policy.obs_to_tensor(o)[0]) for o in (obs, other)]
    torch.testing.assert_close(means[0], means[1], rtol=0, atol=0)
    assert not torch.equal(values[0], values[1])
    # Saved and loaded, it deploys on the diagram's 26 entries alone.
    model.save(tmp_path / "policy.zip")
    loaded = load_model(tmp_path / "policy.zip")
    assert isinstance(loaded.policy, PrivilegedCriticPolicy)
    deployed = DeployedPolicy(loaded)
    expected, _ = loaded.predict(obs[0], deterministic=True)
    np.testing.assert_allclose(deployed(obs[0, :26]), expected, rtol=0, atol=1e-7)
    venv.close()


def test_ppo_history_stacks_the_observations_it_trains_and_deploys_on():
    """PPO with ``ppo_history`` learns on the frame-stacked view ``make_envs`` gives it,
    and deployed it keeps the same stack itself (one observation per call)."""
    from stable_baselines3.common.vec_env import VecFrameStack

    from rlfd_drake.train import make_envs

    config = TrainConfig(algo="ppo", envs=1, ppo_n_steps=16, ppo_history=3)
    envs = make_envs(config, 1, seed=0)
    assert envs.observation_space.shape == (3 * 26,)
    envs.close()
    assert make_envs(replace(config, ppo_history=1), 1, seed=0).observation_space.shape == (26,)
    venv = VecFrameStack(fast_venv(), n_stack=3)
    model = make_model(config, venv, None)
    before = _parameters(model)
    model.learn(total_timesteps=32)
    assert _changed(before, model)
    _assert_deployed_acts_as_on_the_stack(model, venv, history=3)


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"ppo_history": 0}, "ppo_history must be >= 1, got 0"),
        ({"ppo_history": 4, "algo": "sac"}, "ppo_history=4 cannot go with algo 'sac'"),
        (
            {"ppo_history": 4, "privileged_critic": True},
            "ppo_history=4 cannot go with privileged_critic",
        ),
        ({"ppo_history": 2, "imitate": "force_search"}, "ppo_history=2 cannot go with imitate"),
    ],
)
def test_ppo_history_is_refused_where_it_cannot_apply(fields, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**fields)


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"algo": "sac"}, "privileged_critic cannot go with algo 'sac'"),
        ({"imitate": "force_search"}, "privileged_critic cannot go with imitate"),
    ],
)
def test_privileged_critic_is_refused_where_it_cannot_apply(fields, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(privileged_critic=True, **fields)


@pytest.mark.parametrize("curriculum", [True, False])
def test_curriculum_grows_the_start_perturbation_over_the_first_half_of_training(
    tmp_path, curriculum
):
    """``--curriculum``: each env's start offsets are scaled from ``curriculum_start`` up
    to 1 over the first half of the run's episodes, then kept at 1 (the paper's PPO
    recipe on the physical robot); without it the envs are never told a scale."""
    from types import SimpleNamespace

    from rlfd_drake.train import EpisodeLog

    config = TrainConfig(task="peg_easy", episodes=10, curriculum=curriculum, curriculum_start=0.2)
    log = EpisodeLog(config, tmp_path / "episodes.csv")
    told = []
    envs = SimpleNamespace(env_method=lambda name, value: told.append((name, value)))
    log.model = SimpleNamespace(logger=Logger(None, []), get_env=lambda: envs)
    for finished in (0, 2, 5, 8):
        log.episodes = finished
        log._apply_curriculum()
    if not curriculum:
        assert told == []
        return
    assert [name for name, _ in told] == ["set_perturbation_scale"] * 4
    assert [value for _, value in told] == pytest.approx([0.2, 0.52, 1.0, 1.0])


def test_a_run_with_a_falling_noise_saves_a_policy_with_less_noise(tmp_path):
    """`train` wires the schedule in: the saved log std is below where it started, where
    a learned one (no schedule) was moved only by the optimiser's small steps."""
    config = TrainConfig(
        algo="ppo", episodes=2, envs=1, ppo_n_steps=8, log_std_init=-2.0, log_std_final=-4.0
    )
    train(config, tmp_path / "run", progress_bar=False)
    log_std = load_model(tmp_path / "run" / "policy.zip").policy.log_std
    # Rollouts after the first episode sample at -3 (half the run) or lower.
    assert torch.all(log_std <= -3.0 + 1e-6) and torch.all(log_std >= -4.0 - 1e-6)


def test_a_lateral_log_std_explores_only_x_and_y_more(tmp_path):
    """The lateral entries start at their own log std, the rest at log_std_init, and
    both stay learned parameters (moved only by the optimiser's small steps)."""
    config = TrainConfig(
        algo="ppo", episodes=2, envs=1, ppo_n_steps=8, log_std_init=-2.0, lateral_log_std_init=-1.0
    )
    built = make_model(config, fast_venv(), None).policy.log_std
    assert built.tolist() == [-1.0, -1.0, -2.0, -2.0, -2.0, -2.0]
    assert built.requires_grad
    train(config, tmp_path / "run", progress_bar=False)
    trained = load_model(tmp_path / "run" / "policy.zip").policy.log_std.detach()
    assert torch.allclose(trained[:2], torch.tensor(-1.0), atol=0.05)
    assert torch.allclose(trained[2:], torch.tensor(-2.0), atol=0.05)
    with pytest.raises(ValueError, match="cannot go with init_from"):
        TrainConfig(lateral_log_std_init=-1.0, init_from=str(tmp_path / "run" / "policy.zip"))


def test_a_run_with_self_imitation_stores_its_episodes(tmp_path):
    """`train` wires self-imitation in and says what it did."""
    config = TrainConfig(algo="ppo", episodes=2, envs=1, ppo_n_steps=8, self_imitation_batches=3)
    metrics = train(config, tmp_path / "run", progress_bar=False)
    assert 0 < metrics["self_imitation_stored_steps"] <= metrics["timesteps"]
    assert metrics["self_imitation_updates"] % 3 == 0  # whole rounds of minibatches
